#pragma once
// The commands of the contactgrid executable, as functions (the CLI parses, these run).
// pipeline.cpp is the only place that sequences the stages of a run:
//   read scene → (MPI: slabs, redistribute, halo) → engine → (MPI: exchange by id_a range, merge)
//   → write (every rank its rows of one file) → summary
#include <cstdint>
#include <string>

#include "engine.hpp"
#include "generate.hpp"

namespace cg {

class Session;  // comm/session.hpp: the MPI session (one rank in laptop mode)

struct DetectCommand {
  std::string input;
  std::string output;
  std::string csv;  // optional text copy
  Backend backend = Backend::automatic;
  Precision precision = Precision::fp64;
  Fields fields = Fields::basic;
  double cell_size = 0;                        // 0: chosen by cell_choice
  CellChoice cell_choice = CellChoice::tuned;  // --cell-size auto | min
  int threads = 0;
  std::string axis = "auto";      // MPI slab axis: auto | x | y | z
  std::string balance = "count";  // MPI slab balance: count | width
  std::string read = "auto";      // MPI scene read: auto | own | all
  std::string write = "gather";   // MPI output: gather (rank 0 merges, writes) | ranks (each its id_a range)
  int steps = 0;                  // resident steps after the run (a simulation's per-step cost)
  bool quiet = false;
};

// Runs one detection over all ranks of `session`; returns the process exit code (0). Rank 0 writes the
// output file (--write ranks: every rank writes its rows of it); the summary comes from rank 0. Errors are
// agreed on by all ranks and thrown on every rank.
int run_detect(const DetectCommand& cmd, Session& session);

// Compares the /contacts datasets of two contact files byte for byte (what `mpirun -np P` must
// reproduce from the single-rank run). Returns 0 when identical, 1 otherwise (and says where).
int run_compare(const std::string& a, const std::string& b);

int run_generate(const std::string& path, const GenerateOptions& options, bool quiet);

// Writes contacts as CSV (header + one row per contact), to a temporary name then renamed.
template <class Real>
void write_contacts_csv(const std::string& path, const Contacts<Real>& contacts);

}  // namespace cg
