// The oracle's exchange files (format in bullet_oracle.hpp) and the warm-step displacement: the parts
// of the oracle that both Bullet flavours share and that contain no Bullet code. Linked into
// cg_validate and into contactgrid-bullet-float.
//
// Invariants: every read checks the magic, the sizes and that the file ends where the counts say;
// any mismatch is an IoError naming the file (the two ends are always the same build).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>

#include "errors.hpp"
#include "validate/bullet_oracle.hpp"

namespace cg {
namespace {

constexpr char kInputMagic[8] = {'C', 'G', 'B', 'O', 'I', 'N', '0', '3'};
constexpr char kOutputMagic[8] = {'C', 'G', 'B', 'O', 'O', 'U', 'T', '2'};

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

class BinaryFile {
 public:
  BinaryFile(const std::string& path, const char* mode)
      : m_path(path), m_file(std::fopen(path.c_str(), mode)) {
    if (!m_file) throw IoError("oracle exchange: cannot open " + path);
  }
  void write(const void* data, std::size_t bytes) {
    if (bytes && std::fwrite(data, 1, bytes, m_file.get()) != bytes)
      throw IoError("oracle exchange: cannot write " + m_path);
  }
  void read(void* data, std::size_t bytes) {
    if (bytes && std::fread(data, 1, bytes, m_file.get()) != bytes)
      throw IoError("oracle exchange: " + m_path + " is truncated");
  }
  template <class T>
  void put(const T& v) {
    write(&v, sizeof v);
  }
  template <class T>
  T get() {
    T v;
    read(&v, sizeof v);
    return v;
  }
  void expect_magic(const char (&magic)[8]) {
    char m[8];
    read(m, 8);
    if (std::memcmp(m, magic, 8) != 0) throw IoError("oracle exchange: " + m_path + " has a bad header");
  }
  void expect_end() {
    if (std::fgetc(m_file.get()) != EOF) throw IoError("oracle exchange: " + m_path + " has trailing data");
  }
  void close() {
    if (std::fclose(m_file.release()) != 0) throw IoError("oracle exchange: cannot write " + m_path);
  }

 private:
  std::string m_path;
  std::unique_ptr<std::FILE, FileCloser> m_file;
};

// Counts read from a file are checked against a bound before allocating.
std::uint64_t checked_count(std::uint64_t n, const std::string& path) {
  if (n > (std::uint64_t(1) << 34)) throw IoError("oracle exchange: " + path + " has a bad count");
  return n;
}

}  // namespace

std::uint64_t peak_resident_bytes() {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0;
  char line[256];
  unsigned long long kib = 0;
  bool found = false;
  while (!found && std::fgets(line, sizeof line, f)) found = std::sscanf(line, "VmHWM: %llu kB", &kib) == 1;
  std::fclose(f);
  return found ? std::uint64_t(kib) * 1024 : 0;
}

Vec3<double> warm_step_displacement(std::size_t index, double radius) {
  // A fixed direction per body from a golden-ratio sequence on the sphere: no RNG, same in both
  // flavours, never zero.
  const double golden = 0.6180339887498949;
  const double u = std::fmod(double(index) * golden, 1.0);
  const double v = std::fmod(double(index) * golden * golden + 0.5, 1.0);
  const double z = 2 * u - 1, phi = 2 * 3.141592653589793 * v;
  const double s = std::sqrt(std::max(0.0, 1 - z * z));
  return (1e-3 * radius) * Vec3<double>{s * std::cos(phi), s * std::sin(phi), z};
}

void write_oracle_input(const std::string& path, const OracleBodies& s, bool warm_step) {
  BinaryFile f(path, "wb");
  f.write(kInputMagic, 8);
  f.put<std::uint64_t>(s.size());
  f.put<std::uint8_t>(warm_step ? 1 : 0);
  f.put(s.origin);
  f.put(s.scale);
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Vec3<double> e = s.is_ellipsoid(i) ? s.semi_axes[i] : Vec3<double>{0, 0, 0};
    const std::array<double, 4> q = s.is_ellipsoid(i) ? s.orientation[i] : std::array<double, 4>{1, 0, 0, 0};
    const double row[11] = {s.position[i].x,
                            s.position[i].y,
                            s.position[i].z,
                            s.radius[i],
                            e.x,
                            e.y,
                            e.z,
                            q[0],
                            q[1],
                            q[2],
                            q[3]};
    f.write(row, sizeof row);
  }
  f.write(s.id.data(), s.id.size() * sizeof(std::int64_t));
  for (std::size_t i = 0; i < s.size(); ++i) f.put<std::uint8_t>(s.partner.empty() ? 0 : s.partner[i]);
  f.close();
}

OracleBodies read_oracle_input(const std::string& path, bool& warm_step) {
  BinaryFile f(path, "rb");
  f.expect_magic(kInputMagic);
  const std::uint64_t n = checked_count(f.get<std::uint64_t>(), path);
  warm_step = f.get<std::uint8_t>() != 0;
  OracleBodies s;
  s.origin = f.get<Vec3<double>>();
  s.scale = f.get<double>();
  if (!(s.scale > 0) || !std::isfinite(s.scale))
    throw IoError("oracle exchange: " + path + " has a bad scale");
  s.position.resize(n);
  s.radius.resize(n);
  s.semi_axes.resize(n);
  s.orientation.resize(n);
  s.id.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    double row[11];
    f.read(row, sizeof row);
    s.position[i] = {row[0], row[1], row[2]};
    s.radius[i] = row[3];
    s.semi_axes[i] = {row[4], row[5], row[6]};
    s.orientation[i] = {row[7], row[8], row[9], row[10]};
  }
  f.read(s.id.data(), n * sizeof(std::int64_t));
  s.partner.resize(n);
  f.read(s.partner.data(), n);
  f.expect_end();
  return s;
}

void write_oracle_output(const std::string& path, const OracleResult& r) {
  BinaryFile f(path, "wb");
  f.write(kOutputMagic, 8);
  f.put<std::uint32_t>(std::uint32_t(r.scalar_bytes));
  f.put<double>(r.scratch_seconds);
  f.put<double>(r.warm_seconds);
  f.put<std::uint64_t>(r.pairs);
  f.put<std::uint64_t>(peak_resident_bytes());  // the writer's own: the float executable's
  const Contacts<double>& c = r.contacts;
  f.put<std::uint64_t>(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    f.put(c.id_a[i]);
    f.put(c.id_b[i]);
    f.put(c.position_on_a[i]);
    f.put(c.position_on_b[i]);
    f.put(c.normal_on_b[i]);
    f.put(c.distance[i]);
  }
  f.close();
}

OracleResult read_oracle_output(const std::string& path) {
  BinaryFile f(path, "rb");
  f.expect_magic(kOutputMagic);
  OracleResult r;
  r.scalar_bytes = int(f.get<std::uint32_t>());
  r.scratch_seconds = f.get<double>();
  r.warm_seconds = f.get<double>();
  r.pairs = f.get<std::uint64_t>();
  r.child_peak_bytes = f.get<std::uint64_t>();
  const std::uint64_t k = checked_count(f.get<std::uint64_t>(), path);
  Contacts<double>& c = r.contacts;
  for (std::uint64_t i = 0; i < k; ++i) {
    c.id_a.push_back(f.get<std::int64_t>());
    c.id_b.push_back(f.get<std::int64_t>());
    c.position_on_a.push_back(f.get<Vec3<double>>());
    c.position_on_b.push_back(f.get<Vec3<double>>());
    c.normal_on_b.push_back(f.get<Vec3<double>>());
    c.distance.push_back(f.get<double>());
  }
  f.expect_end();
  return r;
}

}  // namespace cg
