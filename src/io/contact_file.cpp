// contact_file.cpp: contact files (docs/FORMAT.md §2) through the HDF5 C API, their rows by
// io/row_writer (see contact_file.hpp).
#include "io/contact_file.hpp"

#include <fmt/format.h>
#include <hdf5.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <type_traits>
#include <utility>

#include "io/attributes.hpp"
#include "io/datasets.hpp"
#include "io/hdf5_handle.hpp"
#include "io/row_writer.hpp"

namespace cg {

using namespace h5;  // NOLINT: the io layer's own helpers

static_assert(sizeof(Vec3<float>) == 3 * sizeof(float) && std::is_standard_layout_v<Vec3<float>>);

namespace {
constexpr const char* kSoftwareVersion = CONTACTGRID_VERSION;
}  // namespace

// ---- contact files, in phases ----------------------------------------------------------------------

// The rows are copied to the file as they are in memory: the file types are little-endian.
static_assert(std::endian::native == std::endian::little,
              "contact rows are written as raw bytes into little-endian datasets: a big-endian host "
              "needs a byte swap in write_contact_rows");
static_assert(sizeof(std::int64_t) == 8 && sizeof(double) == 8 && sizeof(float) == 4);

namespace {

// Columns of a field's dataset (0: rank 1) and its HDF5 type in a file of this precision.
hsize_t dataset_columns(const ContactField& f) { return f.kind == FieldKind::vector ? 3 : 0; }
hid_t dataset_type(const ContactField& f, bool fp32) {
  return f.kind == FieldKind::integer ? H5T_STD_I64LE : fp32 ? H5T_IEEE_F32LE : H5T_IEEE_F64LE;
}

// The rows of dataset k of `c` in layout order (kContactFields).
template <class Real>
std::vector<const unsigned char*> row_sources(const Contacts<Real>& c) {
  std::vector<const unsigned char*> src;
  for_each_contact_field(c, c.fields(), [&](auto, const auto& column) {
    src.push_back(reinterpret_cast<const unsigned char*>(column.data()));
  });
  return src;
}

}  // namespace

std::string ContactFileLayout::to_text() const {
  // One header line, one line per dataset, then the paths (each prefixed by its length: a path may
  // hold any character).
  std::string t = fmt::format("{} {} {} {} {}\n", rows, precision == Precision::fp32 ? 32 : 64,
                              fields.full ? 1 : 0, fields.history ? 1 : 0, datasets.size());
  for (const Dataset& d : datasets) t += fmt::format("{} {} {}\n", d.offset, d.row_bytes, d.name);
  t += fmt::format("{}\n{}\n{}\n{}", path.size(), path, temp.size(), temp);
  return t;
}

ContactFileLayout ContactFileLayout::from_text(const std::string& text) {
  ContactFileLayout l;
  std::size_t at = 0;
  auto line = [&]() {
    const std::size_t e = text.find('\n', at);
    if (e == std::string::npos) throw Error("ContactFileLayout::from_text: truncated layout");
    std::string s = text.substr(at, e - at);
    at = e + 1;
    return s;
  };
  auto counted = [&]() {
    const std::size_t n = std::stoull(line());
    if (at + n > text.size()) throw Error("ContactFileLayout::from_text: truncated layout");
    std::string s = text.substr(at, n);
    at += n;
    return s;
  };
  unsigned long long rows = 0, count = 0;
  int bits = 0, full = 0, history = 0;
  if (std::sscanf(line().c_str(), "%llu %d %d %d %llu", &rows, &bits, &full, &history, &count) != 5 ||
      (bits != 32 && bits != 64) || count > kContactFieldCount)
    throw Error("ContactFileLayout::from_text: bad header");
  l.rows = rows;
  l.precision = bits == 32 ? Precision::fp32 : Precision::fp64;
  l.fields = FieldSet{full != 0, history != 0};
  for (unsigned long long k = 0; k < count; ++k) {
    const std::string s = line();
    unsigned long long offset = 0, row_bytes = 0;
    int used = 0;
    if (std::sscanf(s.c_str(), "%llu %llu %n", &offset, &row_bytes, &used) != 2)
      throw Error("ContactFileLayout::from_text: bad dataset line");
    l.datasets.push_back({s.substr(static_cast<std::size_t>(used)), offset, row_bytes});
  }
  l.path = counted();
  if (at >= text.size() || text[at] != '\n') throw Error("ContactFileLayout::from_text: bad paths");
  ++at;
  l.temp = counted();
  return l;
}

ContactFileLayout create_contact_file(const std::string& path, std::uint64_t rows, Precision precision,
                                      FieldSet fields) {
  LibraryLock lock;
  ContactFileLayout layout;
  layout.path = path;
  layout.temp = temp_name(path);
  layout.rows = rows;
  layout.precision = precision;
  layout.fields = fields;
  const bool fp32 = precision == Precision::fp32;
  Where where(path, true);
  remove_on_stop(layout.temp);  // until commit_contact_file or discard_contact_file
  try {
    Handle file = create_file(where, layout.temp);
    create_group(where, file, "/contacts");
    for (const ContactField& field : kContactFields) {
      if (!fields.has(field.group)) continue;
      const hsize_t cols = dataset_columns(field);
      std::vector<hsize_t> dims{rows};
      if (cols) dims.push_back(cols);
      const std::string name = field.path;
      Handle space = make_space(where, dims);
      Handle dcpl = creation_properties(where, H5P_DATASET_CREATE);
      // contiguous, allocated now (so it has a file offset), never filled (every row gets written)
      check(H5Pset_layout(dcpl, H5D_CONTIGUOUS), where, "cannot set dataset properties");
      check(H5Pset_alloc_time(dcpl, H5D_ALLOC_TIME_EARLY), where, "cannot set dataset properties");
      check(H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER), where, "cannot set dataset properties");
      const hid_t type = dataset_type(field, fp32);
      Handle dataset = checked(H5Dcreate2(file, name.c_str(), type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT),
                               H5Dclose, where, fmt::format("{}: cannot create the dataset", name));
      ContactFileLayout::Dataset d{name, 0, H5Tget_size(type) * (cols ? cols : 1)};
      if (rows > 0) {
        const haddr_t offset = H5Dget_offset(dataset);
        if (offset == HADDR_UNDEF) where.fail(fmt::format("{}: no file offset for the dataset's rows", name));
        d.offset = static_cast<std::uint64_t>(offset);
      }
      layout.datasets.push_back(std::move(d));
    }
    file.close(where, "cannot close (flush) the file");
  } catch (...) {
    discard_contact_file(layout);
    throw;
  }
  return layout;
}

template <class Real>
void write_contact_rows(const ContactFileLayout& layout, std::uint64_t first_row, const Contacts<Real>& c,
                        int threads) {
  const std::uint64_t n = c.size();
  constexpr Precision precision = precision_of<Real>();
  if (!c.consistent())
    throw Error(fmt::format("{}: write_contact_rows: the contact arrays differ in length", layout.path));
  if (precision != layout.precision || c.fields() != layout.fields ||
      layout.datasets.size() != field_count(layout.fields))
    throw Error(fmt::format("{}: write_contact_rows: the rows ({}, {} fields) do not match the file ({}, {})",
                            layout.path, to_string(precision), field_count(c.fields()),
                            to_string(layout.precision), layout.datasets.size()));
  if (first_row > layout.rows || n > layout.rows - first_row)
    throw Error(fmt::format("{}: write_contact_rows: rows {} + {} are outside the file's {} rows",
                            layout.path, first_row, n, layout.rows));
  if (n == 0) return;

  std::vector<RowBlock> blocks;
  const std::vector<const unsigned char*> src = row_sources(c);
  for (std::size_t k = 0; k < layout.datasets.size(); ++k) {
    const ContactFileLayout::Dataset& d = layout.datasets[k];
    add_row_blocks(blocks, k, src[k], d.row_bytes, 0, n, d.offset + first_row * d.row_bytes, first_row);
  }
  write_row_blocks(layout, blocks, threads);
}

template void write_contact_rows<float>(const ContactFileLayout&, std::uint64_t, const Contacts<float>&, int);
template void write_contact_rows<double>(const ContactFileLayout&, std::uint64_t, const Contacts<double>&,
                                         int);

void commit_contact_file(const ContactFileLayout& layout, const RunInfo& info) {
  // The precision attribute is the run's mode (docs/FORMAT.md §2: mixed writes float64 datasets).
  const std::string precision = info.precision.empty() ? to_string(layout.precision) : info.precision;
  try {
    const bool fp32 = precision == "fp32";
    if ((precision != "fp32" && precision != "fp64" && precision != "mixed") ||
        fp32 != (layout.precision == Precision::fp32)) {
      throw Error(fmt::format("{}: write_contacts: RunInfo says precision {}, the contacts are {}",
                              layout.path, precision, to_string(layout.precision)));
    }
    LibraryLock lock;
    Where where(layout.path, true);
    Handle file = checked(H5Fopen(layout.temp.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose, where,
                          fmt::format("cannot reopen {}", layout.temp));
    Attributes attributes;
    attributes["precision"] = precision;
    if (!info.precision_choice.empty()) attributes["precision_choice"] = info.precision_choice;
    attributes["backend"] = info.backend;
    attributes["ranks"] = std::int64_t{info.ranks};
    attributes["bodies"] = static_cast<std::int64_t>(info.bodies);
    attributes["contacts"] = static_cast<std::int64_t>(layout.rows);
    attributes["cell_size"] = info.cell_size;
    attributes["software_version"] = std::string(kSoftwareVersion);
    attributes["input"] = info.input;
    if (info.ellipsoids > 0) {
      attributes["ellipsoids"] = static_cast<std::int64_t>(info.ellipsoids);
      attributes["narrow_fallbacks"] = static_cast<std::int64_t>(info.narrow_fallbacks);
      attributes["narrow_unconverged"] = static_cast<std::int64_t>(info.narrow_unconverged);
    }
    for (const StageTime& stage : info.times) {  // a stage named twice: the times add up
      auto [it, inserted] = attributes.try_emplace("time_" + stage.name, stage.seconds);
      if (!inserted) it->second = std::get<double>(it->second) + stage.seconds;
    }
    {
      Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
      for (const auto& [name, value] : attributes) write_attribute(where, root, name, value);
    }
    file.close(where, "cannot close (flush) the file");
    stop_point();  // the last one before the output appears
    if (std::rename(layout.temp.c_str(), layout.path.c_str()) != 0) {
      const int error = errno;
      throw IoError(
          fmt::format("{}: cannot rename {} over it: {}", layout.path, layout.temp, std::strerror(error)));
    }
    forget_on_stop(layout.temp);
  } catch (...) {
    discard_contact_file(layout);
    throw;
  }
}

void discard_contact_file(const ContactFileLayout& layout) noexcept {
  remove_quietly(layout.temp);
  forget_on_stop(layout.temp);
}

// ---- a contact file written as its rows come ---------------------------------------------------------

ContactFileStream::ContactFileStream(std::string path, Precision precision, FieldSet fields) {
  m_layout.path = std::move(path);
  m_layout.precision = precision;
  m_layout.fields = fields;
}

ContactFileStream::~ContactFileStream() {
  if (!m_finished) discard();
}

void ContactFileStream::discard() noexcept {
  if (m_created) discard_contact_file(m_layout);
  m_finished = true;
}

void ContactFileStream::create(std::uint64_t chunk_rows) {
  LibraryLock lock;
  m_layout.temp = temp_name(m_layout.path);
  m_chunk_rows = chunk_rows;
  const bool fp32 = m_layout.precision == Precision::fp32;
  Where where(m_layout.path, true);
  remove_on_stop(m_layout.temp);  // until commit or discard
  m_created = true;
  Handle file = create_file(where, m_layout.temp);
  create_group(where, file, "/contacts");
  for (const ContactField& field : kContactFields) {
    if (!m_layout.fields.has(field.group)) continue;
    const hsize_t cols = dataset_columns(field);
    std::vector<hsize_t> dims{0}, max{H5S_UNLIMITED}, chunk{chunk_rows};
    if (cols) {
      dims.push_back(cols);
      max.push_back(cols);
      chunk.push_back(cols);
    }
    const std::string name = field.path;
    Handle space = checked(H5Screate_simple(int(dims.size()), dims.data(), max.data()), H5Sclose, where,
                           fmt::format("{}: cannot make the dataspace", name));
    Handle dcpl = creation_properties(where, H5P_DATASET_CREATE);
    // chunked (appended to), each chunk allocated when the rows reach it, never filled
    check(H5Pset_chunk(dcpl, int(chunk.size()), chunk.data()), where, "cannot set dataset properties");
    check(H5Pset_alloc_time(dcpl, H5D_ALLOC_TIME_EARLY), where, "cannot set dataset properties");
    check(H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER), where, "cannot set dataset properties");
    const hid_t type = dataset_type(field, fp32);
    Handle dataset = checked(H5Dcreate2(file, name.c_str(), type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT),
                             H5Dclose, where, fmt::format("{}: cannot create the dataset", name));
    m_layout.datasets.push_back({name, 0, H5Tget_size(type) * (cols ? cols : 1)});
  }
  file.close(where, "cannot close (flush) the file");
}

template <class Real>
void ContactFileStream::append(const Contacts<Real>& c, int threads) {
  const std::uint64_t n = c.size(), first = m_layout.rows;
  constexpr Precision precision = precision_of<Real>();
  if (m_finished) throw Error(fmt::format("{}: ContactFileStream::append after commit", m_layout.path));
  if (!c.consistent())
    throw Error(fmt::format("{}: ContactFileStream: the contact arrays differ in length", m_layout.path));
  if (precision != m_layout.precision || c.fields() != m_layout.fields)
    throw Error(fmt::format("{}: ContactFileStream: the rows ({}, {} fields) do not match the file ({}, {})",
                            m_layout.path, to_string(precision), field_count(c.fields()),
                            to_string(m_layout.precision), field_count(m_layout.fields)));
  if (n == 0) return;
  try {
    // Chunks of a quarter of the first block (a power of two, 4 Ki to 256 Ki rows): a few MiB each
    // for large outputs, at most one chunk a dataset beyond the rows for small ones.
    if (!m_created)
      create(std::clamp<std::uint64_t>(std::bit_ceil(std::max<std::uint64_t>(n / 4, 1)), 4096, 1 << 18));
    std::vector<RowBlock> blocks;
    const std::vector<const unsigned char*> src = row_sources(c);
    {
      LibraryLock lock;
      Where where(m_layout.path, true);
      Handle file = checked(H5Fopen(m_layout.temp.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose, where,
                            fmt::format("cannot reopen {}", m_layout.temp));
      const std::uint64_t end = first + n, cr = m_chunk_rows;
      for (std::size_t k = 0; k < m_layout.datasets.size(); ++k) {
        const ContactFileLayout::Dataset& d = m_layout.datasets[k];
        Handle dataset = checked(H5Dopen2(file, d.name.c_str(), H5P_DEFAULT), H5Dclose, where,
                                 fmt::format("{}: cannot open the dataset", d.name));
        const bool vector = d.row_bytes == 3 * sizeof(Real);
        std::vector<hsize_t> extent{end};
        if (vector) extent.push_back(3);
        check(H5Dset_extent(dataset, extent.data()), where,
              fmt::format("{}: cannot extend to {} rows", d.name, end));
        for (std::uint64_t chunk = first / cr; chunk * cr < end; ++chunk) {
          std::vector<hsize_t> at{chunk * cr};
          if (vector) at.push_back(0);
          unsigned mask = 0;
          haddr_t address = HADDR_UNDEF;
          hsize_t size = 0;
          check(H5Dget_chunk_info_by_coord(dataset, at.data(), &mask, &address, &size), where,
                fmt::format("{}: cannot locate the chunk of row {}", d.name, chunk * cr));
          if (address == HADDR_UNDEF)
            where.fail(fmt::format("{}: the chunk of row {} has no file space", d.name, chunk * cr));
          const std::uint64_t lo = std::max(first, chunk * cr), hi = std::min(end, (chunk + 1) * cr);
          add_row_blocks(blocks, k, src[k], d.row_bytes, lo - first, hi - lo,
                         std::uint64_t(address) + (lo - chunk * cr) * d.row_bytes, lo);
        }
      }
      file.close(where, "cannot close (flush) the file");
    }
    write_row_blocks(m_layout, blocks, threads);
    m_layout.rows = first + n;
  } catch (...) {
    discard();
    throw;
  }
}

template void ContactFileStream::append<float>(const Contacts<float>&, int);
template void ContactFileStream::append<double>(const Contacts<double>&, int);

void ContactFileStream::commit(const RunInfo& info) {
  if (m_finished) throw Error(fmt::format("{}: ContactFileStream::commit twice", m_layout.path));
  try {
    if (!m_created) create(4096);
  } catch (...) {
    discard();
    throw;
  }
  m_finished = true;  // commit_contact_file removes the temporary on failure
  commit_contact_file(m_layout, info);
}

template <class Real>
void write_contacts(const std::string& path, const Contacts<Real>& c, const RunInfo& info, int threads) {
  if (!c.consistent())
    throw Error(fmt::format("{}: write_contacts: the contact arrays differ in length", path));
  const ContactFileLayout layout = create_contact_file(path, c.size(), precision_of<Real>(), c.fields());
  try {
    write_contact_rows(layout, 0, c, threads);
  } catch (...) {
    discard_contact_file(layout);
    throw;
  }
  commit_contact_file(layout, info);
}

template void write_contacts<float>(const std::string&, const Contacts<float>&, const RunInfo&, int);
template void write_contacts<double>(const std::string&, const Contacts<double>&, const RunInfo&, int);

namespace {

// The run record (precision, root attributes) of an open contact file, and its /contacts/id_a.
// The run record is decoded from the file's bytes (attributes.hpp); when the precision attribute is
// not a string we could decode, the real datasets' element type says it (read_contacts).
struct OpenContacts {
  Where where;
  Handle file;
  ContactFileHeader header;
  Dataset id_a;
};

void open_contacts(OpenContacts& o) {
  const Where& where = o.where;
  o.file = open_file_for_reading(where);
  const RawAttributes raw = root_attributes(where, o.file);
  if (!has_root_attribute(where, o.file, raw, "precision")) where.bad("root attribute precision is missing");
  o.header.attributes = other_attributes(raw);
  if (auto precision = o.header.attributes.find("precision"); precision != o.header.attributes.end()) {
    const auto* precision_text = std::get_if<std::string>(&precision->second);
    if (precision_text == nullptr ||
        (*precision_text != "fp32" && *precision_text != "fp64" && *precision_text != "mixed"))
      where.bad("root attribute precision is not \"fp32\", \"fp64\" or \"mixed\"");
    o.header.precision = *precision_text;
  }
  if (!group_exists(where, o.file, "/contacts")) where.bad("/contacts: missing group");
  o.id_a = open_dataset(where, o.file, kContactFields[0].path, 0, Element::integer);  // K rows
  o.header.rows = o.id_a.rows;
}

}  // namespace

ContactFileHeader read_contact_header(const std::string& path) {
  LibraryLock lock;
  OpenContacts o{Where(path, false), {}, {}, {}};
  open_contacts(o);
  return o.header;
}

ContactFile read_contacts(const std::string& path, bool optional_fields) {
  LibraryLock lock;
  OpenContacts o{Where(path, false), {}, {}, {}};
  open_contacts(o);
  const Where& where = o.where;
  const Handle& file = o.file;
  const Dataset& id_a = o.id_a;
  ContactFile out;
  out.precision = o.header.precision;
  out.attributes = std::move(o.header.attributes);
  // Every field of the table: its shape and element kind checked, its rows read (reals as double).
  // The basic fields first; the optional ones must be all present or none, group by group.
  const hsize_t k = id_a.rows;
  Contacts<double>& c = out.contacts;
  auto read_fields = [&](FieldSet set, bool optional) {
    for_each_contact_field(c, set, [&](auto index, auto& column) {
      const ContactField& f = kContactFields[index];
      if (f.optional() != optional) return;
      const bool integers = f.kind == FieldKind::integer;
      Dataset d =
          open_dataset(where, file, f.path, dataset_columns(f), integers ? Element::integer : Element::real);
      require_rows(where, d, id_a);
      column.resize(k);
      read_rows(where, d, 0, k, integers ? H5T_NATIVE_INT64 : H5T_NATIVE_DOUBLE, column.data());
      if (!integers && out.precision.empty()) out.precision = d.element_size == 4 ? "fp32" : "fp64";
    });
  };
  read_fields(FieldSet{}, false);
  auto group_present = [&](FieldGroup group, const char* what) {
    int present = 0, fields = 0;
    for (const ContactField& f : kContactFields) {
      if (f.group != group) continue;
      ++fields;
      present += path_exists(where, file, f.path) ? 1 : 0;
    }
    if (present != 0 && present != fields)
      where.bad(fmt::format("/contacts: the optional datasets ({}) must be all present or none", what));
    return present != 0;
  };
  FieldSet set{group_present(FieldGroup::full, "local points, friction directions"),
               group_present(FieldGroup::history, "age, previous_row")};
  if (!optional_fields) set = FieldSet{};  // checked, not read
  read_fields(set, true);
  c.full = set.full;
  c.history = set.history;
  return out;
}

}  // namespace cg
