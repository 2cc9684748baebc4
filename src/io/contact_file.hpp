#pragma once
// Contact files (docs/FORMAT.md §2): written whole or in phases (by many processes at once), read back.
//
// Writing goes to "<path>.tmp.<pid>" and is renamed over <path> only after the file is closed, so an
// output file exists only for a successful run (IoError otherwise, temporary removed). Contact files
// are written in phases (create, rows by plain pwrite or a shared mapping (io/row_writer) from any number of
// processes and threads, commit), so the ranks of an MPI run write their rows of one file at once
// (comm/distributed_write). Reading throws InputError naming the file and the dataset.
#include <cstdint>
#include <string>
#include <vector>

#include "engine.hpp"
#include "scene/scene.hpp"

namespace cg {

// Everything recorded about a run in the contact file's root attributes (docs/FORMAT.md §2).
struct RunInfo {
  std::uint64_t bodies = 0;
  std::string precision;         // "fp32" | "fp64" | "mixed" (float64 datasets); empty: the contacts' type
  std::string precision_choice;  // --precision auto: why that mode (root attribute only when set)
  std::string backend;           // "cpu" | "cuda"
  int ranks = 1;
  double cell_size = 0;
  std::string input;  // input file name
  StageTimes times;
  // Scenes with ellipsoids (ellipsoids > 0; written as root attributes only then, so sphere-only
  // files are unchanged): the ellipsoid count and the narrow phase's EngineStats summed over ranks.
  std::uint64_t ellipsoids = 0, narrow_fallbacks = 0, narrow_unconverged = 0;
};

// One process writes the whole file: the phases below with `threads` writers (0: all). Throws Error
// for inconsistent arguments, IoError when the file cannot be written; no file left behind.
template <class Real>
void write_contacts(const std::string& path, const Contacts<Real>& contacts, const RunInfo& info,
                    int threads = 0);

// ---- a contact file written in phases, by one process or by many --------------------------------
// (a) create_contact_file (one process): "<path>.tmp.<pid>" with every /contacts dataset of K rows
//     (docs/FORMAT.md §2 types and shapes; contiguous, space allocated at creation, never filled), closed;
//     the layout says where each dataset's rows lie in the file.
// (b) write_contact_rows (any process that can see the file, once per row, slices in any order and
//     of any size): the rows copied (io/row_writer: pwrite, or CONTACTGRID_IO_WRITE=map) at offset +
//     first_row · row_bytes, by several threads. No HDF5 involved, so processes and threads write at once.
// (c) commit_contact_file (the creating process, after every (b) has returned): the root attributes
//     (docs/FORMAT.md §2), then the temporary is renamed over path. On a failure anywhere,
//     discard_contact_file removes the temporary: no output appears.
// The bytes of the datasets are the same whoever wrote which rows (and equal write_contacts').
// Memory and file are little-endian (checked at compile time): rows are copied as they are.
struct ContactFileLayout {
  struct Dataset {
    std::string name;             // "/contacts/id_a", …
    std::uint64_t offset = 0;     // of row 0 in the file (unused when rows == 0)
    std::uint64_t row_bytes = 0;  // 8 for ids, sizeof(Real) for distance, 3·sizeof(Real) for vectors
  };
  std::string path;        // the output file
  std::string temp;        // the file being written ("<path>.tmp.<pid of the creator>")
  std::uint64_t rows = 0;  // K
  Precision precision = Precision::fp64;
  FieldSet fields;                // the optional groups whose datasets exist
  std::vector<Dataset> datasets;  // id_a, id_b, position_on_a, position_on_b, normal_on_b, distance,
                                  // then (full) local_point_a, local_point_b, dir1, dir2, then
                                  // (history) age, previous_row: kContactFields order
  // Text form, to hand the layout to other processes (from_text(to_text()) == *this).
  std::string to_text() const;
  static ContactFileLayout from_text(const std::string& text);
};

// Phase (a). IoError on failure, nothing left behind.
ContactFileLayout create_contact_file(const std::string& path, std::uint64_t rows, Precision precision,
                                      FieldSet fields);

// Phase (b): rows [first_row, first_row + slice.size()) of every dataset from `slice` (its precision
// and fields must match the layout; Error otherwise, before anything is written). `threads` writers
// (0: all) in blocks of a few MiB. IoError naming the file and the dataset when a write fails.
template <class Real>
void write_contact_rows(const ContactFileLayout& layout, std::uint64_t first_row, const Contacts<Real>& slice,
                        int threads = 0);

// Phase (c): root attributes (contacts = layout.rows; info.precision, when given, must match), close,
// rename over layout.path. IoError on failure, and then the temporary is removed.
void commit_contact_file(const ContactFileLayout& layout, const RunInfo& info);

// Removes the temporary (no error if it is gone). Never throws.
void discard_contact_file(const ContactFileLayout& layout) noexcept;

// ---- a contact file written as its rows come, in order (streamed) ---------------------------------
// For a run whose contacts come in consecutive blocks of the sorted order (detect_in_pieces): each
// block is appended to every /contacts dataset as it comes, so the writer never holds more than the
// block. The datasets are chunked with an unlimited row count (docs/FORMAT.md §2 allows any storage
// layout; readers see the same shapes, types and values); an append extends them (HDF5 allocates the
// new chunks at once, never filled), reads the chunks' file offsets, closes the file and pwrites the
// rows there on `threads` writers — no HDF5 while the rows go out, as write_contact_rows. The file
// is created at the first append (its chunk size from that block's rows) or at commit. Commit writes
// the root attributes and renames the temporary over the path; destroying an uncommitted stream (a
// failed run) removes the temporary: no output appears.
class ContactFileStream {
 public:
  ContactFileStream(std::string path, Precision precision, FieldSet fields);
  ~ContactFileStream();
  ContactFileStream(const ContactFileStream&) = delete;
  ContactFileStream& operator=(const ContactFileStream&) = delete;

  // The next rows (precision and fields must match; Error otherwise). IoError when a write fails.
  template <class Real>
  void append(const Contacts<Real>& rows, int threads = 0);
  std::uint64_t rows() const { return m_layout.rows; }
  const std::string& path() const { return m_layout.path; }
  // Root attributes (contacts = rows()), close, rename. IoError on failure, the temporary removed.
  void commit(const RunInfo& info);
  void discard() noexcept;

 private:
  void create(std::uint64_t chunk_rows);
  ContactFileLayout m_layout;  // rows: appended so far; offsets unused (chunks are found per append)
  std::uint64_t m_chunk_rows = 0;
  bool m_created = false, m_finished = false;
};

// Reads a contact file back in double (whatever precision it was written in). Without
// `optional_fields` the optional datasets are checked (all or none) but not read (contacts.full false).
struct ContactFile {
  Contacts<double> contacts;
  std::string precision;
  Attributes attributes;
};
ContactFile read_contacts(const std::string& path, bool optional_fields = true);

// A contact file's run record without its rows: the precision attribute ("" when the file has none
// we could decode), the root attributes and the number of rows (checked as read_contacts checks them).
struct ContactFileHeader {
  std::string precision;
  Attributes attributes;
  std::uint64_t rows = 0;
};
ContactFileHeader read_contact_header(const std::string& path);

}  // namespace cg
