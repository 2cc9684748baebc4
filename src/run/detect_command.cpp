// The `detect` command (run/pipeline.hpp): its options into the run's, the output directories checked,
// the read, the mode chosen (--precision auto), the distributed run in that mode (distributed_run.hpp),
// the write (the contact file, a streamed one under a memory limit, the CSV copy) and the summary.
#include <fmt/format.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>

#include "agreed_stage.hpp"
#include "device_warm_up.hpp"
#include "host_vector.hpp"
#include "io/contacts_csv.hpp"
#include "io/temp_output.hpp"
#include "node_threads.hpp"
#include "precision_choice.hpp"
#include "run/contact_file_shared.hpp"
#include "run/distributed_run.hpp"
#include "run/pipeline.hpp"
#include "run/progress.hpp"
#include "run/stage_clock.hpp"
#include "run/stop.hpp"
#include "run/summary.hpp"
#include "session.hpp"

namespace cg {

namespace {

// A pair stage far above the usual (pair_work_unusual) is said once per process, on any rank, before
// it runs: a run that would take hours says so instead of running without a word.
void warn_unusual_pair_work(const PairEstimate& e, const std::string& prefix) {
  static std::atomic<bool> said{false};
  if (!pair_work_unusual(e) || said.exchange(true)) return;
  fmt::print(
      stderr,
      "contactgrid: warning: {}the pair stage will make {}, far more than usual (a few to a few hundred "
      "per body): expect a long run; --max-pair-tests N refuses such scenes\n",
      prefix, describe(e));
  std::fflush(stderr);
}

DistributedOptions run_options(const DetectCommand& cmd, const Session& session) {
  DistributedOptions o;
  o.engine.backend = cmd.backend;
  o.engine.fields = cmd.fields;
  o.engine.cell_size = cmd.cell_size;
  o.engine.cell_choice = cmd.cell_choice;
  o.engine.broad_phase = cmd.broad_phase;
  o.engine.threads = cmd.threads;
  o.engine.ellipsoid_tolerance = cmd.solver_tolerance;
  o.engine.ellipsoid_max_iterations = cmd.solver_iterations;
  o.engine.skin = cmd.skin;
  o.engine.max_pair_tests = cmd.max_pair_tests;
  o.memory_limit = cmd.memory_limit;
  // A pair stage far above the usual is said before it runs (any rank) and, on rank 0's terminal,
  // shows its progress in pair tests (run/progress.hpp; both backends report it).
  auto pair_bar = std::make_shared<std::unique_ptr<Progress>>();
  o.engine.on_pair_estimate = [pair_bar, draw = !cmd.quiet && session.rank() == 0,
                               prefix = session.uses_mpi() ? session.prefix()
                                                           : std::string()](const PairEstimate& e) {
    warn_unusual_pair_work(e, prefix);
    if (pair_work_unusual(e))
      *pair_bar = std::make_unique<Progress>("detect: pair stage", "pair tests", e.tests, draw);
  };
  o.engine.on_pair_progress = [pair_bar](std::uint64_t done, bool finished) {
    if (!*pair_bar) return;
    (*pair_bar)->update(done);
    if (finished) pair_bar->reset();
  };
  if (cmd.backend != Backend::cpu) o.engine.device = session.device_for(cuda_device_count());
  o.axis = cmd.axis;
  o.balance = cmd.balance;
  o.read = cmd.read;
  // The merge line says how many runs were merged: something only under mpirun.
  if (cmd.verbose && !cmd.quiet && session.rank() == 0 && session.size() > 1)
    o.log = [](const std::string& line) { fmt::print("{}\n", line); };
  // The design card's shape by default: rank 0 gathers, deduplicates and writes the sorted contacts
  // (--write gather). --write ranks: each rank keeps the contacts of its id_a range and writes them
  // into the one output file. A CSV copy is written by rank 0 alone, so it always gathers.
  o.output = cmd.csv.empty() ? cmd.write : ContactOutput::gather;
  o.resident_steps = cmd.steps;
  o.step_motion.spin = cmd.spin;
  o.step_motion.drift = cmd.drift;
  o.engine.skin_auto = cmd.skin_auto;
  o.final_scene = cmd.final_scene;
  if (cmd.steps > 0) {  // a progress line on rank 0's terminal (run/progress.hpp)
    auto bar = std::make_shared<Progress>("detect: resident steps", "steps", std::uint64_t(cmd.steps),
                                          !cmd.quiet && session.rank() == 0);
    o.step_motion.on_step = [bar, steps = cmd.steps](int done) {
      bar->update(std::uint64_t(done));
      if (done == steps) bar->finish();
    };
  }
  return o;
}

// The output file's record of the run (its root attributes): what ran, on what, and the stage times.
template <class Real>
void describe_run(const DistributedResult<Real>& r, const DetectCommand& cmd, RunInfo& info) {
  info.bodies = r.bodies;
  info.backend = to_string(r.backend);
  info.ranks = r.ranks;
  info.cell_size = r.cell_size;
  info.input = cmd.input;
  info.times = file_stage_times(r.times);
  info.ellipsoids = r.ellipsoids;
  info.narrow_fallbacks = r.stats.narrow_fallbacks;
  info.narrow_unconverged = r.stats.narrow_unconverged;
}

// Every rank writes its rows of the one file (src/run/contact_file_shared.hpp); the file records the
// times so far and the write's. Returns the write's time.
template <class Real>
RunTime write_output(Session& session, const DetectCommand& cmd, const DistributedResult<Real>& r,
                     RunInfo& info) {
  describe_run(r, cmd, info);
  const double seconds = write_contacts_distributed(session, cmd.output, r.contacts, r.first_row,
                                                    r.total_contacts, info, r.threads);
  return {RunStage::write, -1, seconds};
}

// The streamed output file's root attributes and its rename (its rows were appended as the pieces
// came). Returns the time of this last step.
template <class Real>
RunTime commit_stream(ContactFileStream& stream, const DistributedResult<Real>& r, const DetectCommand& cmd,
                      RunInfo& info) {
  const auto t0 = WallClock::now();
  describe_run(r, cmd, info);
  info.times.push_back({"write", seconds_since(t0)});
  stream.commit(info);
  return {RunStage::write, -1, seconds_since(t0)};
}

// The CSV copy, by rank 0 (which holds every contact: --csv gathers). Returns its time (rank 0).
template <class Real>
RunTime write_csv(const Session& session, const std::string& path, const Contacts<Real>& contacts) {
  std::exception_ptr error;
  double seconds = 0;
  if (session.rank() == 0) {
    try {
      auto t = WallClock::now();
      write_contacts_csv(path, contacts);
      seconds = seconds_since(t);
    } catch (...) {
      error = std::current_exception();
    }
  }
  session.agree(error, "csv");
  return {RunStage::csv, -1, seconds};
}

// The mode of the run: --precision as given, or (auto) choose_precision on the agreed global bounds
// and the backend every rank runs (cuda only where every rank's engine would), so every rank picks
// the same mode.
PrecisionChoice choose_mode(const Session& session, const DetectCommand& cmd, const ReadScene& in) {
  if (cmd.precision) return {*cmd.precision, {}};
  const Backend mine =
      cmd.backend == Backend::automatic ? (cuda_available() ? Backend::cuda : Backend::cpu) : cmd.backend;
  const Backend backend = session.max(mine == Backend::cuda ? 0.0 : 1.0) > 0 ? Backend::cpu : Backend::cuda;
  PrecisionChoice pick;
  agreed_stage(session, "frame", [&] {
    try {
      const bool ellipsoids = in.part.has_shapes;
      pick = choose_precision(precision_scene(in.global, ellipsoids, cmd.cell_size, cmd.cell_choice), backend,
                              cmd.accuracy);
    } catch (const InputError& e) {  // no mode meets the accuracy here: name the scene
      throw InputError(cmd.input + ": " + e.what());
    }
  });
  return pick;
}

// frame → slabs → distribute → exchange ghosts → detect → collect contacts (distributed_run) → write →
// summary, in the chosen mode.
template <class Real>
int run_in_mode(const DetectCommand& cmd, Session& session, const DistributedOptions& options, ReadScene&& in,
                const PrecisionChoice& choice, int threads, DeviceWarmUp& warm) {
  // One rank under a memory limit writes the contacts as its pieces come (host memory: a piece or
  // two, never all rows); a CSV copy or several ranks gather them first.
  std::optional<ContactFileStream> stream;
  if (options.memory_limit && session.size() == 1 && cmd.csv.empty() && options.resident_steps == 0)
    stream.emplace(cmd.output, precision_of<Real>(), FieldSet(options.engine.fields == Fields::full));
  // The free blocks the host pool keeps for reuse count against the limit as well.
  if (stream) cap_host_pool(options.memory_limit);
  const double waited = warm.wait();
  DistributedResult<Real> r = or_abort(session, [&] {
    return distributed_run<Real>(session, cmd.input, options, std::move(in), threads,
                                 stream ? &*stream : nullptr);
  });
  r.warm_up = warm.seconds();
  r.warm_up_context = warm.context_seconds();
  r.warm_up_wait = waited;
  RunTimes times = r.times;
  RunInfo info;
  info.precision = to_string(choice.mode);
  info.precision_choice = choice.reason;
  stop_point();
  // The contact file and its CSV copy appear both or neither (rank 0 renames them into place).
  FinishedOutputs outputs;
  if (stream)
    times.push_back(commit_stream(*stream, r, cmd, info));
  else
    times.push_back(write_output(session, cmd, r, info));
  if (session.rank() == 0) outputs.add(cmd.output);
  if (!cmd.csv.empty()) {
    times.push_back(write_csv(session, cmd.csv, r.contacts));
    if (session.rank() == 0) outputs.add(cmd.csv);
  }
  stop_point();
  outputs.keep();
  if (!cmd.quiet && session.rank() == 0) print_summary(info, times, r.total_contacts, r);
  return 0;
}

}  // namespace

namespace {

// The directory `file` goes into exists and this process may create files there, and `file` is not
// itself a directory; IoError naming `option`, the file and the directory otherwise. Checked before the
// scene is read, so that a mistyped output path fails at once rather than after the whole run.
void require_writable_directory(const std::string& option, const std::string& file) {
  namespace fs = std::filesystem;
  const fs::path parent = fs::path(file).parent_path();
  const std::string dir = parent.empty() ? std::string(".") : parent.string();
  std::error_code ec;
  const fs::file_status status = fs::status(dir, ec);
  auto fail = [&](const std::string& why) {
    throw IoError(fmt::format("{} {}: cannot write into the directory {}: {}", option, file, dir, why));
  };
  if (status.type() == fs::file_type::none) fail(ec.message());  // e.g. a parent not searchable
  if (!fs::exists(status)) fail("it does not exist");
  if (!fs::is_directory(status)) fail("it is not a directory");
  if (::access(dir.c_str(), W_OK | X_OK) != 0) fail(std::strerror(errno));
  if (fs::is_directory(fs::status(file, ec)))
    throw IoError(fmt::format("{} {}: is a directory, not a file name", option, file));
}

// Every rank that writes checks its files' directories: rank 0 the output file and the CSV copy,
// with --write ranks every rank the output file (each writes its rows into it).
void check_output_directories(const Session& session, const DetectCommand& cmd,
                              const DistributedOptions& options) {
  agreed_stage(session, "output", [&] {
    if (session.rank() == 0 || options.output == ContactOutput::ranks)
      require_writable_directory("-o", cmd.output);
    if (session.rank() == 0 && !cmd.csv.empty()) require_writable_directory("--csv", cmd.csv);
  });
}

}  // namespace

// read → (--precision auto: choose the mode) → the run in that mode → write → summary
int run_detect(const DetectCommand& cmd, Session& session) {
  if (cmd.output.empty()) throw UsageError("detect: -o/--output is required");
  if (cmd.precision && cmd.accuracy.position)
    throw UsageError(std::string("--accuracy: only with --precision auto (the default), not --precision ") +
                     to_string(*cmd.precision));
  DistributedOptions options = run_options(cmd, session);
  check_output_directories(session, cmd, options);
  const int threads = host_threads(options.engine.threads, session);
  const DefaultTeam team(threads);
  // The GPU's context and the kernels of a detection in the mode asked (auto: each until chosen) made
  // ready on a thread of their own while the scene is read.
  DeviceWarmUp warm(options.engine,
                    cmd.precision ? DeviceWarmUp::bit(*cmd.precision) : DeviceWarmUp::all_modes());
  ReadScene in = or_abort(session, [&] { return read_scene(session, cmd.input, options); });
  const PrecisionChoice choice = or_abort(session, [&] { return choose_mode(session, cmd, in); });
  warm.keep_only(choice.mode, in.part.has_shapes);
  options.engine.fp32_broad_phase = choice.mode == Precision::mixed;
  return choice.mode == Precision::fp32
             ? run_in_mode<float>(cmd, session, options, std::move(in), choice, threads, warm)
             : run_in_mode<double>(cmd, session, options, std::move(in), choice, threads, warm);
}

}  // namespace cg
