// The CUDA host paths (cuda/tuning.hpp: HostPath): by default the bodies go up first and the device
// takes their bounds (kernels/engine.cpp: detect_host_on_device); `packed`: fp32 sphere calls upload the
// 16-byte spheres the host packs (upload_pack.hpp); both download an engine's later calls straight
// into the result vectors' page-locked pool blocks (HostPool::lock_block). On the CPU: the host packing
// against the CPU backend's pack, and the pool's locking. On a GPU (skipped visibly without one): the
// same bytes every way and as the CPU backend, through small pinned slots that put chunk boundaries
// inside the arrays, with rows that need the world doubles; a bad body named by id as the CPU names it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "backend.hpp"
#include "engine.hpp"
#include "grid_plan.hpp"
#include "host_vector.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "upload_pack.hpp"

namespace cg::test {
namespace {

// The host packing of the 16-byte upload gives the bits of the CPU backend's pack (radius margin 0,
// fp32), in windows of any size and on any number of threads, for a scene far from its origin.
TEST(UploadPack, EqualsTheCpuPackBitForBit) {
  const Spheres s = random_spheres(70001, 0.1, 1.7, 3701, true).translated({1234.5, -77.25, 1e4 / 3});
  const BodiesView v{s.p, s.r, {}, {}};
  const Vec3<double> origin{1100.125, -200.0 / 3, 3000.0};
  GridParams<float> g{};
  g.inv_cell = 0.25f;
  g.radius_margin = 0.0f;
  detail::host::PackedBodies<float> cpu;
  detail::host::pack<float>(v, origin, g, 0.0f, false, 2, cpu);
  for (const std::size_t window : {std::size_t(70001), std::size_t(777), std::size_t(1)}) {
    for (const int threads : {1, 2}) {
      std::vector<Sphere<float>> up(s.r.size());
      for (std::size_t first = 0; first < s.r.size(); first += window) {
        const std::size_t end = std::min(s.r.size(), first + window);
        detail::pack_upload_spheres(s.p.data(), s.r.data(), origin, first, end, up.data() + first, threads);
      }
      for (std::size_t i = 0; i < s.r.size(); ++i)
        ASSERT_EQ(std::memcmp(&up[i], &cpu.spheres[i], sizeof(Sphere<float>)), 0)
            << "body " << i << ", window " << window << ", threads " << threads;
    }
  }
}

// parallel_copy (the ring's fills and drains): the bytes of memcpy for blocks of every alignment and
// size, pieces split at any byte, one thread or all.
TEST(ParallelCopy, GivesMemcpysBytesAtEveryAlignment) {
  std::mt19937_64 rng(3727);
  std::vector<std::byte> src((std::size_t(9) << 20) + 333), dst(src.size()), want(src.size());
  for (auto& b : src) b = std::byte(rng() & 0xff);
  for (const std::size_t skew : {std::size_t(0), std::size_t(1), std::size_t(7), std::size_t(13)}) {
    std::fill(dst.begin(), dst.end(), std::byte{0x5a});
    want = dst;
    // three blocks laid end to end: 5000 bytes, 4 MiB + 17, the rest but a tail left alone
    const std::size_t a = 5000, b = (std::size_t(4) << 20) + 17, c = src.size() - 64 - a - b - skew;
    const detail::CopyBlock blocks[] = {{dst.data() + skew, src.data() + 3, a},
                                        {dst.data() + skew + a, src.data() + 3 + a, b},
                                        {dst.data() + skew + a + b, src.data() + 11 + a + b, c}};
    std::memcpy(want.data() + skew, src.data() + 3, a + b);
    std::memcpy(want.data() + skew + a + b, src.data() + 11 + a + b, c);
    for (const int threads : {1, 0}) {
      detail::parallel_copy(blocks, 3, threads);
      ASSERT_TRUE(dst == want) << "skew " << skew << ", threads " << threads;
    }
  }
}

// ids_ascending (the default CUDA host path's check of the ids): compute_bounds' verdict on the ids,
// on one thread or all, a violation anywhere in a long array found.
TEST(IdsAscending, AgreesWithComputeBounds) {
  EXPECT_TRUE(ids_ascending({}, 0));
  const std::vector<std::int64_t> one{5}, up{1, 2, 9}, equal{1, 2, 2}, down{3, 2};
  EXPECT_TRUE(ids_ascending(one, 0));
  EXPECT_TRUE(ids_ascending(up, 1));
  EXPECT_FALSE(ids_ascending(equal, 0));
  EXPECT_FALSE(ids_ascending(down, 0));
  std::vector<std::int64_t> many(300001);
  for (std::size_t i = 0; i < many.size(); ++i) many[i] = 3 * std::int64_t(i) - 7;
  for (const int threads : {1, 0}) EXPECT_TRUE(ids_ascending(many, threads));
  for (const std::size_t at : {std::size_t(1), std::size_t(150000), many.size() - 1}) {
    std::vector<std::int64_t> bad = many;
    bad[at] = bad[at - 1];
    for (const int threads : {1, 0}) EXPECT_FALSE(ids_ascending(bad, threads)) << "at " << at;
  }
}

// A pooled block is locked once, stays locked while it is free in the pool and is reused, and is
// unlocked before the pool frees it; an array outside the pool is never locked.
int g_locks = 0, g_unlocks = 0;
void* g_unlocked = nullptr;
bool count_lock(void*, std::size_t) { return ++g_locks > 0; }
void count_unlock(void* p) {
  ++g_unlocks;
  g_unlocked = p;
}
bool refuse_lock(void*, std::size_t) { return false; }

TEST(HostPoolLocks, ABlockIsLockedOnceAndUnlockedBeforeItIsFreed) {
  detail::HostPool& pool = detail::HostPool::instance();
  pool.release_all();
  g_locks = g_unlocks = 0;
  void* block = nullptr;
  {
    HostVector<std::byte> big(std::size_t(3) << 20);
    block = big.data();
    EXPECT_FALSE(pool.block_locked(block));
    EXPECT_GE(pool.lock_block(block, count_lock, count_unlock), big.size());
    EXPECT_GE(pool.lock_block(block, count_lock, count_unlock), big.size());
    EXPECT_EQ(g_locks, 1);
    EXPECT_TRUE(pool.block_locked(block));
    HostVector<std::byte> small(4096);
    EXPECT_EQ(pool.lock_block(small.data(), count_lock, count_unlock), 0u);
    EXPECT_EQ(g_locks, 1);
    HostVector<std::byte> other(std::size_t(5) << 20);
    EXPECT_EQ(pool.lock_block(other.data(), refuse_lock, count_unlock), 0u);
    EXPECT_FALSE(pool.block_locked(other.data()));
  }
  const char* cap = std::getenv("CONTACTGRID_HOST_POOL_MIB");
  if (!cap || std::strtoull(cap, nullptr, 10) >= 8) {  // the freed block is kept, still locked
    EXPECT_EQ(g_unlocks, 0);
    HostVector<std::byte> again(std::size_t(3) << 20);
    EXPECT_EQ(static_cast<void*>(again.data()), block) << "the pool hands the freed block out again";
    EXPECT_TRUE(pool.block_locked(again.data()));
  }
  pool.release_all();
  EXPECT_EQ(g_unlocks, 1);
  EXPECT_EQ(g_unlocked, block);
  EXPECT_EQ(g_locks, 1);
}

#define CG_SKIP_WITHOUT_CUDA()                                                                        \
  do {                                                                                                \
    if (!::cg::cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped"; \
  } while (0)

// A jittered cubic lattice a little tighter than a diameter (about 3 contacts a sphere, so every
// basic field of the rows is a pooled block: >= 1 MiB), and at every 97th site a second sphere a few
// ulps off: rows whose normal fp32 cannot resolve (the world doubles' rows).
Spheres lattice_with_twins(int side, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  Spheres s;
  s.name = "lattice " + std::to_string(side) + "^3 with twins";
  int site = 0;
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j)
      for (int k = 0; k < side; ++k, ++site) {
        const double x = 0.97 * i + u(rng) + 50, y = 0.97 * j + u(rng) - 20, z = 0.97 * k + u(rng);
        s.add(x, y, z, 0.5);
        if (site % 97 == 0) s.add(std::nextafter(x, 1e9), y, std::nextafter(z, -1e9), 0.25);
      }
  return s;
}

struct Knobs {  // the knobs are removed even when an assertion fails
  ~Knobs() {
    ::unsetenv("CONTACTGRID_CUDA_HOST_PATH");
    ::unsetenv("CONTACTGRID_CUDA_TRANSFER_SLOT");
  }
};

template <class Real>
void expect_same_every_way(const Spheres& s, Fields fields, const std::string& what) {
  SCOPED_TRACE(what + " " + to_string(fields));
  EngineOptions o;
  o.fields = fields;
  o.backend = Backend::cpu;
  Engine<Real> cpu(o);
  o.backend = Backend::cuda;
  Engine<Real> gpu(o);
  const BodiesView v{s.p, s.r, {}, {}};
  const Contacts<Real> oracle = cpu.detect(v);
  ::unsetenv("CONTACTGRID_CUDA_HOST_PATH");
  const Contacts<Real> first = gpu.detect(v);   // the engine's first download: not locked
  const Contacts<Real> second = gpu.detect(v);  // into pool blocks locked now, `first` still held
  const Contacts<Real> third = gpu.detect(v);   // into blocks locked before
  ::setenv("CONTACTGRID_CUDA_HOST_PATH", "packed", 1);
  const Contacts<Real> packed = gpu.detect(v);
  const std::uint64_t fp64_rows = gpu.stats().fp64_rows;
  ::setenv("CONTACTGRID_CUDA_HOST_PATH", "old", 1);
  const Contacts<Real> old = gpu.detect(v);
  ::unsetenv("CONTACTGRID_CUDA_HOST_PATH");
  ASSERT_EQ(oracle.size(), first.size());
  EXPECT_EQ(compare_contacts(first, oracle), "identical") << "default path against the CPU";
  EXPECT_EQ(compare_contacts(second, oracle), "identical") << "default path, second call";
  EXPECT_EQ(compare_contacts(third, oracle), "identical") << "default path, third call";
  EXPECT_EQ(compare_contacts(packed, oracle), "identical") << "packed path against the CPU";
  EXPECT_EQ(compare_contacts(old, oracle), "identical") << "old path against the CPU";
  EXPECT_EQ(fp64_rows, cpu.stats().fp64_rows);
  EXPECT_EQ(gpu.stats().fp64_rows, cpu.stats().fp64_rows);
  if (first.id_a.size() * sizeof(std::int64_t) >= (std::size_t(1) << 20) &&
      first.distance.size() * sizeof(Real) >= (std::size_t(1) << 20)) {
    auto locked = [](const void* p) {
      return detail::HostPool::instance().block_locked(const_cast<void*>(p));
    };
    EXPECT_TRUE(locked(second.id_a.data())) << "the rows did not come down into locked pool blocks";
    EXPECT_TRUE(locked(second.distance.data()));
    EXPECT_TRUE(locked(third.id_a.data()));
  }
}

TEST(HostPathCuda, EveryHostPathGivesTheCpuBytes) {
  CG_SKIP_WITHOUT_CUDA();
  Knobs knobs;
  const Spheres twins = lattice_with_twins(48, 3711);  // 110 592 + 1 141 bodies, ~330 k contacts
  // default slots (4 MiB: the upload in one piece at this size), then 4096 and 5000 bytes: 256 and
  // 304 spheres a slot (5000 rounds down to 4864), neither dividing the body count
  for (const char* slot : {static_cast<const char*>(nullptr), "4096", "5000"}) {
    if (slot) ::setenv("CONTACTGRID_CUDA_TRANSFER_SLOT", slot, 1);
    const std::string what = std::string("slot ") + (slot ? slot : "default");
    expect_same_every_way<float>(twins, Fields::basic, what);
    expect_same_every_way<float>(twins, Fields::full, what);
    expect_same_every_way<float>(coincident(3712), Fields::full, what + ", coincident");
    expect_same_every_way<float>(random_spheres(3, 0.5, 1.0, 3713), Fields::basic, what + ", 3 bodies");
  }
  ::unsetenv("CONTACTGRID_CUDA_TRANSFER_SLOT");
  // fp64 keeps the doubles' upload; its rows come down the same way
  expect_same_every_way<double>(twins, Fields::basic, "fp64");
}

// The default path with global ids, a report mask and ellipsoids: the CPU's rows, and an upload stage
// in the call's times.
TEST(HostPathCuda, TheDevicePathKeepsIdsReportMasksAndShapes) {
  CG_SKIP_WITHOUT_CUDA();
  ShapeScene scene = make_scene("host path", 3721, 40000, 0.5, 60);
  std::vector<std::int64_t> ids(scene.r.size());
  std::vector<std::uint8_t> report(scene.r.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ids[i] = 7 + 3 * std::int64_t(i);
    report[i] = i % 5 == 0 ? kPairedBit : kReportedBit;
  }
  BodiesView v = scene.view();
  v.id = ids;
  v.report = report;
  auto check = [&]<class Real>(Real, bool mixed, const char* what) {
    SCOPED_TRACE(what);
    EngineOptions o;
    o.fields = Fields::full;
    o.fp32_broad_phase = mixed;
    o.backend = Backend::cpu;
    const Contacts<Real> want = Engine<Real>(o).detect(v);
    o.backend = Backend::cuda;
    Engine<Real> gpu(o);
    const Contacts<Real> got = gpu.detect(v);
    EXPECT_GT(want.size(), 1000u);
    EXPECT_EQ(compare_contacts(got, want), "identical");
    EXPECT_EQ(gpu.stats().ellipsoids,
              std::size_t(std::count(scene.shape.begin(), scene.shape.end(), Shape::ellipsoid)));
    bool timed_upload = false;
    for (const auto& t : gpu.times()) timed_upload = timed_upload || (t.name == "upload" && t.seconds > 0);
    EXPECT_TRUE(timed_upload) << "no upload stage in the call's times";
  };
  check(0.0f, false, "fp32");
  check(0.0, false, "fp64");
  check(0.0, true, "mixed");
}

// An engine's first download of at least 64 MiB of rows (the CLI's one call on a large scene) goes
// straight into pool blocks locked then, as the registered download would lock the rows anyway: the
// same bytes as the old path's.
TEST(HostPathCuda, ALargeFirstDownloadGoesStraightIntoLockedBlocks) {
  CG_SKIP_WITHOUT_CUDA();
  Knobs knobs;
  const Spheres s = lattice_with_twins(100, 3729);  // ~1.01 M bodies, ~3 M contacts: ~170 MB of rows
  const BodiesView v{s.p, s.r, {}, {}};
  EngineOptions o;
  o.backend = Backend::cuda;
  const Contacts<float> first = Engine<float>(o).detect(v);
  ASSERT_GE(first.size() * 56, std::size_t(64) << 20);
  EXPECT_TRUE(detail::HostPool::instance().block_locked(const_cast<std::int64_t*>(first.id_a.data())))
      << "a first download of this size did not come straight into locked pool blocks";
  ::setenv("CONTACTGRID_CUDA_HOST_PATH", "old", 1);
  const Contacts<float> old = Engine<float>(o).detect(v);
  ::unsetenv("CONTACTGRID_CUDA_HOST_PATH");
  EXPECT_EQ(compare_contacts(first, old), "identical");
}

// Arrays the caller page-locked (Engine::pin_host) go up straight, the others through the ring: the
// same bytes with the positions alone, the radii alone or both locked.
TEST(HostPathCuda, PageLockedArraysGiveTheSameBytes) {
  CG_SKIP_WITHOUT_CUDA();
  Spheres s = lattice_with_twins(40, 3725);
  const BodiesView v{s.p, s.r, {}, {}};
  EngineOptions o;
  o.backend = Backend::cpu;
  const Contacts<float> want = Engine<float>(o).detect(v);
  o.backend = Backend::cuda;
  Engine<float> gpu(o);
  for (const int which : {1, 2, 3}) {
    SCOPED_TRACE("locked: " + std::string(which & 1 ? "positions " : "") + (which & 2 ? "radii" : ""));
    const bool p = (which & 1) && gpu.pin_host(s.p.data(), s.p.size() * sizeof(s.p[0]));
    const bool r = (which & 2) && gpu.pin_host(s.r.data(), s.r.size() * sizeof(s.r[0]));
    EXPECT_EQ(p, (which & 1) != 0) << "the driver refused to lock the positions";
    EXPECT_EQ(r, (which & 2) != 0) << "the driver refused to lock the radii";
    const Contacts<float> got = gpu.detect(v);
    if (p) gpu.unpin_host(s.p.data());
    if (r) gpu.unpin_host(s.r.data());
    EXPECT_EQ(compare_contacts(got, want), "identical");
  }
}

// A bad body on the default path is named by its id with the CPU backend's text: a centre that is not
// finite, a radius <= 0, a bad shape row, ids out of order, arrays of different sizes.
TEST(HostPathCuda, TheDevicePathNamesABadBodyAsTheCpuDoes) {
  CG_SKIP_WITHOUT_CUDA();
  const ShapeScene scene = make_scene("bad bodies", 3723, 5000, 0.5, 30);
  std::vector<std::int64_t> ids(scene.r.size());
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = 100 + 2 * std::int64_t(i);
  auto message = [](Backend backend, const BodiesView& v) -> std::string {
    EngineOptions o;
    o.backend = backend;
    try {
      Engine<double>(o).detect(v);
    } catch (const InputError& e) {
      return e.what();
    }
    return "no error";
  };
  auto expect_same = [&](const char* what, const ShapeScene& s, const std::vector<std::int64_t>& id) {
    SCOPED_TRACE(what);
    BodiesView v = s.view();
    v.id = id;
    const std::string cpu = message(Backend::cpu, v);
    EXPECT_NE(cpu, "no error");
    EXPECT_EQ(message(Backend::cuda, v), cpu);
  };
  ShapeScene nan = scene;
  nan.p[4321].y = std::nan("");
  expect_same("centre not finite", nan, ids);
  ShapeScene zero = scene;
  zero.r[17] = 0;
  expect_same("radius 0", zero, ids);
  ShapeScene flat = scene;
  const auto e =
      std::find(flat.shape.begin() + 2000, flat.shape.end(), Shape::ellipsoid) - flat.shape.begin();
  flat.axes[e].y = -0.5;
  expect_same("semi-axis < 0", flat, ids);
  std::vector<std::int64_t> unordered = ids;
  std::swap(unordered[3000], unordered[3001]);
  expect_same("ids out of order", scene, unordered);
  std::vector<std::int64_t> short_ids(ids.begin(), ids.end() - 1);
  expect_same("ids of another size", scene, short_ids);
}

// The scene must hold rows that need the world doubles, or the rerun of the narrow stage goes untested.
TEST(HostPathCuda, TheTwinsSceneHasRowsThatNeedTheWorldDoubles) {
  const Spheres twins = lattice_with_twins(48, 3711);
  EngineOptions o;
  o.backend = Backend::cpu;
  Engine<float> cpu(o);
  const Contacts<float> c = cpu.detect(BodiesView{twins.p, twins.r, {}, {}});
  EXPECT_GT(cpu.stats().fp64_rows, 1000u);
  EXPECT_GT(c.size(), std::size_t(300000));
}

}  // namespace
}  // namespace cg::test
