// The CUDA backend against its oracle, the CPU backend: every field of every contact bit-identical
// (fp64 and fp32), on random and adversarial scenes; the persistent workspace; the device-array API
// (the example of engine.hpp, compiled and run here). Every case skips, visibly, without a GPU.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "engine.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

#if defined(CONTACTGRID_HAVE_CUDA)
#include <cuda_runtime.h>
#endif

namespace cg::test {
namespace {

#define CG_SKIP_WITHOUT_CUDA()                                                                        \
  do {                                                                                                \
    if (!::cg::cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped"; \
  } while (0)

template <class Real>
void expect_identical(const Contacts<Real>& cpu, const Contacts<Real>& gpu, const std::string& what) {
  ASSERT_EQ(cpu.size(), gpu.size()) << what;
  ASSERT_EQ(cpu.full, gpu.full) << what;
  EXPECT_EQ(compare_contacts(gpu, cpu), "identical") << what;
}

template <class Real>
class CudaBackendTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_CUDA(); }

  void compare(const Spheres& s, Fields fields, double cell = 0, std::span<const std::int64_t> ids = {},
               std::span<const std::uint8_t> report = {}) {
    EngineOptions o;
    o.fields = fields;
    o.cell_size = cell;
    o.cell_choice = CellChoice::smallest;  // the scenes' adversarial geometry is drawn for it
    o.backend = Backend::cpu;
    Engine<Real> cpu(o);
    o.backend = Backend::cuda;
    Engine<Real> gpu(o);
    const BodiesView v{s.p, s.r, ids, report};
    const Contacts<Real> a = cpu.detect(v);
    const Contacts<Real> b = gpu.detect(v);
    expect_identical(a, b, s.name + " " + to_string(fields));
    EXPECT_EQ(cpu.stats().entries, gpu.stats().entries) << s.name;
    EXPECT_EQ(cpu.stats().pair_tests, gpu.stats().pair_tests) << s.name;
    EXPECT_GT(gpu.stats().peak_device_bytes, 0u);
  }
};
using Reals = ::testing::Types<double, float>;
struct RealNames {
  template <class T>
  static std::string GetName(int) {
    return sizeof(T) == 4 ? "fp32" : "fp64";
  }
};
TYPED_TEST_SUITE(CudaBackendTest, Reals, RealNames);

TYPED_TEST(CudaBackendTest, BitIdenticalToCpuOnScenes) {
  std::uint64_t seed = 1001;
  for (std::size_t n : {1u, 2u, 5u, 100u, 3000u, 60000u})
    this->compare(random_spheres(n, 0.5, 1.0, seed++), Fields::basic);
  this->compare(random_spheres(20000, 0.001, 1.0, 1011, true), Fields::full);
  this->compare(clustered(4000, 1012), Fields::full);
  this->compare(one_cell(400, 1013), Fields::full);
  this->compare(on_boundaries(1014), Fields::full, 2.0);
  this->compare(on_boundaries(1015), Fields::basic, 1.0 + 1e-3);
  this->compare(coincident(1016), Fields::full);
  this->compare(tangent(1017), Fields::full);
  this->compare(random_spheres(5000, 0.5, 1.0, 1018).translated({1e6, -1e6, 1e6}), Fields::full);
}

// The backend's alternative paths, forced through their knobs (each is otherwise chosen by the scene
// size against the L2 or opted into): the same bits as the CPU on dense, sparse and masked scenes.
TYPED_TEST(CudaBackendTest, EveryPathIsBitIdentical) {
  struct Knob {
    const char *name, *value;
  };
  struct Unset {  // the knob is removed even when an assertion fails
    const char* name;
    ~Unset() { ::unsetenv(name); }
  };
  auto masked = random_spheres(6000, 0.5, 1.0, 1031);
  std::vector<std::int64_t> ids(masked.r.size());
  std::vector<std::uint8_t> report(masked.r.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ids[i] = std::int64_t(3 * i + 1);
    report[i] = static_cast<std::uint8_t>(((i % 3) != 0 ? kReportedBit : 0) | (i % 5 < 2 ? kPairedBit : 0));
  }
  for (const Knob& k :
       {Knob{"CONTACTGRID_CUDA_TYPE_PASSES", "1"}, Knob{"CONTACTGRID_CUDA_RENUMBER", "0"},
        Knob{"CONTACTGRID_CUDA_RENUMBER", "1"}, Knob{"CONTACTGRID_CUDA_ORDER", "radix"},
        Knob{"CONTACTGRID_CUDA_ORDER", "counting"}, Knob{"CONTACTGRID_CUDA_DOWNLOAD", "registered"},
        Knob{"CONTACTGRID_CUDA_DOWNLOAD", "staged"}, Knob{"CONTACTGRID_CUDA_DOWNLOAD", "streamed"},
        Knob{"CONTACTGRID_CUDA_UPLOAD", "registered"}, Knob{"CONTACTGRID_CUDA_UPLOAD", "pageable"},
        Knob{"CONTACTGRID_CUDA_UPLOAD", "streamed"}}) {
    SCOPED_TRACE(std::string(k.name) + "=" + k.value);
    ::setenv(k.name, k.value, 1);
    Unset unset{k.name};
    this->compare(random_spheres(30000, 0.5, 1.0, 1032), Fields::full);
    this->compare(random_spheres(8000, 0.01, 1.0, 1033, true), Fields::basic);
    this->compare(clustered(3000, 1034), Fields::basic);
    this->compare(one_cell(300, 1035), Fields::full);
    this->compare(masked, Fields::full, 0, ids, report);
  }
}

// Streamed transfers through slots of 64 KiB: every upload and download wraps around the pinned ring
// several times (8 slots), one engine reused over scenes of growing and shrinking size, so a slot is
// refilled while the previous call's copies may still use it. The same bits as the CPU.
TYPED_TEST(CudaBackendTest, StreamedTransfersWrapAroundTheRing) {
  const char* knobs[] = {"CONTACTGRID_CUDA_UPLOAD", "CONTACTGRID_CUDA_DOWNLOAD",
                         "CONTACTGRID_CUDA_TRANSFER_SLOT"};
  struct Unset {  // the knobs are removed even when an assertion fails
    const char* const* names;
    ~Unset() {
      for (int i = 0; i < 3; ++i) ::unsetenv(names[i]);
    }
  } unset{knobs};
  ::setenv("CONTACTGRID_CUDA_UPLOAD", "streamed", 1);
  ::setenv("CONTACTGRID_CUDA_DOWNLOAD", "streamed", 1);
  ::setenv("CONTACTGRID_CUDA_TRANSFER_SLOT", "65536", 1);
  this->compare(random_spheres(60000, 0.5, 1.0, 1041), Fields::full);  // 1.9 MB up: 30 slots
  this->compare(random_spheres(3, 0.5, 1.0, 1042), Fields::full);
  this->compare(clustered(20000, 1043), Fields::basic);
  this->compare(one_cell(700, 1044), Fields::full);
  ::setenv("CONTACTGRID_CUDA_TRANSFER_SLOT", "4096", 1);  // another slot size: the ring is remade
  this->compare(random_spheres(30000, 0.5, 1.0, 1045), Fields::basic);
}

TYPED_TEST(CudaBackendTest, BitIdenticalWithIdsAndReportMask) {
  auto s = random_spheres(8000, 0.5, 1.0, 1021);
  std::vector<std::int64_t> ids(s.r.size());
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ids[i] = std::int64_t(7 + 5 * i);
    report[i] = (i % 4) != 1;
  }
  this->compare(s, Fields::full, 0, ids, report);
}

TYPED_TEST(CudaBackendTest, LargeKeys64BitGrid) {
  // A sparse scene wide enough that the grid needs > 2^32 cells: 64-bit cell keys on both backends.
  Spheres s;
  s.name = "sparse wide";
  std::mt19937_64 rng(1031);
  std::uniform_real_distribution<double> u(0, 1);
  const double span = sizeof(TypeParam) == 4 ? 3.0e6 : 4.0e6;  // fp32: < 2^22 cells per axis
  for (int i = 0; i < 3000; ++i) {
    const double x = u(rng) * span, y = u(rng) * span, z = u(rng) * span;
    s.add(x, y, z, 0.5 + 0.5 * u(rng));
    s.add(x + 1.2, y, z + 0.3, 0.5 + 0.5 * u(rng));  // a partner so that there are contacts
  }
  if constexpr (sizeof(TypeParam) == 8) {
    this->compare(s, Fields::full);
  } else {
    // fp32 refuses a scene whose float32 world positions would err by more than r_max/4 (3e6: 0.25);
    // its float grid with 64-bit keys runs as mixed's broad phase (Engine<double>, fp32_broad_phase).
    EngineOptions o;
    o.fields = Fields::full;
    o.cell_choice = CellChoice::smallest;
    const BodiesView v{s.p, s.r, {}, {}};
    o.backend = Backend::cuda;
    EXPECT_THROW(Engine<float>(o).detect(v), InputError);
    o.fp32_broad_phase = true;
    Engine<double> gpu(o);
    o.backend = Backend::cpu;
    Engine<double> cpu(o);
    const Contacts<double> a = cpu.detect(v), b = gpu.detect(v);
    expect_identical(a, b, s.name + " mixed");
    EXPECT_GT(gpu.stats().key_bits, 32) << "the float grid needs 64-bit keys here";
    EXPECT_EQ(cpu.stats().pair_tests, gpu.stats().pair_tests);
  }
}

TYPED_TEST(CudaBackendTest, WorkspaceIsReusedAcrossFrames) {
  EngineOptions o;
  o.backend = Backend::cuda;
  Engine<TypeParam> e(o);
  auto s = random_spheres(20000, 0.5, 1.0, 1041);
  const BodiesView v{s.p, s.r, {}, {}};
  auto first = e.detect(v);
  EXPECT_GT(e.stats().device_allocations, 0u);
  const auto held = e.stats().peak_device_bytes;
  for (int frame = 0; frame < 3; ++frame) {
    auto again = e.detect(v);
    EXPECT_EQ(e.stats().device_allocations, 0u) << "frame " << frame;
    EXPECT_EQ(e.stats().peak_device_bytes, held);
    expect_identical(first, again, "frame " + std::to_string(frame));
  }
  auto small = random_spheres(500, 0.5, 1.0, 1042);
  e.detect(BodiesView{small.p, small.r, {}, {}});
  EXPECT_EQ(e.stats().device_allocations, 0u) << "a smaller frame must fit the workspace";
  std::vector<std::string> names;
  for (const auto& t : e.times()) names.push_back(t.name);
  const std::vector<std::string> expect{"plan",  "upload", "pack",   "entries", "sort",
                                        "pairs", "order",  "narrow", "download"};
  EXPECT_EQ(names, expect);
}

#if defined(CONTACTGRID_HAVE_CUDA)
// Device copies of a scene's positions (3n doubles) and radii, freed at scope exit.
struct DeviceScene {
  double* d_pos = nullptr;
  double* d_rad = nullptr;
  std::uint8_t* d_report = nullptr;
  explicit DeviceScene(const Spheres& s, std::span<const std::uint8_t> report = {}) {
    const std::size_t n = s.r.size();
    EXPECT_EQ(cudaMalloc(&d_pos, 3 * n * sizeof(double)), cudaSuccess);
    EXPECT_EQ(cudaMalloc(&d_rad, n * sizeof(double)), cudaSuccess);
    EXPECT_EQ(cudaMemcpy(d_pos, s.p.data(), 3 * n * sizeof(double), cudaMemcpyHostToDevice), cudaSuccess);
    EXPECT_EQ(cudaMemcpy(d_rad, s.r.data(), n * sizeof(double), cudaMemcpyHostToDevice), cudaSuccess);
    if (!report.empty()) {
      EXPECT_EQ(cudaMalloc(&d_report, n), cudaSuccess);
      EXPECT_EQ(cudaMemcpy(d_report, report.data(), n, cudaMemcpyHostToDevice), cudaSuccess);
    }
  }
  ~DeviceScene() {
    cudaFree(d_pos);
    cudaFree(d_rad);
    cudaFree(d_report);
  }
};

template <class T>
HostVector<T> to_host(const T* d, std::size_t n) {
  HostVector<T> h(n);
  if (n) {
    EXPECT_EQ(cudaMemcpy(h.data(), d, n * sizeof(T), cudaMemcpyDeviceToHost), cudaSuccess);
  }
  return h;
}

// The example of engine.hpp (Engine::detect_device), as a simulation would call it every step.
TYPED_TEST(CudaBackendTest, DeviceArrayApiExample) {
  using Real = TypeParam;
  auto s = random_spheres(30000, 0.5, 1.0, 1051);
  const std::size_t n = s.r.size();
  DeviceScene scene(s);
  double* d_pos = scene.d_pos;
  double* d_rad = scene.d_rad;

  cg::Engine<Real> engine({.backend = cg::Backend::cuda, .fields = cg::Fields::full});
  cg::DeviceBodiesView bodies{.position = d_pos, .radius = d_rad, .count = n};
  cg::Contacts<Real> c = engine.detect_device(bodies);
  cg::DeviceContactsView<Real> dc = engine.detect_device_resident(bodies);
  EXPECT_EQ(engine.stats().device_allocations, 0u) << "second step allocated";

  // Same bits as the host-array path, and as the CPU backend.
  Engine<Real> cpu({.backend = Backend::cpu, .fields = Fields::full});
  const Contacts<Real> ref = cpu.detect(BodiesView{s.p, s.r, {}, {}});
  expect_identical(ref, c, "detect_device");
  ASSERT_EQ(dc.count, ref.size());
  ASSERT_TRUE(dc.full);
  Contacts<Real> back;
  back.full = true;
  zip_contact_fields(back, dc, true,
                     [&](auto, auto& column, const auto* d) { column = to_host(d, dc.count); });
  expect_identical(ref, back, "detect_device_resident");
  std::vector<std::string> names;
  for (const auto& t : engine.times()) names.push_back(t.name);
  const std::vector<std::string> expect{"plan", "pack", "entries", "sort", "pairs", "order", "narrow"};
  EXPECT_EQ(names, expect);
}

TYPED_TEST(CudaBackendTest, DeviceArrayApiReportMaskAndFrame) {
  auto s = random_spheres(10000, 0.5, 1.0, 1061);
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < report.size(); ++i) report[i] = (i % 3) == 0;
  DeviceScene scene(s, report);
  const Frame frame{{-5, -6, -7}, 2.5};
  Engine<TypeParam> gpu({.backend = Backend::cuda});
  Engine<TypeParam> cpu({.backend = Backend::cpu});
  auto c = gpu.detect_device({scene.d_pos, scene.d_rad, scene.d_report, s.r.size()}, frame);
  auto ref = cpu.detect(BodiesView{s.p, s.r, {}, report}, frame);
  expect_identical(ref, c, "report mask + frame");
  EXPECT_EQ(gpu.stats().pair_tests, cpu.stats().pair_tests);
}

TYPED_TEST(CudaBackendTest, DeviceArrayApiNamesBadBodies) {
  Spheres s;
  s.add(0, 0, 0, 1);
  s.add(1, std::nan(""), 0, 1);
  s.add(2, 0, 0, 1);
  s.add(3, 0, 0, -1);
  Engine<TypeParam> e({.backend = Backend::cuda});
  DeviceScene scene(s);
  const DeviceBodiesView v{scene.d_pos, scene.d_rad, nullptr, s.r.size()};
  std::string device_text, host_text;
  try {
    e.detect_device(v);
  } catch (const InputError& x) {
    device_text = x.what();
  }
  try {
    compute_bounds(BodiesView{s.p, s.r, {}, {}});
  } catch (const InputError& x) {
    host_text = x.what();
  }
  EXPECT_NE(device_text.find("body 1"), std::string::npos) << device_text;
  EXPECT_EQ(device_text, host_text);
  Spheres r;
  r.add(0, 0, 0, 1);
  r.add(1, 0, 0, 0);
  DeviceScene rs(r);
  EXPECT_THROW(e.detect_device({rs.d_pos, rs.d_rad, nullptr, 2}), InputError);
  // empty input: no contacts, no error
  EXPECT_EQ(e.detect_device({rs.d_pos, rs.d_rad, nullptr, 0}).size(), 0u);
}
#endif

TEST(CudaBackendApi, DeviceApiNeedsCudaBackend) {
  Engine<double> e({.backend = Backend::cpu});
  EXPECT_THROW(e.detect_device({}), UsageError);
}

}  // namespace
}  // namespace cg::test

namespace cg::test {
namespace {

// A scene larger than the device memory it may use: a ResourceError saying how many bytes are
// needed, no crash; with the cap lifted the same engine object works again.
TEST(CudaBackendMemory, TooLargeForTheDeviceIsAClearError) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  auto s = random_spheres(std::size_t(1) << 20, 0.5, 1.0, 1071);
  Engine<float> engine({.backend = Backend::cuda});
  ::setenv("CONTACTGRID_DEVICE_MEMORY_LIMIT", std::to_string(std::size_t(70) << 20).c_str(), 1);
  try {
    engine.detect(BodiesView{s.p, s.r, {}, {}});
    ADD_FAILURE() << "no ResourceError with a 70 MiB device cap";
  } catch (const ResourceError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("needs"), std::string::npos) << m;
    EXPECT_NE(m.find("bytes"), std::string::npos) << m;
  }
  ::unsetenv("CONTACTGRID_DEVICE_MEMORY_LIMIT");
  Engine<float> cpu({.backend = Backend::cpu});
  EXPECT_EQ(engine.detect(BodiesView{s.p, s.r, {}, {}}).size(),
            cpu.detect(BodiesView{s.p, s.r, {}, {}}).size());
}

}  // namespace
}  // namespace cg::test
