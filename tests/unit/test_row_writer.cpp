// The contact rows' two writers (src/io/row_writer.hpp): pwrite, and the shared mapping whose pages
// each thread populates. Every file written one way is byte for byte the file written the other way
// (precisions, field sets, 0, 1 and many rows, whole and streamed, on tmpfs and on a disk), reads back
// through HDF5 as the rows written, and the command line writes the same /contacts either way for
// sphere, ellipsoid and mixed scenes on both backends. A full filesystem ends either way with exit 6,
// the disk's reason, and nothing left.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <type_traits>
#include <vector>

#include "backends.hpp"
#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/row_writer.hpp"
#include "support/contacts_equal.hpp"
#include "support/paths.hpp"
#include "support/run_cli.hpp"
#include "support/shell.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

namespace fs = std::filesystem;

// CONTACTGRID_IO_WRITE set for a scope (restored after).
class IoKnob {
 public:
  explicit IoKnob(const char* value) {
    if (const char* old = std::getenv("CONTACTGRID_IO_WRITE")) m_old = old;
    ::setenv("CONTACTGRID_IO_WRITE", value, 1);
  }
  ~IoKnob() {
    if (m_old.empty())
      ::unsetenv("CONTACTGRID_IO_WRITE");
    else
      ::setenv("CONTACTGRID_IO_WRITE", m_old.c_str(), 1);
  }
  IoKnob(const IoKnob&) = delete;
  IoKnob& operator=(const IoKnob&) = delete;

 private:
  std::string m_old;
};

std::vector<unsigned char> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// k rows of every field in `set`, each column its own values (no two datasets alike, no NaN).
template <class Real>
Contacts<Real> rows_of(std::size_t k, FieldSet set) {
  Contacts<Real> c;
  c.resize(k, set);
  c.full = set.full;
  c.history = set.history;
  for_each_contact_field(c, set, [&](auto index, auto& column) {
    using T = std::remove_cvref_t<decltype(column[0])>;
    if constexpr (std::is_same_v<T, std::int64_t>) {
      for (std::size_t i = 0; i < k; ++i) column[i] = std::int64_t(i) * 7 + std::int64_t(index) - 3;
    } else {
      Real* v = reinterpret_cast<Real*>(column.data());
      const std::size_t n = k * sizeof(T) / sizeof(Real);
      for (std::size_t j = 0; j < n; ++j) v[j] = Real(j) * Real(0.37) + Real(index) - Real(1e3);
    }
  });
  return c;
}

RunInfo info_for(bool fp32) {
  RunInfo info;
  info.bodies = 99;
  info.precision = fp32 ? "fp32" : "fp64";
  info.backend = "cpu";
  info.cell_size = 1.5;
  info.input = "scene.h5";
  return info;
}

class RowWriter : public TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    m_shm = fs::path("/dev/shm") / m_dir.filename();
    std::error_code ec;
    fs::create_directories(m_shm, ec);
    if (ec) m_shm.clear();
  }
  void TearDown() override {
    std::error_code ec;
    if (!m_shm.empty()) fs::remove_all(m_shm, ec);
    TempDirTest::TearDown();
  }
  // The directories to write into: this test's disk directory, and one on tmpfs when there is one.
  std::vector<std::string> dirs() const {
    std::vector<std::string> d{m_dir.string()};
    if (!m_shm.empty()) d.push_back(m_shm.string());
    return d;
  }
  fs::path m_shm;
};

// One file per writer in `dir`, by write_contacts (threads writers); the two byte for byte equal and
// read back through HDF5 as the rows.
template <class Real>
void expect_same_whole_files(const std::string& dir, std::size_t k, FieldSet set, int threads) {
  const bool fp32 = std::is_same_v<Real, float>;
  const Contacts<Real> c = rows_of<Real>(k, set);
  for (const char* mode : {"pwrite", "map"}) {
    IoKnob knob(mode);
    write_contacts(dir + "/" + mode + ".h5", c, info_for(fp32), threads);
  }
  const auto a = file_bytes(dir + "/pwrite.h5"), b = file_bytes(dir + "/map.h5");
  ASSERT_FALSE(a.empty());
  EXPECT_TRUE(a == b) << "the two writers' files differ (" << a.size() << " and " << b.size() << " bytes)";
  const ContactFile back = read_contacts(dir + "/map.h5");
  EXPECT_EQ(back.precision, fp32 ? "fp32" : "fp64");
  ASSERT_EQ(back.contacts.size(), k);
  if (!set.history) {  // (compare_contacts looks at the basic and full fields)
    EXPECT_EQ(compare_contacts(c, back.contacts), "identical");
  }
  for (const ContactField& f : kContactFields) {
    if (!set.has(f.group)) continue;
    const auto bytes = read_dataset_bytes(dir + "/map.h5", f.path);
    EXPECT_EQ(bytes.size(),
              k * (f.kind == FieldKind::vector ? 3 : 1) * (f.kind == FieldKind::integer ? 8 : sizeof(Real)))
        << f.path;
  }
}

TEST_F(RowWriter, WholeFilesAreByteIdenticalEitherWay) {
  for (const std::string& dir : dirs()) {
    for (std::size_t k : {std::size_t{0}, std::size_t{1}, std::size_t{17}, std::size_t{5000}}) {
      for (FieldSet set : {FieldSet{}, FieldSet{true}, FieldSet{true, true}}) {
        SCOPED_TRACE(dir + ", " + std::to_string(k) + " rows, full " + std::to_string(set.full) +
                     ", history " + std::to_string(set.history));
        expect_same_whole_files<float>(dir, k, set, 2);
        expect_same_whole_files<double>(dir, k, set, 1);
      }
    }
  }
}

// 300 000 fp64 rows: several 4 MiB blocks a vector dataset, on 1 to 4 threads, into pages of a
// mapping that starts and ends mid-page.
TEST_F(RowWriter, ManyBlocksOnManyThreadsAreByteIdentical) {
  for (const std::string& dir : dirs()) {
    for (int threads : {1, 4}) {
      SCOPED_TRACE(dir + ", " + std::to_string(threads) + " threads");
      expect_same_whole_files<double>(dir, 300000, FieldSet{true, true}, threads);
    }
  }
}

// Appended in uneven blocks (ContactFileStream: chunked datasets, the chunks found per append):
// the same file bytes either way, and the same dataset bytes as the whole file's.
TEST_F(RowWriter, StreamedFilesAreByteIdenticalEitherWay) {
  const FieldSet set{true, true};
  const Contacts<float> c = rows_of<float>(70001, set);
  const std::size_t cuts[] = {0, 1, 40000, 40001, 70001};
  for (const std::string& dir : dirs()) {
    SCOPED_TRACE(dir);
    for (const char* mode : {"pwrite", "map"}) {
      IoKnob knob(mode);
      ContactFileStream stream(dir + "/" + mode + ".h5", Precision::fp32, set);
      for (std::size_t j = 0; j + 1 < std::size(cuts); ++j) {
        Contacts<float> s;
        s.resize(cuts[j + 1] - cuts[j], set);
        s.full = set.full;
        s.history = set.history;
        zip_contact_fields(s, c, set, [&](auto, auto& dst, const auto& src) {
          std::copy(src.begin() + cuts[j], src.begin() + cuts[j + 1], dst.begin());
        });
        stream.append(s, 3);
      }
      stream.commit(info_for(true));
    }
    write_contacts(dir + "/whole.h5", c, info_for(true));
    const auto a = file_bytes(dir + "/pwrite.h5"), b = file_bytes(dir + "/map.h5");
    EXPECT_TRUE(!a.empty() && a == b) << "the streamed files differ";
    for (const ContactField& f : kContactFields)
      EXPECT_EQ(read_dataset_bytes(dir + "/map.h5", f.path), read_dataset_bytes(dir + "/whole.h5", f.path))
          << f.path;
  }
}

TEST_F(RowWriter, KnobChoosesAndRefusesOtherValues) {
  {
    IoKnob knob("");  // unset: by the team's size
    EXPECT_EQ(row_write_mode(1), RowWriteMode::pwrite);
    EXPECT_EQ(row_write_mode(kMapWriteThreads - 1), RowWriteMode::pwrite);
    EXPECT_EQ(row_write_mode(kMapWriteThreads), RowWriteMode::map);
  }
  {
    IoKnob knob("pwrite");
    EXPECT_EQ(row_write_mode(64), RowWriteMode::pwrite);
  }
  {
    IoKnob knob("map");
    EXPECT_EQ(row_write_mode(1), RowWriteMode::map);
  }
  {
    IoKnob knob("hdf5");
    EXPECT_THROW(row_write_mode(1), UsageError);
  }
}

// ---- the command line -----------------------------------------------------------------------------

template <class T>
class RowWriterCli : public RowWriter {};
TYPED_TEST_SUITE(RowWriterCli, BackendTypes, BackendTypeNames);

// detect of a sphere, an ellipsoid and a mixed scene, fp32 and fp64, basic and full fields, into
// tmpfs with each writer: every /contacts dataset the same bytes.
TYPED_TEST(RowWriterCli, DetectWritesTheSameContactsEitherWay) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  const std::string dir = this->m_shm.empty() ? this->m_dir.string() : this->m_shm.string();
  const std::string backend = to_string(TypeParam::backend);
  for (const char* kind : {"uniform", "ellipsoids", "mixed"}) {
    const std::string scene = dir + "/" + kind + ".h5";
    const CliResult g =
        run_cli(std::string("generate ") + scene + " --kind " + kind + " -n 6000 --seed 5 -q");
    ASSERT_EQ(g.code, 0) << g.output;
    for (const char* precision : {"fp32", "fp64"}) {
      for (const char* fields : {"basic", "full"}) {
        SCOPED_TRACE(std::string(kind) + " " + precision + " " + fields + " " + backend);
        for (const char* mode : {"pwrite", "map"}) {
          const ShellResult r =
              run_shell("CONTACTGRID_IO_WRITE=" + std::string(mode) + " " + cli_binary() + " detect " +
                        scene + " -o " + dir + "/" + mode + ".h5 --backend " + backend + " --precision " +
                        precision + " --fields " + fields + " -q 2>&1");
          ASSERT_EQ(r.code, 0) << r.output;
        }
        const ContactFile back = read_contacts(dir + "/map.h5");
        EXPECT_GT(back.contacts.size(), 0u);
        for (const ContactField& f : kContactFields) {
          if (!FieldSet{std::string(fields) == "full"}.has(f.group)) continue;
          EXPECT_EQ(read_dataset_bytes(dir + "/pwrite.h5", f.path),
                    read_dataset_bytes(dir + "/map.h5", f.path))
              << f.path;
        }
      }
    }
  }
}

// A filesystem that fills up while the rows are written (the file's space is set aside sparse at its
// creation, so with the mapping it is the pages' population that fails): exit 6, the disk's reason,
// nothing left, with either writer; and an unknown CONTACTGRID_IO_WRITE is a usage error (exit 2).
TEST_F(RowWriter, FullFilesystemEndsWithExit6EitherWay) {
  const CliResult g = run_cli("generate " + path("scene.h5") + " -n 20000 --seed 4 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  fs::create_directories(path("disk"));
  for (const char* mode : {"pwrite", "map"}) {
    SCOPED_TRACE(mode);
    const std::string detect = "CONTACTGRID_IO_WRITE=" + std::string(mode) + " " + cli_binary() + " detect " +
                               path("scene.h5") + " -o " + path("disk") +
                               "/out.h5 --backend cpu --threads 2 -q";
    const ShellResult r = run_on_small_tmpfs(path("disk"), 256, detect);
    if (r.code == -1 && r.output.empty()) GTEST_SKIP() << "no tmpfs in a user namespace here (unshare -rm)";
    EXPECT_EQ(r.code, 6) << r.output;
    EXPECT_NE(r.output.find("No space left on device"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("/contacts/"), std::string::npos)
        << "not the rows' write that failed: " << r.output;
    EXPECT_NE(r.output.find("LEFT:\n"), std::string::npos) << "files left on the full filesystem:\n"
                                                           << r.output;
    const ShellResult ok = run_on_small_tmpfs(path("disk"), 8192, detect);
    EXPECT_EQ(ok.code, 0) << ok.output;
    EXPECT_NE(ok.output.find("LEFT:out.h5\n"), std::string::npos) << ok.output;
  }
  const ShellResult bad = run_shell("CONTACTGRID_IO_WRITE=hdf5 " + cli_binary() + " detect " +
                                    path("scene.h5") + " -o " + path("bad.h5") + " --backend cpu -q 2>&1");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("CONTACTGRID_IO_WRITE=hdf5"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(path("bad.h5")));
}

}  // namespace
}  // namespace cg::test
