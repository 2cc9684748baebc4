#pragma once
// Internal to src/io: thin RAII over the HDF5 C API shared by the scene, contact and inspection files.
//
// Invariants:
// - every HDF5 identifier is owned by exactly one Handle and closed exactly once;
// - HDF5's automatic error printing is off; every failing HDF5 call becomes one exception whose
//   message starts with the file name: InputError while reading (bad or unreadable input), IoError
//   while writing; data checks name the file, the dataset and the first bad row (file row numbers);
// - the library is entered by one thread at a time (a process-wide mutex: Debian's serial HDF5 is
//   not thread-safe): every public entry point holds a LibraryLock;
// - writers write "<path>.tmp.<pid>" and rename it over path only after a successful close; on any
//   failure the temporary is removed;
// - written objects carry no timestamps (obj_track_times off) and attributes are written in a fixed
//   order, so equal content gives byte-identical files.
#include <fmt/format.h>
#include <hdf5.h>

#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "errors.hpp"
#include "io/temp_output.hpp"

namespace cg::h5 {

// Held by every public entry point: serializes the library and silences its error printing.
class LibraryLock {
 public:
  LibraryLock();

 private:
  std::lock_guard<std::mutex> m_lock;
};

// The most specific message on HDF5's error stack (then cleared); "" when there is none.
std::string hdf5_detail();

// The file an operation is about, and which exception its failures raise.
class Where {
 public:
  Where(std::string file, bool writing) : m_file(std::move(file)), m_writing(writing) {}
  const std::string& file() const { return m_file; }

  // An HDF5 call failed: the library's own reason is appended.
  [[noreturn]] void fail(const std::string& what) const {
    std::string detail = hdf5_detail();
    std::string message = fmt::format("{}: {}", m_file, what);
    if (!detail.empty()) message += fmt::format(" (HDF5: {})", detail);
    if (m_writing) throw IoError(message);
    throw InputError(message);
  }
  // The data is wrong (no HDF5 failure involved).
  [[noreturn]] void bad(const std::string& what) const {
    throw InputError(fmt::format("{}: {}", m_file, what));
  }

 private:
  std::string m_file;
  bool m_writing;
};

// Owner of one HDF5 identifier.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) noexcept : m_id(id), m_closer(closer) {}
  ~Handle() { reset(); }
  Handle(Handle&& other) noexcept
      : m_id(std::exchange(other.m_id, H5I_INVALID_HID)), m_closer(other.m_closer) {}
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      reset();
      m_id = std::exchange(other.m_id, H5I_INVALID_HID);
      m_closer = other.m_closer;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const noexcept { return m_id; }
  operator hid_t() const noexcept { return m_id; }  // NOLINT: hand to the C API directly

  // Close now and check (a file's close flushes: its failure is a write failure).
  void close(const Where& where, const std::string& what) {
    hid_t id = std::exchange(m_id, H5I_INVALID_HID);
    if (id >= 0 && m_closer(id) < 0) where.fail(what);
  }
  void reset() noexcept {
    if (m_id >= 0) m_closer(m_id);
    m_id = H5I_INVALID_HID;
  }

 private:
  hid_t m_id = H5I_INVALID_HID;
  Closer m_closer = nullptr;
};

Handle checked(hid_t id, Handle::Closer closer, const Where& where, const std::string& what);
void check(herr_t status, const Where& where, const std::string& what);

Handle make_space(const Where& where, const std::vector<hsize_t>& dims);
Handle scalar_space(const Where& where);
Handle string_type(const Where& where);                    // variable-length UTF-8
std::string shape_text(const std::vector<hsize_t>& dims);  // "(N, 3)"
std::string type_text(hid_t type);                         // "32-bit integer", "string", …

// ---- objects ---------------------------------------------------------------------------------

// True when every component of the absolute path exists as a link.
bool path_exists(const Where& where, hid_t file, const std::string& path);
H5I_type_t object_type(const Where& where, hid_t file, const std::string& path);
// Before HDF5 opens the object at `path` (an existing link): InputError "<what>: damaged: …" (or
// "<what>: <path> is damaged: …") when its header is one libhdf5 1.10.8 would crash on
// (raw_attributes.hpp: damaged_object). object_type and path_exists call it.
void check_object_header(const Where& where, hid_t file, const std::string& path, const std::string& what);
// Whether a group exists (and is a group).
bool group_exists(const Where& where, hid_t file, const std::string& path);
// The file of `where`, read-only; InputError naming it when missing, not HDF5 or unreadable.
Handle open_file_for_reading(const Where& where);

// ---- writing ---------------------------------------------------------------------------------

// The temporary of an output (io/temp_output.hpp).
using cg::check_output_directory;
using cg::remove_quietly;
using cg::temp_name;
using cg::TempOutput;

Handle creation_properties(const Where& where, hid_t plist_class);  // object times off
// Creates `name` (the temporary of where.file()): check_output_directory, then a failure is an
// IoError naming where.file() with the system's reason only.
Handle create_file(const Where& where, const std::string& name);
Handle create_group(const Where& where, hid_t file, const std::string& name);  // with intermediates
// A contiguous dataset of the given file type and shape (no fill writes: every row gets written).
Handle create_dataset(const Where& where, hid_t file, const std::string& name, hid_t file_type,
                      const std::vector<hsize_t>& dims);
// Writes rows [first, first + count) of a dataset of `cols` columns (0: rank 1).
void write_rows(const Where& where, hid_t dataset, const std::string& name, hsize_t first, hsize_t count,
                hsize_t cols, hid_t mem_type, const void* data);

}  // namespace cg::h5
