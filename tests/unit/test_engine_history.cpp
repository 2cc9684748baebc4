// Contact identity across steps (EngineOptions::history, core/history.hpp), one test body over both
// backends and precisions (CUDA cases skip, visibly, without a GPU). The oracle is a brute-force map
// from the previous step's pairs (by global ids) to their row and age — no binary search, no shared
// code with the engine's stage. Seeded random walks in which pairs break and form again, through the
// host arrays (ids 5i + 3, so keys differ from rows), the resident bodies with ids, and on the GPU the
// device arrays with ids (the device history, through Thrust's lower_bound and through the
// hand-written search): every step's age and previous_row as the oracle's, and CPU = CUDA. The
// history fields in contact files and CSV: written and read back.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "backends.hpp"
#include "engine.hpp"
#include "history.hpp"
#include "io/contact_file.hpp"
#include "io/contacts_csv.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "temp_dir.hpp"

#if defined(CONTACTGRID_HAVE_CUDA)
#include <cuda_runtime.h>
#endif

namespace cg::test {
namespace {

template <class Cfg>
class EngineHistoryTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(Cfg); }
};
TYPED_TEST_SUITE(EngineHistoryTest, AllConfigs, ConfigNames);

// The oracle: the previous step's pairs (global ids) → (row, age).
struct Oracle {
  std::map<std::pair<std::int64_t, std::int64_t>, std::pair<std::int64_t, std::int64_t>> previous;

  // Checks the history fields of `c` (keys: its ids through `global`, or the ids), then makes c the
  // previous step. Returns the number of continued pairs.
  template <class Real>
  std::size_t check_and_step(const Contacts<Real>& c, const std::vector<std::int64_t>& global,
                             const std::string& at) {
    EXPECT_TRUE(c.history) << at;
    EXPECT_EQ(c.age.size(), c.size()) << at;
    EXPECT_EQ(c.previous_row.size(), c.size()) << at;
    std::map<std::pair<std::int64_t, std::int64_t>, std::pair<std::int64_t, std::int64_t>> now;
    std::size_t continued = 0;
    for (std::size_t k = 0; k < c.size() && k < c.age.size() && k < c.previous_row.size(); ++k) {
      const auto key = global.empty()
                           ? std::make_pair(c.id_a[k], c.id_b[k])
                           : std::make_pair(global[std::size_t(c.id_a[k])], global[std::size_t(c.id_b[k])]);
      std::int64_t age = 0, row = -1;
      if (auto it = previous.find(key); it != previous.end()) {
        row = it->second.first;
        age = it->second.second + 1;
        ++continued;
      }
      if (c.age[k] != age || c.previous_row[k] != row) {
        ADD_FAILURE() << at << ": row " << k << " (" << key.first << ", " << key.second << "): age "
                      << c.age[k] << " previous_row " << c.previous_row[k] << ", want " << age << " and "
                      << row;
        break;
      }
      now[key] = {std::int64_t(k), age};
    }
    previous = std::move(now);
    return continued;
  }
};

// Every centre moved by a random vector of length <= step.
void random_step(Spheres& s, double step, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  for (auto& p : s.p) p = p + step * Vec3<double>{u(rng), u(rng), u(rng)};
}

EngineOptions history_options(Backend backend, double skin = 0) {
  EngineOptions o;
  o.backend = backend;
  o.history = true;
  o.skin = skin;
  return o;
}

// The host-array path with ids 5i + 3: every step as the oracle; pairs continue, end and begin.
TYPED_TEST(EngineHistoryTest, HostWalkMatchesOracle) {
  using Real = typename TypeParam::Real;
  for (double skin : {0.0, 0.1}) {
    Engine<Real> engine(history_options(TypeParam::backend, skin));
    Spheres s = random_spheres(3000, 0.4, 1.0, 7301);
    std::vector<std::int64_t> id(s.r.size());
    for (std::size_t i = 0; i < id.size(); ++i) id[i] = 5 * std::int64_t(i) + 3;
    std::mt19937_64 rng(7302);
    Oracle oracle;
    std::size_t continued = 0, rows = 0, old = 0;
    for (int step = 0; step < 30; ++step) {
      const std::string at = "skin " + std::to_string(skin) + " step " + std::to_string(step);
      const Contacts<Real> c = engine.detect(BodiesView{s.p, s.r, id, {}});
      const std::size_t kept = oracle.check_and_step(c, {}, at);
      if (step == 0) {
        EXPECT_EQ(kept, 0u) << "the first step's pairs are all new";
      }
      continued += kept;
      rows += c.size();
      for (std::int64_t a : c.age) old += a >= 5 ? 1 : 0;
      random_step(s, 0.03, rng);
    }
    EXPECT_GT(continued, rows / 2) << "most pairs last from step to step";
    EXPECT_LT(continued, rows - rows / 30) << "pairs end and begin in the walk";
    EXPECT_GT(old, 0u) << "some pairs last five steps and more";
  }
}

// Resident bodies with global ids: the contacts keep row indices, the keys are the ids; a second set
// of resident rows in another order of the same bodies (the rows of a rank after a migration) keeps
// the pairs' identity.
TYPED_TEST(EngineHistoryTest, ResidentIdsKeyThePairs) {
  using Real = typename TypeParam::Real;
  Engine<Real> engine(history_options(TypeParam::backend));
  Spheres s = random_spheres(2500, 0.5, 1.0, 7311);
  std::vector<std::int64_t> id(s.r.size());
  for (std::size_t i = 0; i < id.size(); ++i) id[i] = 1000 + 7 * std::int64_t(i);
  std::mt19937_64 rng(7312);
  Oracle oracle;
  engine.set_resident(BodiesView{s.p, s.r, id, {}});
  for (int step = 0; step < 12; ++step) {
    const std::string at = "step " + std::to_string(step);
    if (step > 0) {
      random_step(s, 0.02, rng);
      engine.write_resident(0, s.r.size(), s.p.data(), s.r.data());
    }
    const std::size_t k = engine.detect_resident();
    const Contacts<Real>& c = engine.resident_contacts();
    ASSERT_EQ(c.size(), k) << at;
    oracle.check_and_step(c, id, at);
  }
  // The same bodies without their first 500 rows: other row indices, the same keys.
  Spheres t;
  std::vector<std::int64_t> tid;
  for (std::size_t i = 500; i < s.r.size(); ++i) {
    t.add(s.p[i].x, s.p[i].y, s.p[i].z, s.r[i]);
    tid.push_back(id[i]);
  }
  engine.set_resident(BodiesView{t.p, t.r, tid, {}});
  engine.detect_resident();
  EXPECT_GT(oracle.check_and_step(engine.resident_contacts(), tid, "after the new rows"), 100u);
}

// reset_history starts over; a step without bodies ends every pair; strictly ascending resident ids.
TYPED_TEST(EngineHistoryTest, ResetAndEmptySteps) {
  using Real = typename TypeParam::Real;
  Engine<Real> engine(history_options(TypeParam::backend));
  Spheres s = random_spheres(1500, 0.5, 1.0, 7321);
  const BodiesView v{s.p, s.r, {}, {}};
  engine.detect(v);
  Contacts<Real> c = engine.detect(v);
  ASSERT_GT(c.size(), 50u);
  for (std::size_t k = 0; k < c.size(); ++k) {
    ASSERT_EQ(c.age[k], 1) << "unmoved bodies: every pair continues";
    ASSERT_EQ(c.previous_row[k], std::int64_t(k)) << "and keeps its row";
  }
  engine.reset_history();
  c = engine.detect(v);
  for (std::size_t k = 0; k < c.size(); ++k) ASSERT_EQ(c.previous_row[k], -1) << "after reset_history";
  const Contacts<Real> none = engine.detect(BodiesView{});
  EXPECT_TRUE(none.history);
  EXPECT_EQ(none.size(), 0u);
  c = engine.detect(v);
  for (std::size_t k = 0; k < c.size(); ++k) ASSERT_EQ(c.age[k], 0) << "after a step without bodies";
  std::vector<std::int64_t> bad(s.r.size());
  for (std::size_t i = 0; i < bad.size(); ++i) bad[i] = std::int64_t(i == 9 ? 7 : i);
  EXPECT_THROW(engine.set_resident(BodiesView{s.p, s.r, bad, {}}), InputError);
}

// Without the option the contacts carry no history fields (and files and comparers see none).
TYPED_TEST(EngineHistoryTest, OffByDefault) {
  using Real = typename TypeParam::Real;
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<Real> engine(o);
  Spheres s = random_spheres(500, 0.5, 1.0, 7331);
  const Contacts<Real> c = engine.detect(BodiesView{s.p, s.r, {}, {}});
  EXPECT_FALSE(c.history);
  EXPECT_TRUE(c.age.empty());
  EXPECT_TRUE(c.previous_row.empty());
  EXPECT_TRUE(c.consistent());
}

// step_history on its own (what a step loop that merges ranks' rows calls): a hand-made case, and
// keys through global ids.
TEST(StepHistory, HandMadeSteps) {
  ContactHistory h;
  Contacts<double> c;
  c.resize(3, FieldSet{});
  c.id_a = {0, 0, 2};
  c.id_b = {1, 3, 5};
  step_history(c, h);
  EXPECT_EQ(c.age, (HostVector<std::int64_t>{0, 0, 0}));
  EXPECT_EQ(c.previous_row, (HostVector<std::int64_t>{-1, -1, -1}));
  Contacts<double> d;
  d.resize(4, FieldSet{});
  d.id_a = {0, 0, 2, 3};
  d.id_b = {1, 2, 5, 4};
  step_history(d, h, {}, 1);
  EXPECT_EQ(d.age, (HostVector<std::int64_t>{1, 0, 1, 0}));
  EXPECT_EQ(d.previous_row, (HostVector<std::int64_t>{0, -1, 2, -1}));
  EXPECT_TRUE(d.consistent());
  Contacts<double> e;  // rows 0..3 are global ids 0, 2, 3, 5 (so (1, 3) is (2, 5), row 2 of d)
  e.resize(2, FieldSet{});
  e.id_a = {0, 1};
  e.id_b = {1, 3};
  const std::vector<std::int64_t> global{0, 2, 3, 5};
  step_history(e, h, global, 2);
  EXPECT_EQ(e.age, (HostVector<std::int64_t>{1, 2}));
  EXPECT_EQ(e.previous_row, (HostVector<std::int64_t>{1, 2}));
  ASSERT_EQ(h.size(), 2u);
  EXPECT_TRUE(h.keys[1] == (PairKey{2, 5}));
}

TEST(StepHistory, LowerBoundKey) {
  const PairKey keys[] = {{0, 4}, {0, 9}, {1, 2}, {1, 3}, {7, 8}};
  EXPECT_EQ(lower_bound_key(keys, 5, {0, 1}), 0u);
  EXPECT_EQ(lower_bound_key(keys, 5, {0, 9}), 1u);
  EXPECT_EQ(lower_bound_key(keys, 5, {1, 0}), 2u);
  EXPECT_EQ(lower_bound_key(keys, 5, {1, 3}), 3u);
  EXPECT_EQ(lower_bound_key(keys, 5, {7, 9}), 5u);
  EXPECT_EQ(lower_bound_key(keys, 0, {7, 9}), 0u);
}

// The search from a guess gives lower_bound_key's position from every guess: seeded sorted keys with
// runs of one first body, every key present and absent (between, before, after all), every guess
// (in range and past the end), and no keys at all.
TEST(StepHistory, LowerBoundKeyNearEqualsTheWholeSearch) {
  EXPECT_EQ(lower_bound_key_near(nullptr, 0, {1, 2}, 0), 0u);
  EXPECT_EQ(lower_bound_key_near(nullptr, 0, {1, 2}, 5), 0u);
  std::mt19937_64 rng(9021);
  for (const std::size_t m : {1u, 2u, 3u, 7u, 64u, 300u}) {
    std::vector<PairKey> keys;
    std::int64_t a = 0, b = 0;
    while (keys.size() < m) {
      if (rng() % 3 == 0) {
        a += 1 + std::int64_t(rng() % 3);
        b = a;
      }
      b += 1 + std::int64_t(rng() % 3);
      keys.push_back({a, b});
    }
    std::vector<PairKey> probes = keys;
    for (const PairKey& k : keys) {
      probes.push_back({k.a, k.b - 1});
      probes.push_back({k.a, k.b + 1});
    }
    probes.push_back({-1, 0});
    probes.push_back({a + 5, 0});
    for (const PairKey& key : probes) {
      const std::size_t want = lower_bound_key(keys.data(), m, key);
      for (std::size_t guess = 0; guess <= m + 2; ++guess)
        ASSERT_EQ(lower_bound_key_near(keys.data(), m, key, guess), want)
            << "m " << m << " key (" << key.a << ", " << key.b << ") guess " << guess;
    }
  }
}

class HistoryFiles : public TempDirTest {
 protected:
  std::string text(const std::string& file) const {
    std::ifstream in(file);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
};

// The history fields in contact files and CSV: written and read back.
TEST_F(HistoryFiles, RoundTrip) {
  Contacts<double> c;
  c.resize(3, FieldSet{true, true});
  for (std::size_t k = 0; k < 3; ++k) {
    c.id_a[k] = std::int64_t(k);
    c.id_b[k] = std::int64_t(k + 5);
    c.position_on_a[k] = c.position_on_b[k] = c.normal_on_b[k] = {1, 0, 0};
    c.local_point_a[k] = c.local_point_b[k] = c.lateral_friction_dir1[k] =
        c.lateral_friction_dir2[k] = {0, 1, 0};
    c.distance[k] = -0.1;
    c.age[k] = std::int64_t(7 * k);
    c.previous_row[k] = k == 1 ? -1 : std::int64_t(k + 2);
  }
  RunInfo info;
  info.precision = "fp64";
  write_contacts(path("h.h5"), c, info);
  const ContactFile back = read_contacts(path("h.h5"));
  EXPECT_TRUE(back.contacts.full);
  EXPECT_TRUE(back.contacts.history);
  EXPECT_EQ(back.contacts.age, c.age);
  EXPECT_EQ(back.contacts.previous_row, c.previous_row);
  write_contacts_csv(path("h.csv"), c);
  const std::string csv = text(path("h.csv"));
  EXPECT_NE(csv.find(",age,previous_row\n"), std::string::npos) << csv.substr(0, csv.find('\n'));
  EXPECT_NE(csv.find(",14,4\n"), std::string::npos);
}

#if defined(CONTACTGRID_HAVE_CUDA)
// Device arrays (DEVICE, with global ids), the device history against the CPU engine's host history
// of the same bodies, with every device search (from the row's place, Thrust, the whole search), and a skin
// so that the rejecting narrow's rows are counted before the stage. Then the history moves between paths: a
// host-array call on the CUDA engine continues the device history, and a device call after it.
template <class Real>
void device_walk(const char* search) {
  ::setenv("CONTACTGRID_CUDA_HISTORY", search, 1);
  struct Unset {
    ~Unset() { ::unsetenv("CONTACTGRID_CUDA_HISTORY"); }
  } unset;
  Engine<Real> gpu(history_options(Backend::cuda, 0.05)), cpu(history_options(Backend::cpu));
  Spheres s = random_spheres(6000, 0.4, 1.0, 7341);
  const std::size_t n = s.r.size();
  std::vector<std::int64_t> id(n);
  for (std::size_t i = 0; i < n; ++i) id[i] = 11 + 3 * std::int64_t(i);
  double *d_pos = nullptr, *d_rad = nullptr;
  std::int64_t* d_id = nullptr;
  ASSERT_EQ(cudaMalloc(&d_pos, n * sizeof(Vec3<double>)), cudaSuccess);
  ASSERT_EQ(cudaMalloc(&d_rad, n * sizeof(double)), cudaSuccess);
  ASSERT_EQ(cudaMalloc(&d_id, n * sizeof(std::int64_t)), cudaSuccess);
  cudaMemcpy(d_id, id.data(), n * sizeof(std::int64_t), cudaMemcpyHostToDevice);
  cudaMemcpy(d_rad, s.r.data(), n * sizeof(double), cudaMemcpyHostToDevice);
  std::mt19937_64 rng(7342);
  Oracle oracle;
  for (int step = 0; step < 24; ++step) {
    const std::string at = std::string(search) + " step " + std::to_string(step);
    cudaMemcpy(d_pos, s.p.data(), n * sizeof(Vec3<double>), cudaMemcpyHostToDevice);
    const Contacts<Real> want = cpu.detect(BodiesView{s.p, s.r, id, {}});
    Contacts<Real> got;
    if (step == 15) {  // the CUDA engine's host-array path continues the device history
      got = gpu.detect(BodiesView{s.p, s.r, id, {}});
    } else {
      DeviceBodiesView v;
      v.position = d_pos;
      v.radius = d_rad;
      v.count = n;
      v.id = d_id;
      got = gpu.detect_device(v);
    }
    ASSERT_EQ(got.size(), want.size()) << at;
    EXPECT_EQ(got.age, want.age) << at;
    EXPECT_EQ(got.previous_row, want.previous_row) << at;
    oracle.check_and_step(got, step == 15 ? std::vector<std::int64_t>{} : id, at);
    random_step(s, 0.015, rng);
  }
  cudaFree(d_pos);
  cudaFree(d_rad);
  cudaFree(d_id);
}

#endif

// Built without CUDA, or run without a GPU: skipped, visibly.
TEST(EngineHistoryDevice, DeviceHistoryEqualsHost) {
#if defined(CONTACTGRID_HAVE_CUDA)
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  for (const char* search : {"near", "thrust", "kernel"}) {
    device_walk<float>(search);
    device_walk<double>(search);
  }
#else
  GTEST_SKIP() << "CUDA backend not built: CUDA case skipped";
#endif
}

}  // namespace
}  // namespace cg::test
