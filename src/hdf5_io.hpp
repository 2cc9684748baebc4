#pragma once
// HDF5 I/O of CONTRACT §1 and §2, behind thin RAII wrappers of the HDF5 C API (hdf5_io.cpp).
//
// Reading validates everything it reads and throws InputError with one message naming the file, the
// dataset and the first bad row ("scene.h5: /spheres/radius row 17: radius -1 is not > 0"); a file
// that cannot be opened or is truncated is an InputError naming the file.
// Writing goes to "<path>.tmp.<pid>" and is renamed over <path> only after the file is closed, so an
// output file exists only for a successful run (IoError otherwise, temporary removed). Contact files
// are written in phases (create, rows by plain pwrite from any number of processes and threads,
// commit), so the ranks of an MPI run write their rows of one file at once (comm/distributed_write).
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine.hpp"
#include "scene.hpp"

namespace cg {

// Whole scene into memory (double), validated. Rows [first, first+count) of each group can be read
// with read_scene_rows for parallel readers.
Scene read_scene(const std::string& path);

// Counts of bodies in a scene file without reading the data (datasets' types and shapes are checked;
// a file without bodies is an InputError, like read_scene).
struct SceneShape {
  std::size_t spheres = 0, ellipsoids = 0;
};
SceneShape read_scene_shape(const std::string& path);

// Rows [first, first + count) of /spheres (positions, radii) — validated like read_scene, with the
// row numbers of the file in messages. Root attributes are read too.
// Rows count in global body ids (spheres 0 … N-1, then ellipsoids N … N+M-1), so for a file with
// only spheres they are exactly the rows of /spheres; a range crossing N returns the spheres
// [first, N) and the ellipsoids [0, first+count-N) of /ellipsoids. A range past N+M is a UsageError.
Scene read_scene_rows(const std::string& path, std::size_t first, std::size_t count);

// Writes float64 datasets ((N,3) / (N)), root attributes radius_low/radius_high when set and every
// entry of scene.attributes (keys "radius_low"/"radius_high" there are ignored: the optionals rule).
// Writing does not validate the values (tests write bad scenes on purpose). A scene without bodies
// is written as an empty /spheres group. IoError on failure, no file left behind.
void write_scene(const std::string& path, const Scene& scene);

// What a scene file holds besides its rows: the body counts (the datasets' final sizes) and the root
// attributes.
struct SceneFileHeader {
  std::size_t spheres = 0, ellipsoids = 0;
  std::optional<double> radius_low, radius_high;
  Attributes attributes;
};

// Streams a scene file of known size in row blocks, in bounded host memory (generate_scene_file,
// 2^28 bodies). Datasets of the final sizes are created by the constructor; every row must be
// written once (blocks in any order); commit() closes the temporary "<path>.tmp.<pid>" and renames
// it over path. Destroyed without commit(), the temporary is removed. Throws IoError.
class SceneFileWriter {
 public:
  SceneFileWriter(const std::string& path, const SceneFileHeader& header);
  ~SceneFileWriter();
  SceneFileWriter(const SceneFileWriter&) = delete;
  SceneFileWriter& operator=(const SceneFileWriter&) = delete;

  void write_spheres(std::size_t first, std::span<const Vec3<double>> position,
                     std::span<const double> radius);
  void write_ellipsoids(std::size_t first, std::span<const Vec3<double>> position,
                        std::span<const Vec3<double>> semi_axes,
                        std::span<const std::array<double, 4>> orientation);
  void commit();

  struct Impl;

 private:
  std::unique_ptr<Impl> m_impl;
};

// Everything recorded about a run in the contact file's root attributes (CONTRACT §2).
struct RunInfo {
  std::uint64_t bodies = 0;
  std::string precision;  // "fp32" | "fp64"
  std::string backend;    // "cpu" | "cuda"
  int ranks = 1;
  double cell_size = 0;
  std::string input;  // input file name
  StageTimes times;
};

// One process writes the whole file: the phases below with `threads` writers (0: all). Throws Error
// for inconsistent arguments, IoError when the file cannot be written; no file left behind.
template <class Real>
void write_contacts(const std::string& path, const Contacts<Real>& contacts, const RunInfo& info,
                    int threads = 0);

// ---- a contact file written in phases, by one process or by many --------------------------------
// (a) create_contact_file (one process): "<path>.tmp.<pid>" with every /contacts dataset of K rows
//     (CONTRACT §2 types and shapes; contiguous, space allocated at creation, never filled), closed;
//     the layout says where each dataset's rows lie in the file.
// (b) write_contact_rows (any process that can see the file, once per row, slices in any order and
//     of any size): plain pwrite of the rows at offset + first_row · row_bytes, by several threads.
//     No HDF5 involved, so processes and threads write at once.
// (c) commit_contact_file (the creating process, after every (b) has returned): the root attributes
//     (CONTRACT §2), then the temporary is renamed over path. On a failure anywhere,
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
  bool full = false;              // the four optional datasets exist
  std::vector<Dataset> datasets;  // id_a, id_b, position_on_a, position_on_b, normal_on_b, distance,
                                  // then (full) local_point_a, local_point_b, dir1, dir2
  // Text form, to hand the layout to other processes (from_text(to_text()) == *this).
  std::string to_text() const;
  static ContactFileLayout from_text(const std::string& text);
};

// Phase (a). IoError on failure, nothing left behind.
ContactFileLayout create_contact_file(const std::string& path, std::uint64_t rows, Precision precision,
                                      bool full);

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

// Reads a contact file back in double (whatever precision it was written in).
struct ContactFile {
  Contacts<double> contacts;
  std::string precision;
  Attributes attributes;
};
ContactFile read_contacts(const std::string& path);

// The /contacts datasets of CONTRACT §2 in file order: six always, the last four with --fields full.
inline constexpr const char* kContactDatasets[] = {"/contacts/id_a",
                                                   "/contacts/id_b",
                                                   "/contacts/position_on_a",
                                                   "/contacts/position_on_b",
                                                   "/contacts/normal_on_b",
                                                   "/contacts/distance",
                                                   "/contacts/local_point_a",
                                                   "/contacts/local_point_b",
                                                   "/contacts/lateral_friction_dir1",
                                                   "/contacts/lateral_friction_dir2"};

// Low-level helpers for tests and tools that must produce files the writers above refuse to make
// (wrong element types, shapes, empty datasets). They write in place (no temporary): the file is
// created if missing, else opened read-write; intermediate groups are created; `values` (row-major,
// converted by HDF5 to `type`) must hold the product of `dims` values. Throw IoError.
enum class RawType { float64, float32, int32, int64 };
void write_raw_dataset(const std::string& path, const std::string& dataset, RawType type,
                       const std::vector<std::uint64_t>& dims, std::span<const double> values);
void write_raw_attribute(const std::string& path, const std::string& name, const AttrValue& value);

// Element type ("float64", "float32", "int64", "int32", … "uint8", or "other") and shape of a dataset;
// nullopt when the path does not exist. InputError when the file cannot be read.
struct DatasetInfo {
  std::string type;
  std::vector<std::uint64_t> dims;
};
std::optional<DatasetInfo> inspect_dataset(const std::string& path, const std::string& dataset);

// A dataset's elements as stored in the file (its own type, row-major, no conversion): what the
// byte-for-byte comparisons of runs look at. InputError when missing or unreadable.
std::vector<unsigned char> read_dataset_bytes(const std::string& path, const std::string& dataset);

}  // namespace cg
