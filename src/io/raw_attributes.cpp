// raw_attributes.cpp: attributes decoded from the file's bytes (see raw_attributes.hpp).
#include "io/raw_attributes.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cstdint>
#include <cstring>
#include <map>
#include <utility>
#include <vector>

#include "io/hdf5_handle.hpp"

namespace cg::h5 {

namespace {

constexpr std::uint64_t kMaxString = std::uint64_t(1) << 20;  // longer strings are not read
constexpr int kMaxChunks = 64;                                // object header chunks followed

// The file, read by pread with every offset checked against its size.
class RawFile {
 public:
  explicit RawFile(const std::string& path) : m_fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {
    struct stat st {};
    if (m_fd >= 0 && ::fstat(m_fd, &st) == 0) m_size = static_cast<std::uint64_t>(st.st_size);
  }
  ~RawFile() {
    if (m_fd >= 0) ::close(m_fd);
  }
  RawFile(const RawFile&) = delete;
  RawFile& operator=(const RawFile&) = delete;

  std::uint64_t size() const { return m_size; }
  // Bytes [at, at + n) of the file; false when they are not all inside it.
  bool read(std::uint64_t at, std::uint64_t n, std::vector<unsigned char>& out) const {
    if (m_fd < 0 || at > m_size || n > m_size - at) return false;
    out.resize(n);
    std::uint64_t done = 0;
    while (done < n) {
      const ssize_t r = ::pread(m_fd, out.data() + done, n - done, static_cast<off_t>(at + done));
      if (r <= 0) return false;
      done += static_cast<std::uint64_t>(r);
    }
    return true;
  }

 private:
  int m_fd = -1;
  std::uint64_t m_size = 0;
};

// Little-endian unsigned integer of `bytes` bytes at p[at], bounds-checked against the buffer.
bool le(const std::vector<unsigned char>& b, std::uint64_t at, unsigned bytes, std::uint64_t& v) {
  if (at > b.size() || bytes > b.size() - at) return false;
  v = 0;
  for (unsigned k = 0; k < bytes; ++k) v |= std::uint64_t(b[at + k]) << (8 * k);
  return true;
}

std::uint64_t align8(std::uint64_t n) { return (n + 7) & ~std::uint64_t(7); }

// One attribute message: its name and, when it is one element of a kind we read, its value (a
// variable-length string: the reference to its heap object, resolved later).
struct AttributeMessage {
  std::string name;
  std::optional<AttrValue> value;
  bool vlen_string = false;
  std::uint64_t length = 0, collection = 0, index = 0;
};

// The value of one element of the datatype at t[0…] (its message) stored in data; nullopt for
// types we do not read.
std::optional<AttrValue> decode_value(const std::vector<unsigned char>& t, std::uint64_t t_at,
                                      const std::vector<unsigned char>& m, std::uint64_t at) {
  std::uint64_t class_byte = 0, bits0 = 0, size = 0;
  if (!le(t, t_at, 1, class_byte) || !le(t, t_at + 1, 1, bits0) || !le(t, t_at + 4, 4, size))
    return std::nullopt;
  const unsigned type_class = class_byte & 0x0f;
  const bool big_endian = (bits0 & 1) != 0;
  auto raw = [&](std::uint64_t& v) {
    if (size == 0 || size > 8 || !le(m, at, static_cast<unsigned>(size), v)) return false;
    if (big_endian) {
      std::uint64_t swapped = 0;
      for (std::uint64_t k = 0; k < size; ++k) swapped |= ((v >> (8 * k)) & 0xff) << (8 * (size - 1 - k));
      v = swapped;
    }
    return true;
  };
  if (type_class == 0) {  // fixed-point
    std::uint64_t offset = 1, precision = 0;
    if (!(size == 1 || size == 2 || size == 4 || size == 8) || !le(t, t_at + 8, 2, offset) ||
        !le(t, t_at + 10, 2, precision) || offset != 0 || precision != 8 * size)
      return std::nullopt;
    std::uint64_t v = 0;
    if (!raw(v)) return std::nullopt;
    const bool is_signed = (bits0 & 0x08) != 0;
    if (is_signed && size < 8 && (v >> (8 * size - 1)) != 0) v |= ~std::uint64_t(0) << (8 * size);
    return static_cast<std::int64_t>(v);
  }
  if (type_class == 1) {  // floating point: IEEE binary32/binary64 only
    std::uint64_t offset = 1, precision = 0, exp_at = 0, exp_size = 0, mant_at = 1, mant_size = 0, bias = 0;
    if (!le(t, t_at + 8, 2, offset) || !le(t, t_at + 10, 2, precision) || !le(t, t_at + 12, 1, exp_at) ||
        !le(t, t_at + 13, 1, exp_size) || !le(t, t_at + 14, 1, mant_at) || !le(t, t_at + 15, 1, mant_size) ||
        !le(t, t_at + 16, 4, bias) || (bits0 & 0x40) != 0 || offset != 0 || mant_at != 0)
      return std::nullopt;
    std::uint64_t v = 0;
    if (size == 8 && precision == 64 && exp_at == 52 && exp_size == 11 && mant_size == 52 && bias == 1023 &&
        raw(v))
      return std::bit_cast<double>(v);
    if (size == 4 && precision == 32 && exp_at == 23 && exp_size == 8 && mant_size == 23 && bias == 127 &&
        raw(v))
      return static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(v)));
    return std::nullopt;
  }
  if (type_class == 3) {  // fixed-length string
    if (size == 0 || size > kMaxString || at > m.size() || size > m.size() - at) return std::nullopt;
    std::string text(reinterpret_cast<const char*>(m.data() + at), size);
    text.resize(std::strlen(text.c_str()));
    if ((bits0 & 0x0f) == 2) {
      while (!text.empty() && text.back() == ' ') text.pop_back();
    }
    return text;
  }
  return std::nullopt;
}

// A message of an object header flagged "shared" (HDF5 File Format Specification IV.A.2, message
// flags bit 1, or an attribute's datatype or dataspace flagged shared in the attribute message): its
// body is a reference into the shared-message table or to another object header.
struct SharedMessage {
  std::uint64_t type = 0;
  std::vector<unsigned char> body;
};

// Decodes an attribute message (data of `m`): ok, or damaged (its parts overrun it), or unsupported
// (shared datatype or dataspace).
RawAttributes::Status parse_attribute(const std::vector<unsigned char>& m, AttributeMessage& out,
                                      std::vector<SharedMessage>* shared) {
  using S = RawAttributes::Status;
  std::uint64_t version = 0, flags = 0, name_size = 0, type_size = 0, space_size = 0;
  if (!le(m, 0, 1, version) || !le(m, 1, 1, flags) || !le(m, 2, 2, name_size) || !le(m, 4, 2, type_size) ||
      !le(m, 6, 2, space_size))
    return S::damaged;
  const bool padded = version == 1;
  std::uint64_t pos = 8;
  if (version == 3) pos = 9;  // character set encoding
  if (version < 1 || version > 3) return S::damaged;
  if (name_size == 0 || pos + name_size > m.size()) return S::damaged;
  if (version >= 2 && (flags & 3) != 0) {  // shared datatype (1) or dataspace (2): not read
    const std::uint64_t type_at = pos + name_size, space_at = type_at + type_size;
    if (space_at > m.size() || space_size > m.size() - space_at) return S::damaged;
    auto body = [&](std::uint64_t at, std::uint64_t n) {
      return std::vector<unsigned char>(m.begin() + static_cast<std::ptrdiff_t>(at),
                                        m.begin() + static_cast<std::ptrdiff_t>(at + n));
    };
    if (shared != nullptr && (flags & 1) != 0) shared->push_back({0x03, body(type_at, type_size)});
    if (shared != nullptr && (flags & 2) != 0) shared->push_back({0x01, body(space_at, space_size)});
    return S::unsupported;
  }
  out.name.assign(reinterpret_cast<const char*>(m.data() + pos), name_size - 1);
  if (m[pos + name_size - 1] != 0) return S::damaged;
  out.name.resize(std::strlen(out.name.c_str()));
  pos += padded ? align8(name_size) : name_size;
  // datatype: class in the low nibble of byte 0; variable-length (9) of type string (1)
  const std::uint64_t type_at = pos;
  std::uint64_t class_byte = 0, bits = 0;
  if (!le(m, pos, 1, class_byte) || !le(m, pos + 1, 1, bits)) return S::damaged;
  const bool vlen_string = (class_byte & 0x0f) == 9 && (bits & 0x0f) == 1;
  pos += padded ? align8(type_size) : type_size;
  // dataspace: one element (scalar, or every dimension 1)
  std::uint64_t space_version = 0, rank = 0, space_type = 1;
  if (!le(m, pos, 1, space_version) || !le(m, pos + 1, 1, rank)) return S::damaged;
  std::uint64_t dims_at = pos + (space_version == 1 ? 8 : 4);
  if (space_version == 2 && !le(m, pos + 3, 1, space_type)) return S::damaged;
  if (space_version != 1 && space_version != 2) return S::damaged;
  if (rank > 32) return S::damaged;
  std::uint64_t points = space_type == 2 ? 0 : 1;
  for (std::uint64_t k = 0; k < rank; ++k) {
    std::uint64_t d = 0;
    if (!le(m, dims_at + 8 * k, 8, d)) return S::damaged;
    points = d != 0 && points > (std::uint64_t(1) << 32) / d ? (std::uint64_t(1) << 33) : points * d;
  }
  pos += padded ? align8(space_size) : space_size;
  if (pos > m.size()) return S::damaged;
  // The data must fit in the message (HDF5 1.10.8 copies npoints × size bytes without looking).
  std::uint64_t element = 0;
  if (!le(m, type_at + 4, 4, element)) return S::damaged;
  if (vlen_string) element = 16;
  if (points != 0 && element > (m.size() - pos) / points) return S::damaged;
  if (points != 1) return S::ok;  // (only one-element attributes are read)
  if (!vlen_string) {
    out.value = decode_value(m, type_at, m, pos);
    return S::ok;
  }
  out.vlen_string = true;
  le(m, pos, 4, out.length);
  le(m, pos + 4, 8, out.collection);
  le(m, pos + 12, 4, out.index);
  return S::ok;
}

// What else a header walk collects besides attributes.
struct HeaderWalk {
  std::vector<std::pair<std::uint64_t, std::uint64_t>> symbol_tables;  // v1 B-tree, local heap
  std::vector<SharedMessage> shared;
};

// Every attribute message of the object header at `header` (absolute) into `out`; with out ==
// nullptr, attribute messages are not decoded (only the header's layout is checked).
RawAttributes::Status header_attributes(const RawFile& f, std::uint64_t base, std::uint64_t header,
                                        unsigned version, std::vector<AttributeMessage>* out,
                                        HeaderWalk* walk = nullptr) {
  using S = RawAttributes::Status;
  struct Chunk {
    std::uint64_t at, size;
  };
  std::vector<Chunk> chunks;
  std::vector<unsigned char> b;
  bool creation_order = false;
  if (version == 1) {
    std::uint64_t size = 0;
    if (!f.read(header, 16, b) || b[0] != 1 || !le(b, 8, 4, size)) return S::damaged;
    chunks.push_back({header + 16, size});
  } else if (version == 2) {
    if (!f.read(header, 6, b) || std::memcmp(b.data(), "OHDR", 4) != 0 || b[4] != 2) return S::damaged;
    const unsigned flags = b[5];
    creation_order = (flags & 0x04) != 0;
    std::uint64_t at = header + 6 + ((flags & 0x20) ? 16 : 0) + ((flags & 0x10) ? 4 : 0);
    const unsigned width = 1u << (flags & 3);
    std::uint64_t size = 0;
    if (!f.read(at, width, b) || !le(b, 0, width, size)) return S::damaged;
    chunks.push_back({at + width, size});
  } else {
    return S::damaged;
  }
  S result = S::ok;  // unsupported parts do not end the walk: every message is seen
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    if (c >= kMaxChunks) return S::damaged;
    const Chunk chunk = chunks[c];
    std::vector<unsigned char> data;
    if (!f.read(chunk.at, chunk.size, data)) return S::damaged;
    std::uint64_t pos = 0;
    if (version == 2 && c > 0) {  // "OCHK" … checksum
      if (data.size() < 8 || std::memcmp(data.data(), "OCHK", 4) != 0) return S::damaged;
      pos = 4;
      data.resize(data.size() - 4);
    }
    const std::uint64_t prefix = version == 1 ? 8 : (creation_order ? 6 : 4);
    while (pos + prefix <= data.size()) {
      std::uint64_t type = 0, size = 0, flags = 0;
      if (version == 1) {
        le(data, pos, 2, type);
        le(data, pos + 2, 2, size);
        le(data, pos + 4, 1, flags);
      } else {
        le(data, pos, 1, type);
        le(data, pos + 1, 2, size);
        le(data, pos + 3, 1, flags);
      }
      pos += prefix;
      if (size > data.size() - pos) return S::damaged;
      std::vector<unsigned char> m(data.begin() + static_cast<std::ptrdiff_t>(pos),
                                   data.begin() + static_cast<std::ptrdiff_t>(pos + size));
      if ((flags & 0x02) != 0 && walk != nullptr) walk->shared.push_back({type, m});
      if (type == 0x10) {  // continuation: offset, length
        std::uint64_t offset = 0, length = 0;
        if (!le(m, 0, 8, offset) || !le(m, 8, 8, length)) return S::damaged;
        chunks.push_back({base + offset, length});
      } else if (type == 0x0C && out != nullptr) {
        AttributeMessage a;
        const S status = parse_attribute(m, a, walk != nullptr ? &walk->shared : nullptr);
        if (status == S::damaged) return status;
        if (status == S::ok) out->push_back(std::move(a));
        if (status == S::unsupported) result = status;
      } else if (type == 0x11 && walk != nullptr) {  // symbol table: v1 B-tree, local heap
        std::uint64_t btree = 0, heap = 0;
        if (!le(m, 0, 8, btree) || !le(m, 8, 8, heap)) return S::damaged;
        walk->symbol_tables.emplace_back(base + btree, base + heap);
      } else if (type == 0x15 &&
                 out != nullptr) {  // attribute info: dense storage when its fractal heap exists
        std::uint64_t info_flags = 0, heap = 0;
        if (!le(m, 1, 1, info_flags) || !le(m, 2 + ((info_flags & 1) ? 2 : 0), 8, heap)) return S::damaged;
        if (heap != ~std::uint64_t(0)) result = S::unsupported;
      }
      pos += size;
    }
  }
  return result;
}

struct HeapObject {
  std::uint64_t at = 0, size = 0;  // of its data in the collection
};

// The global heap collection at `at` (absolute), walked like H5HG__cache_heap_deserialize: where
// each object lies, or false when the walk leaves the collection or stalls.
bool heap_objects(const RawFile& f, std::uint64_t at, std::vector<unsigned char>& b,
                  std::map<std::uint64_t, HeapObject>& objects) {
  std::uint64_t size = 0;
  if (!f.read(at, 16, b) || std::memcmp(b.data(), "GCOL", 4) != 0 || b[4] != 1 || !le(b, 8, 8, size))
    return false;
  if (size < 16 || !f.read(at, size, b)) return false;
  std::uint64_t p = 16;
  while (p < size) {
    if (p + 16 > size) break;  // too small for an object header: free space
    std::uint64_t index = 0, object = 0;
    le(b, p, 2, index);
    le(b, p + 8, 8, object);
    std::uint64_t need = 0;
    if (index > 0) {
      if (object > size - p - 16) return false;
      need = 16 + align8(object);
      objects[index] = HeapObject{p + 16, object};
    } else {
      need = object;  // free space: its size includes its header
    }
    if (need == 0 || need > size - p) return false;
    p += need;
  }
  return p == size || p + 16 > size;
}

// The header at `at` (absolute), its version from its first bytes ("OHDR": 2, else 1); attribute
// messages are not decoded.
RawAttributes::Status walk_header(const RawFile& f, std::uint64_t base, std::uint64_t at, HeaderWalk& walk) {
  std::vector<unsigned char> b;
  if (!f.read(at, 4, b)) return RawAttributes::Status::damaged;
  const unsigned version = std::memcmp(b.data(), "OHDR", 4) == 0 ? 2 : 1;
  return header_attributes(f, base, at, version, nullptr, &walk);
}

// What is wrong with the shared messages of the header at `self` (relative), "" when nothing.
// A shared message (IV.A.2, "shared message" encoding): version 1 or 2, an object header's address
// (a committed datatype); version 3, type 1: an 8-byte id in the shared-message table (H5SM), type
// 2: an object header's address. libhdf5 1.10.8 takes type 1 of version 2 as a table id too (its
// check is an assertion, off in release builds), and looks the id up without checking that the
// file has a table (`indexes`: its number of indexes).
std::string shared_damage(const RawFile& f, std::uint64_t userblock, unsigned indexes,
                          const std::vector<SharedMessage>& shared, std::uint64_t self) {
  for (const SharedMessage& m : shared) {
    std::uint64_t version = 0, type = 0, address = 0;
    if (!le(m.body, 0, 1, version) || !le(m.body, 1, 1, type) || version < 1 || version > 3)
      return fmt::format("its header message {} is flagged shared but cannot be decoded", m.type);
    if (version >= 2 && type == 1) {
      if (indexes == 0)
        return fmt::format(
            "its header message {} is stored in a shared-message table, which the file does not have",
            m.type);
      if (version == 3) continue;  // followed by HDF5
    }
    if ((version == 3 && type != 2) || (version == 2 && type > 2))
      return fmt::format("its header message {} is flagged shared but cannot be decoded", m.type);
    if (!le(m.body, version == 1 ? 16 : 2, 8, address))
      return fmt::format("its header message {} is flagged shared but cannot be decoded", m.type);
    // The committed object must be a header of its own, inside the file, with no shared message.
    HeaderWalk target;
    if (address == ~std::uint64_t(0) || address == self ||
        walk_header(f, userblock, userblock + address, target) == RawAttributes::Status::damaged ||
        !target.shared.empty())
      return fmt::format("its header message {} refers to a damaged object header at {}", m.type, address);
  }
  return "";
}

}  // namespace

RawAttributes raw_attributes(const std::string& path, hid_t file, hid_t object) {
  using S = RawAttributes::Status;
  RawAttributes out;
  std::size_t sizeof_addr = 0, sizeof_size = 0;
  hsize_t userblock = 0;
  unsigned indexes = 0;
  {
    Handle fcpl(H5Fget_create_plist(file), H5Pclose);
    if (fcpl.get() < 0 || H5Pget_sizes(fcpl, &sizeof_addr, &sizeof_size) < 0 ||
        H5Pget_userblock(fcpl, &userblock) < 0 || H5Pget_shared_mesg_nindexes(fcpl, &indexes) < 0) {
      out.status = S::damaged;
      return out;
    }
  }
  H5O_info_t info{};
  if (sizeof_addr != 8 || sizeof_size != 8) {
    out.status = S::unsupported;
  } else if (H5Oget_info2(object, &info, H5O_INFO_BASIC | H5O_INFO_HDR) < 0 || info.addr == HADDR_UNDEF) {
    out.status = S::damaged;
  }
  if (out.status != S::ok) return out;
  RawFile f(path);
  std::vector<AttributeMessage> messages;
  HeaderWalk walk;
  out.status = header_attributes(f, userblock, userblock + info.addr, info.hdr.version, &messages, &walk);
  // (HDF5's own reads of an unsupported header would decode its shared messages: checked first)
  if (out.status != S::damaged && !shared_damage(f, userblock, indexes, walk.shared, info.addr).empty())
    out.status = S::damaged;
  if (out.status != S::ok) return out;
  for (AttributeMessage& m : messages) {
    out.names.insert(m.name);
    if (m.vlen_string) {
      if (m.collection == 0) {  // the null string
        m.value = std::string();
      } else if (m.length <= kMaxString) {
        std::vector<unsigned char> heap;
        std::map<std::uint64_t, HeapObject> objects;
        if (heap_objects(f, userblock + m.collection, heap, objects)) {
          const auto it = objects.find(m.index);
          if (it != objects.end() && it->second.size == m.length) {
            std::string text(reinterpret_cast<const char*>(heap.data() + it->second.at), m.length);
            text.resize(std::strlen(text.c_str()));  // as a C string, like HDF5's read
            m.value = std::move(text);
          }
        }
      }
    }
    if (m.value) out.values.emplace(m.name, std::move(*m.value));
  }
  return out;
}

std::string damaged_group(const std::string& path, hid_t file, hid_t group) {
  std::size_t sizeof_addr = 0, sizeof_size = 0;
  {
    Handle fcpl(H5Fget_create_plist(file), H5Pclose);
    if (fcpl.get() < 0 || H5Pget_sizes(fcpl, &sizeof_addr, &sizeof_size) < 0)
      return "unreadable file properties";
  }
  H5O_info_t info{};
  if (H5Oget_info2(group, &info, H5O_INFO_BASIC | H5O_INFO_HDR) < 0 || info.addr == HADDR_UNDEF)
    return "no object header";
  if (sizeof_addr != 8 || sizeof_size != 8) return "";  // not followed (see raw_attributes)
  hsize_t userblock = 0;
  {
    Handle fcpl(H5Fget_create_plist(file), H5Pclose);
    if (fcpl.get() < 0 || H5Pget_userblock(fcpl, &userblock) < 0) return "unreadable file properties";
  }
  RawFile f(path);
  HeaderWalk walk;
  std::vector<AttributeMessage> attributes;
  const RawAttributes::Status status =
      header_attributes(f, userblock, userblock + info.addr, info.hdr.version, &attributes, &walk);
  if (status == RawAttributes::Status::damaged) return "its object header overruns itself or the file";
  std::vector<unsigned char> b;
  for (const auto& [btree, heap] : walk.symbol_tables) {
    if (!f.read(btree, 8, b) || std::memcmp(b.data(), "TREE", 4) != 0)
      return fmt::format("its symbol table's B-tree address {} holds no B-tree", btree);
    std::uint64_t size = 0, free = 0, data = 0;
    if (!f.read(heap, 32, b) || std::memcmp(b.data(), "HEAP", 4) != 0 || b[4] != 0 || !le(b, 8, 8, size) ||
        !le(b, 16, 8, free) || !le(b, 24, 8, data))
      return fmt::format("its symbol table's local heap address {} holds no local heap", heap);
    if (size > f.size() || data + userblock > f.size() - size || (free != 1 && free >= size))
      return fmt::format("its local heap at {} (data {} bytes at {}) lies outside the file", heap, size,
                         data);
    // The free list, walked as H5HL__fl_deserialize walks it (which, on a list that loops, appends
    // blocks without end: memory grows until the process is killed): each block (offset of the
    // next, its size) inside the data, of non-zero size; at most one block per 16 bytes of data.
    if (free != 1) {
      std::vector<unsigned char> heap_data;
      if (!f.read(data + userblock, size, heap_data))
        return fmt::format("its local heap at {} (data {} bytes at {}) lies outside the file", heap, size,
                           data);
      std::uint64_t block = free, blocks = 0;
      while (block != 1) {
        std::uint64_t next = 0, block_size = 0;
        if (block >= size || ++blocks > size / 16 + 1 || !le(heap_data, block, 8, next) ||
            !le(heap_data, block + 8, 8, block_size) || next == 0 || block_size > size - block)
          return fmt::format("its local heap at {} has a damaged free list (block at {})", heap, block);
        block = next;
      }
    }
  }
  return "";
}

std::string damaged_object(const std::string& path, hid_t file, const std::string& name) {
  std::size_t sizeof_addr = 0, sizeof_size = 0;
  hsize_t userblock = 0;
  unsigned indexes = 0;
  {
    Handle fcpl(H5Fget_create_plist(file), H5Pclose);
    if (fcpl.get() < 0 || H5Pget_sizes(fcpl, &sizeof_addr, &sizeof_size) < 0 ||
        H5Pget_userblock(fcpl, &userblock) < 0 || H5Pget_shared_mesg_nindexes(fcpl, &indexes) < 0)
      return "unreadable file properties";
  }
  if (sizeof_addr != 8 || sizeof_size != 8) return "";  // not followed (see raw_attributes)
  H5L_info_t link{};
  if (H5Lget_info(file, name.c_str(), &link, H5P_DEFAULT) < 0) return "";  // HDF5 reports it on opening
  if (link.type != H5L_TYPE_HARD) return "";                               // resolved by HDF5
  RawFile f(path);
  HeaderWalk walk;
  if (walk_header(f, userblock, userblock + link.u.address, walk) == RawAttributes::Status::damaged)
    return "its object header overruns itself or the file";
  return shared_damage(f, userblock, indexes, walk.shared, link.u.address);
}

}  // namespace cg::h5
