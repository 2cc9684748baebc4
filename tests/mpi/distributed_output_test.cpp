// The parallel output path under MPI: distributed_detect's ContactOutput::ranks mode (each rank keeps the
// contacts whose id_a lies in its range [N·r/P, N·(r+1)/P), merged, with its first row and K) and
// write_contacts_distributed (every rank writes its rows of one file). Against the single-rank
// Engine::detect on the whole scene, computed on every rank (the scenes are small): each rank's rows
// must be exactly rows [first_row, first_row + n) of it, bit for bit, and the slices must tile it.
//
// Every test is collective: all ranks run it, and only EXPECTs (never ASSERTs) come before the last
// collective, so a failed check never leaves a rank behind.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "mpi/mpi_test_env.hpp"
#include "run/contact_file_shared.hpp"
#include "run/distributed_detect.hpp"
#include "support/contacts_equal.hpp"

namespace cg {
namespace {

using test::compare_contact_window;
using test::compare_contacts;
using testing::session;
using testing::shared_path;
using testing::write_shared;

Scene random_scene(std::uint64_t seed, std::size_t n, double edge, double r_low, double r_high) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, edge), u01(0, 1);
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    s.sphere_position.push_back({u(rng), u(rng), u(rng)});
    s.sphere_radius.push_back(r_low + u01(rng) * (r_high - r_low));
  }
  return s;
}

// About 0.4 contacts per body, radii in [0.5, 1].
Scene uniform_scene(std::uint64_t seed, std::size_t n) {
  const double edge =
      std::cbrt(static_cast<double>(n) * (4.0 / 3.0) * std::numbers::pi * std::pow(1.5, 3) / 0.8);
  return random_scene(seed, n, edge, 0.5, 1.0);
}

// Contacts only among the first `touching` bodies (a tight cluster); the rest are far apart. With
// N / P > touching, every rank but 0 has an id range without contacts.
Scene cluster_scene(std::uint64_t seed, std::size_t n, std::size_t touching) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    if (i < touching) {
      s.sphere_position.push_back({u(rng), u(rng), u(rng)});
    } else {
      s.sphere_position.push_back({10.0 + 5.0 * static_cast<double>(i), 3.0 * u(rng), 3.0 * u(rng)});
    }
    s.sphere_radius.push_back(1.0);
  }
  return s;
}

DistributedOptions range_options(Fields fields = Fields::full) {
  DistributedOptions o;
  o.engine.backend = Backend::cpu;
  o.engine.fields = fields;
  o.engine.threads = 1;  // the test machines are shared: one thread per rank
  o.output = ContactOutput::ranks;
  return o;
}

// This rank's slice is rows [first_row, first_row + n) of `want`, bit for bit.
template <class Real>
void expect_rows_of(const Contacts<Real>& got, std::uint64_t first, const Contacts<Real>& want,
                    const std::string& what) {
  EXPECT_EQ(got.full, want.full) << what;
  EXPECT_LE(first + got.size(), want.size()) << what;
  EXPECT_EQ(compare_contact_window(got, want, first), "identical") << what;
}

// Runs ContactOutput::ranks mode and checks this rank's range, order, rows, first row and K; returns the
// result.
template <class Real>
DistributedResult<Real> check_ranges(const std::string& path, const Scene& scene,
                                     const DistributedOptions& options, const std::string& name) {
  DistributedResult<Real> got = distributed_detect<Real>(session(), path, options);
  const unsigned long long held = session().sum(got.contacts.size());  // collective: before any check
  const std::string label = name + (std::is_same_v<Real, float> ? " fp32" : " fp64") + " at rank " +
                            std::to_string(session().rank()) + "/" + std::to_string(session().size());
  const std::uint64_t n = scene.size(), p = static_cast<std::uint64_t>(session().size()),
                      r = static_cast<std::uint64_t>(session().rank());
  EXPECT_EQ(got.id_begin, n * r / p) << label;
  EXPECT_EQ(got.id_end, n * (r + 1) / p) << label;
  for (std::size_t k = 0; k < got.contacts.size(); ++k) {
    const std::int64_t a = got.contacts.id_a[k];
    if (a < static_cast<std::int64_t>(got.id_begin) || a >= static_cast<std::int64_t>(got.id_end)) {
      ADD_FAILURE() << label << ": row " << k << " has id_a " << a << " outside the rank's range";
      break;
    }
  }
  std::vector<std::string> top;
  for (const auto& t : got.times)
    if (t.engine_stage < 0) top.push_back(t.name());
  EXPECT_EQ(top, (std::vector<std::string>{"read", "redistribute", "halo", "detect", "exchange", "merge"}))
      << label;
  EXPECT_EQ(got.duplicates_removed, 0u) << label;
  Engine<Real> engine(options.engine);
  const Contacts<Real> want = engine.detect(BodiesView{scene.sphere_position, scene.sphere_radius, {}, {}});
  EXPECT_EQ(got.total_contacts, want.size()) << label;
  EXPECT_EQ(held, want.size()) << label << ": the slices do not add up to K";
  // first row: the contacts of every smaller id_a
  std::uint64_t first = 0;
  while (first < want.size() && want.id_a[first] < static_cast<std::int64_t>(got.id_begin)) ++first;
  EXPECT_EQ(got.first_row, first) << label;
  expect_rows_of(got.contacts, got.first_row, want, label);
  return got;
}

template <class F>
void both_precisions(F&& f) {
  f(double{});
  f(float{});
}

TEST(DistributedOutput, EachRankGetsItsIdRangeAndTogetherTheSingleRankResult) {
  const Scene scene = uniform_scene(201, 3000);
  const std::string path = write_shared("ranges_uniform", scene);
  both_precisions([&](auto real) {
    using Real = decltype(real);
    check_ranges<Real>(path, scene, range_options(), "uniform");
    check_ranges<Real>(path, scene, range_options(Fields::basic), "uniform basic");
    DistributedOptions o = range_options();
    o.axis = SlabAxis::z;
    o.balance = Balance::width;
    check_ranges<Real>(path, scene, o, "uniform z width");
  });
}

TEST(DistributedOutput, TinyMessagesGiveTheSameRows) {
  const Scene scene = uniform_scene(202, 1500);
  const std::string path = write_shared("ranges_tiny", scene);
  DistributedOptions o = range_options();
  o.max_message_bytes = 64;  // many messages of a few rows per field and peer
  both_precisions([&](auto real) { check_ranges<decltype(real)>(path, scene, o, "tiny messages"); });
}

TEST(DistributedOutput, RanksWithoutContacts) {
  const Scene scene = cluster_scene(203, 400, 12);  // contacts among bodies 0 … 11 only
  const std::string path = write_shared("ranges_cluster", scene);
  both_precisions([&](auto real) {
    using Real = decltype(real);
    DistributedResult<Real> r = check_ranges<Real>(path, scene, range_options(), "cluster");
    EXPECT_GT(r.total_contacts, 10u);
    if (session().rank() > 0) {
      EXPECT_EQ(r.contacts.size(), 0u);
      EXPECT_EQ(r.first_row, r.total_contacts);
    }
  });
}

TEST(DistributedOutput, MoreRanksThanBodies) {
  Scene s;
  s.sphere_position = {{0, 0, 0}, {1.5, 0, 0}, {3.0, 0.1, 0}};
  s.sphere_radius = {1.0, 0.8, 0.9};
  const std::string path = write_shared("ranges_three", s);
  both_precisions([&](auto real) {
    DistributedResult<decltype(real)> r = check_ranges<decltype(real)>(path, s, range_options(), "three");
    EXPECT_EQ(r.total_contacts, 2u);
  });
}

// ---- one file written by every rank ------------------------------------------------------------------

std::vector<std::string> leftovers(const std::string& prefix) {
  std::vector<std::string> found;
  for (const auto& e : std::filesystem::directory_iterator(testing::shared_temp_dir())) {
    const std::string name = e.path().filename().string();
    if (name.rfind(prefix, 0) == 0) found.push_back(name);
  }
  return found;
}

// The file every rank writes (ContactOutput::ranks slices, and ContactOutput::gather's everything-on-rank-0)
// has the dataset bytes of the single-rank writer.
template <class Real>
void write_and_compare(const std::string& name, const Scene& scene) {
  const std::string path = write_shared(name, scene);
  const DistributedOptions ranges = range_options();
  DistributedOptions root = ranges;
  root.output = ContactOutput::gather;
  DistributedResult<Real> a = distributed_detect<Real>(session(), path, ranges);
  DistributedResult<Real> b = distributed_detect<Real>(session(), path, root);
  RunInfo info;
  info.bodies = scene.size();
  info.ranks = session().size();
  info.times = file_stage_times(a.times);
  const std::string out_a = shared_path(name + ".ranges.out.h5"), out_b = shared_path(name + ".root.out.h5"),
                    out_1 = shared_path(name + ".one.out.h5");
  write_contacts_distributed(session(), out_a, a.contacts, a.first_row, a.total_contacts, info, 2);
  RunInfo info_b = info;
  write_contacts_distributed(session(), out_b, b.contacts, b.first_row, b.total_contacts, info_b);
  std::exception_ptr error;
  if (session().rank() == 0) {
    try {
      Engine<Real> engine(ranges.engine);
      RunInfo one = info;
      write_contacts(out_1, engine.detect(BodiesView{scene.sphere_position, scene.sphere_radius, {}, {}}),
                     one);
    } catch (...) {
      error = std::current_exception();
    }
  }
  session().agree(error, "reference");
  session().barrier();
  EXPECT_EQ(info.times.back().name, "write");
  if (session().rank() == 0) {
    for (const ContactField& field : kContactFields) {
      if (field.group == FieldGroup::history) continue;  // a detection's files carry no history
      const std::string ds = field.path;
      EXPECT_EQ(read_dataset_bytes(out_a, ds), read_dataset_bytes(out_1, ds)) << name << " " << ds;
      EXPECT_EQ(read_dataset_bytes(out_b, ds), read_dataset_bytes(out_1, ds)) << name << " " << ds;
    }
    const ContactFile f = read_contacts(out_a);
    EXPECT_EQ(std::get<std::int64_t>(f.attributes.at("contacts")),
              static_cast<std::int64_t>(a.total_contacts));
    EXPECT_EQ(std::get<std::int64_t>(f.attributes.at("ranks")), session().size());
    EXPECT_TRUE(f.attributes.count("time_write"));
    EXPECT_TRUE(f.attributes.count("time_exchange"));
    EXPECT_EQ(leftovers(name + ".ranges.out.h5.tmp").size(), 0u);
  }
  session().barrier();
}

TEST(DistributedOutput, EveryRankWritesItsRowsOfOneFile) {
  write_and_compare<double>("write_uniform", uniform_scene(204, 2500));
  write_and_compare<float>("write_uniform32", uniform_scene(205, 2500));
  write_and_compare<double>("write_cluster", cluster_scene(206, 300, 9));
  Scene none;  // no contacts at all: K = 0
  none.sphere_position = {{0, 0, 0}, {10, 0, 0}};
  none.sphere_radius = {1, 1};
  write_and_compare<double>("write_none", none);
}

// A failure on the last rank in the row phase (its slice's fields differ in length: rejected by
// write_contact_rows after the file was created) is every rank's IoError-or-Error, and leaves neither
// the output nor the temporary.
TEST(DistributedOutput, FailedRowPhaseLeavesNoFile) {
  const Scene scene = uniform_scene(207, 800);
  const std::string path = write_shared("fail_rows", scene);
  DistributedResult<double> r = distributed_detect<double>(session(), path, range_options());
  Contacts<double> slice = r.contacts;
  const bool last = session().rank() == session().size() - 1;
  if (last) slice.distance.push_back(0.0);  // one field longer than the others
  RunInfo info;
  const std::string out = shared_path("fail_rows.out.h5");
  std::string message;
  try {
    // the slice's size (id_a) still tiles [0, K): only the row phase notices
    write_contacts_distributed(session(), out, slice, r.first_row, r.total_contacts, info);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    message = e.what();
  }
  session().barrier();
  EXPECT_NE(message.find("write"), std::string::npos) << message;
  EXPECT_NE(message.find("differ in length"), std::string::npos) << message;
  EXPECT_FALSE(std::filesystem::exists(out));
  EXPECT_EQ(leftovers("fail_rows.out.h5").size(), 0u);
}

TEST(DistributedOutput, RowsThatDoNotTileAreRefusedBeforeCreating) {
  const Scene scene = uniform_scene(208, 800);
  const std::string path = write_shared("fail_tile", scene);
  DistributedResult<float> r = distributed_detect<float>(session(), path, range_options());
  RunInfo info;
  const std::string out = shared_path("fail_tile.out.h5");
  EXPECT_THROW(
      write_contacts_distributed(session(), out, r.contacts, r.first_row, r.total_contacts + 1, info), Error);
  session().barrier();
  EXPECT_EQ(leftovers("fail_tile.out.h5").size(), 0u);
}

TEST(DistributedOutput, UnwritableOutputIsAnIoErrorOnEveryRank) {
  const Scene scene = uniform_scene(209, 300);
  const std::string path = write_shared("fail_dir", scene);
  DistributedResult<double> r = distributed_detect<double>(session(), path, range_options());
  RunInfo info;
  const std::string out = shared_path("no/such/dir/out.h5");
  EXPECT_THROW(write_contacts_distributed(session(), out, r.contacts, r.first_row, r.total_contacts, info),
               IoError);
  session().barrier();
  EXPECT_FALSE(std::filesystem::exists(shared_path("no")));
}

}  // namespace
}  // namespace cg
