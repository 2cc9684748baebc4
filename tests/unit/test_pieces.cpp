// Contacts of any count in bounded memory (decomposition/pieces.hpp): a scene whose contacts exceed
// the memory limit is detected in slabs, and the result is the one-piece result row for row — spheres
// and ellipsoids, fp32, fp64 and mixed, on both backends (CUDA cases skip without a GPU), through the
// library and the command line (--memory-limit). A limit too small for even one body's piece is a
// refusal: ResourceError, exit code 7, no output file.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

#include "backends.hpp"
#include "engine.hpp"
#include "io/contact_file.hpp"
#include "io/scene_file.hpp"
#include "pieces.hpp"
#include "scenes.hpp"
#include "slab_decomposition.hpp"
#include "support/contacts_equal.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

// The one-piece contacts of `v` and those in pieces under a limit of about a quarter of their bytes.
template <class Real>
void expect_same_in_pieces(Backend backend, const BodiesView& v, bool mixed, bool full) {
  EngineOptions o;
  o.backend = backend;
  o.fp32_broad_phase = mixed;
  o.fields = full ? Fields::full : Fields::basic;
  Engine<Real> engine(o);
  const Bounds global = compute_bounds(v);
  const Precision precision = mixed ? Precision::mixed : precision_of<Real>();
  const Frame frame = make_frame(global, 0, precision, CellChoice::tuned);
  const Contacts<Real> whole = engine.detect(v, frame);
  ASSERT_GT(whole.size(), 100u);

  // A limit of about a quarter of the rows beside all bodies: every piece fits at its first try (sized
  // from the densest piece so far), and the blocks come in order, each within the limit.
  PieceOptions p;
  const std::uint64_t allowed = whole.size() / 4;
  p.memory_limit = piece_bytes<Real>(allowed, full, v.size());
  PieceReport report;
  std::vector<Contacts<Real>> blocks;
  detect_in_pieces<Real>(
      engine, v, frame, p, [&](Contacts<Real>&& c) { blocks.push_back(std::move(c)); }, &report);
  EXPECT_GE(report.pieces, 5u);
  EXPECT_EQ(report.attempts, report.pieces);  // no failed try
  ASSERT_EQ(blocks.size(), report.pieces);
  std::size_t at = 0;
  for (const Contacts<Real>& b : blocks) {
    EXPECT_LE(b.size(), allowed);
    for (std::size_t i = 0; i < b.size(); ++i, ++at) {
      ASSERT_EQ(b.id_a[i], whole.id_a[at]) << "block rows are not the next rows of the whole";
      ASSERT_EQ(b.id_b[i], whole.id_b[at]);
    }
  }
  EXPECT_EQ(at, whole.size());
  const Contacts<Real> pieces = detect_in_pieces(engine, v, frame, p);
  EXPECT_EQ(pieces.size(), whole.size());
  EXPECT_EQ(compare_contacts(pieces, whole), "identical");

  // No limit: one piece, the engine's own detect().
  PieceReport one;
  EXPECT_EQ(compare_contacts(detect_in_pieces(engine, v, frame, PieceOptions{}, &one), whole), "identical");
  EXPECT_EQ(one.pieces, 1u);

  // Too small for the bodies alone: refused.
  p.memory_limit = 64;
  EXPECT_THROW(detect_in_pieces(engine, v, frame, p), ResourceError);

  // A limit the first piece (an eighth of the bodies) does not fit: halved until it does, the later
  // pieces planned no larger (fp32 basic only: many small pieces).
  if (full || mixed || !std::is_same_v<Real, float>) return;
  p.memory_limit = piece_bytes<Real>(whole.size() / 40, full, v.size());
  PieceReport halved;
  EXPECT_EQ(compare_contacts(detect_in_pieces(engine, v, frame, p, &halved), whole), "identical");
  EXPECT_GT(halved.attempts, halved.pieces);
  EXPECT_LE(halved.attempts, halved.pieces + 4) << "failed tries beyond the first piece's halvings";
}

template <class T>
class PiecesTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(T); }
};
TYPED_TEST_SUITE(PiecesTest, BackendTypes, BackendTypeNames);

TYPED_TEST(PiecesTest, SpheresGiveTheOnePieceContacts) {
  for (std::uint64_t seed : {5u, 6u}) {
    const Spheres s = random_spheres(6000, 0.5, 1.0, seed);
    SCOPED_TRACE(s.name);
    const BodiesView v{s.p, s.r, {}, {}};
    expect_same_in_pieces<float>(TypeParam::backend, v, false, false);
    expect_same_in_pieces<double>(TypeParam::backend, v, false, true);
    expect_same_in_pieces<double>(TypeParam::backend, v, true, false);
  }
}

TYPED_TEST(PiecesTest, EllipsoidsGiveTheOnePieceContacts) {
  const ShapeScene s = make_scene("mixed shapes", 7, 3000, 0.6, 18.0);
  SCOPED_TRACE(s.name);
  expect_same_in_pieces<float>(TypeParam::backend, s.view(), false, false);
  expect_same_in_pieces<double>(TypeParam::backend, s.view(), false, true);
  expect_same_in_pieces<double>(TypeParam::backend, s.view(), true, false);
}

// A report mask and ids (a rank's owned bodies and ghosts): a piece reports only the anchors it owns
// among those the input reports, so the pieces give the rank's contacts.
TYPED_TEST(PiecesTest, KeepsTheReportMaskAndIds) {
  const Spheres s = random_spheres(5000, 0.5, 1.0, 9);
  std::vector<std::int64_t> id(s.r.size());
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < id.size(); ++i) {
    id[i] = 3 * std::int64_t(i) + 1;
    report[i] = i % 3 == 0 ? 0 : kReportedBit;
  }
  const BodiesView v{s.p, s.r, id, report};
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<double> engine(o);
  const Bounds global = compute_bounds(v);
  const Frame frame = make_frame(global, 0, Precision::fp64, CellChoice::tuned);
  const Contacts<double> whole = engine.detect(v, frame);
  PieceOptions p;
  p.memory_limit = piece_bytes<double>(whole.size() / 3, false, v.size());
  PieceReport report_out;
  EXPECT_EQ(compare_contacts(detect_in_pieces(engine, v, frame, p, &report_out), whole), "identical");
  EXPECT_GE(report_out.pieces, 2u);

  // Wide bodies (a distributed run's ghosts: the narrow body of a wide-narrow pair is its anchor): the
  // pieces' rows are not consecutive blocks, so they are merged before they are handed on (one block).
  for (std::size_t i = 0; i < id.size(); i += 40) report[i] |= kWideBit;
  const Contacts<double> wide = engine.detect(v, frame);
  std::size_t blocks = 0;
  Contacts<double> merged;
  detect_in_pieces<double>(engine, v, frame, p, [&](Contacts<double>&& c) {
    ++blocks;
    merged = std::move(c);
  });
  EXPECT_EQ(blocks, 1u);
  EXPECT_EQ(compare_contacts(merged, wide), "identical");
}

// CUDA: a piece that runs out of device memory in the middle is split and detected again; the result
// is the one-piece result. Every piece holds all the bodies' workspace (a piece is a range of anchors),
// so the scene is dense (about 50 neighbours a body: the contacts' rows outweigh the bodies and the
// workspace's 64 MiB margin) and the cap (EngineOptions::device_memory_limit) is the bodies' share,
// the margin and a tenth of what the contacts add: the whole scene fails, the first piece (an eighth
// of the anchors) too, a half of it fits. The model limit is out of the way (1 TiB).
TEST(PiecesCuda, DeviceOutOfMemoryInTheMiddleSplitsThePiece) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  Spheres s;
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(0, 40);
  for (int i = 0; i < 100000; ++i) s.add(u(rng), u(rng), u(rng), 1.0);
  const BodiesView v{s.p, s.r, {}, {}};
  const Bounds global = compute_bounds(v);
  const Frame frame = make_frame(global, 0, Precision::fp32, CellChoice::tuned);
  EngineOptions o;
  o.backend = Backend::cuda;
  Engine<float> unlimited(o);
  const Contacts<float> whole = unlimited.detect(v, frame);
  const std::uint64_t peak = unlimited.stats().peak_device_bytes;
  // the bodies' share: one anchor reported
  std::vector<std::uint8_t> one(s.r.size(), 0);
  one[0] = kReportedBit;
  Engine<float> anchor(o);
  (void)anchor.detect(BodiesView{s.p, s.r, {}, one}, frame);
  const std::uint64_t bodies_share = anchor.stats().peak_device_bytes;
  ASSERT_GT(peak, bodies_share);
  const std::uint64_t margin = std::uint64_t(64) << 20;  // cuda/workspace.cuh: Workspace::reserve
  ASSERT_GT(peak - bodies_share, 2 * margin) << "the contacts do not outweigh the margin";
  o.device_memory_limit = bodies_share + margin + (peak - bodies_share) / 10;
  Engine<float> capped(o);
  EXPECT_THROW(capped.detect(v, frame), ResourceError) << "the cap does not make the whole scene fail";
  PieceOptions p;
  p.memory_limit = std::uint64_t(1) << 40;
  PieceReport report;
  const Contacts<float> pieces = detect_in_pieces(capped, v, frame, p, &report);
  EXPECT_GE(report.pieces, 2u);
  EXPECT_GT(report.attempts, report.pieces) << "no piece ran out of device memory mid-way";
  EXPECT_EQ(compare_contacts(pieces, whole), "identical");
}

class PiecesCli : public TempDirTest {};

Scene granular_scene(std::size_t n, std::uint64_t seed, bool ellipsoids) {
  const Spheres s = random_spheres(n, 0.5, 1.0, seed);
  Scene scene;
  for (std::size_t i = 0; i < n; ++i) {
    if (ellipsoids && i % 2 == 1) {
      scene.ellipsoid_position.push_back(s.p[i]);
      scene.ellipsoid_semi_axes.push_back({s.r[i], 0.7 * s.r[i], 0.5 * s.r[i]});
      scene.ellipsoid_orientation.push_back({std::sqrt(0.5), std::sqrt(0.5), 0, 0});
    } else {
      scene.sphere_position.push_back(s.p[i]);
      scene.sphere_radius.push_back(s.r[i]);
    }
  }
  return scene;
}

// The command line: --memory-limit below the contacts' bytes gives the same /contacts as no limit
// (spheres and ellipsoids, each precision); a limit too small for any piece exits 7 with one message
// and leaves no file.
TEST_F(PiecesCli, MemoryLimitGivesTheSameContactsFile) {
  for (bool ellipsoids : {false, true}) {
    write_scene(path("scene.h5"), granular_scene(8000, 21, ellipsoids));
    for (const char* precision : {"fp32", "fp64", "mixed"}) {
      SCOPED_TRACE(std::string(precision) + (ellipsoids ? " ellipsoids" : " spheres"));
      const std::string common =
          "detect " + path("scene.h5") + " --backend cpu --threads 2 --precision " + precision;
      const CliResult a = run_cli(common + " -o " + path("whole.h5"));
      ASSERT_EQ(a.code, 0) << a.output;
      const CliResult b = run_cli(common + " -o " + path("pieces.h5") + " --memory-limit 512K");
      ASSERT_EQ(b.code, 0) << b.output;
      EXPECT_NE(b.output.find(" pieces under --memory-limit 0.5 MiB"), std::string::npos) << b.output;
      EXPECT_EQ(b.output.find("  1 pieces under"), std::string::npos) << b.output;
      const ContactFile whole = read_contacts(path("whole.h5")), pieces = read_contacts(path("pieces.h5"));
      ASSERT_GT(whole.contacts.size(), 500u);
      EXPECT_EQ(whole.precision, pieces.precision);
      EXPECT_EQ(compare_contacts(pieces.contacts, whole.contacts), "identical");
    }
  }
  const CliResult r = run_cli("detect " + path("scene.h5") + " --backend cpu -o " + path("refused.h5") +
                              " --memory-limit 1K");
  EXPECT_EQ(r.code, 7) << r.output;
  EXPECT_NE(r.output.find("do not fit in the memory limit of"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(path("refused.h5")));
  const CliResult bad = run_cli("detect " + path("scene.h5") + " -o " + path("x.h5") + " --memory-limit 4Q");
  EXPECT_NE(bad.code, 0);
  EXPECT_NE(bad.output.find("--memory-limit: '4Q' is not a size"), std::string::npos) << bad.output;
}

// The command line's peak resident memory and its output. The peak is the process's own VmHWM
// (/proc/<pid>/status), read every 10 ms once it runs contactgrid's image until it exits: a forked
// child's rusage would count the pages it shared with this test process before its exec.
struct Measured {
  int code = -1;
  long max_rss_kib = 0;
  std::string output;
};
Measured run_measured(const std::string& args, const std::string& log) {
  // glibc's heap keeps freed blocks of varying sizes mapped (its mmap threshold rises with them): fixed
  // here, so that the peak counts what the run holds, not what the allocator keeps. The engine's own
  // host pool keeps its default: a run under --memory-limit caps it itself.
  const std::string cmd =
      "MALLOC_MMAP_THRESHOLD_=1048576 exec " + cli_binary() + " " + args + " > " + log + " 2>&1";
  const std::string image = std::filesystem::canonical(cli_binary()).string();
  Measured m;
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  if (pid < 0) return m;
  const std::string proc = "/proc/" + std::to_string(pid);
  int status = 0;
  for (;;) {
    const pid_t done = ::waitpid(pid, &status, WNOHANG);
    if (done == pid) break;
    if (done < 0) return m;
    std::error_code ec;
    if (std::filesystem::read_symlink(proc + "/exe", ec).string() == image) {
      std::ifstream st(proc + "/status");
      for (std::string line; std::getline(st, line);)
        if (line.rfind("VmHWM:", 0) == 0)
          m.max_rss_kib = std::max(m.max_rss_kib, std::atol(line.c_str() + 6));
    }
    ::usleep(10000);
  }
  m.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(log);
  m.output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return m;
}

// Host memory is bounded too: one rank under --memory-limit appends each piece's rows to the output
// file as they come, so a scene whose contacts take several times the limit runs in a small fraction
// of their bytes, where the run without a limit holds them all (the test's own check that it can
// fail). fp64, 100 000 spheres at about 30 contacts a body (about 290 MB of rows).
TEST_F(PiecesCli, HostMemoryStaysBoundedWhileTheFileIsWritten) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "AddressSanitizer's allocator (quarantine, shadow memory, its own caches) decides the "
                  "peak RSS here: the bound is measured in the regular build";
#endif
  const std::size_t n = 100000;
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0, 46.4);
  Scene scene;
  for (std::size_t i = 0; i < n; ++i) {
    scene.sphere_position.push_back({u(rng), u(rng), u(rng)});
    scene.sphere_radius.push_back(1.21);
  }
  write_scene(path("dense.h5"), scene);
  const std::string common = "detect " + path("dense.h5") + " --backend cpu --threads 2 --precision fp64";
  const Measured limited =
      run_measured(common + " -o " + path("limited.h5") + " --memory-limit 32M", path("limited.log"));
  ASSERT_EQ(limited.code, 0) << limited.output;
  const std::uint64_t rows = read_contact_header(path("limited.h5")).rows;
  const std::uint64_t bytes = std::filesystem::file_size(path("limited.h5"));
  ASSERT_GT(rows, 2000000u);
  EXPECT_GE(bytes, rows * 96);
  std::filesystem::remove(path("limited.h5"));
  const Measured whole = run_measured(common + " -o " + path("whole.h5"), path("whole.log"));
  ASSERT_EQ(whole.code, 0) << whole.output;
  EXPECT_EQ(read_contact_header(path("whole.h5")).rows, rows);
  std::filesystem::remove(path("whole.h5"));
  const double limited_mb = double(limited.max_rss_kib) / 1024, whole_mb = double(whole.max_rss_kib) / 1024,
               rows_mb = double(rows * 96) / double(1 << 20);
  std::printf("peak RSS: --memory-limit 32M %.0f MiB, no limit %.0f MiB; rows %.0f MiB\n", limited_mb,
              whole_mb, rows_mb);
  EXPECT_GT(whole_mb, rows_mb) << "the run without a limit holds every row";
  EXPECT_LT(limited_mb, 0.6 * rows_mb) << "the run in pieces holds more than a few pieces";
}

// A piece that fails after the first piece's rows went to the file — out of memory outside what a
// smaller piece mends, or a device error — ends the run with one message and its exit code, and no
// output (nor its temporary) is left.
TEST_F(PiecesCli, AFailingPieceLeavesNoFile) {
  write_scene(path("scene.h5"), granular_scene(8000, 21, false));
  for (const auto& [fault, code] : {std::pair<const char*, int>{"oom@piece", 7}, {"device@piece", 4}}) {
    SCOPED_TRACE(fault);
    ::setenv("CONTACTGRID_TEST_FAULT", fault, 1);
    const CliResult r = run_cli("detect " + path("scene.h5") + " --backend cpu --threads 2 -o " +
                                path("out.h5") + " --memory-limit 512K");
    ::unsetenv("CONTACTGRID_TEST_FAULT");
    EXPECT_EQ(r.code, code) << r.output;
    EXPECT_NE(r.output.find("test fault: "), std::string::npos) << r.output;
    EXPECT_FALSE(std::filesystem::exists(path("out.h5")));
    EXPECT_EQ(entries(), std::vector<std::string>{"scene.h5"}) << "a temporary was left";
  }
}

}  // namespace
}  // namespace cg::test
