// Unit tests of the HDF5 layer (src/io/), the phased contact writer: a contact file created, its rows
// written by pwrite from anywhere (uneven slices, any order, any thread count), committed or discarded,
// and what a failure in each phase leaves (nothing). Every test works in its own temporary directory
// (hdf5_io_helpers.hpp: Hdf5Io).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "hdf5_io_helpers.hpp"
#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "support/contacts_equal.hpp"
#include "support/paths.hpp"
#include "temp_dir.hpp"

namespace {

namespace fs = std::filesystem;
using cg::AttrValue;
using cg::Contacts;
using cg::InputError;
using cg::IoError;
using cg::RawType;
using cg::Scene;
using cg::Vec3;
using cg::test::error_of;
using cg::test::Hdf5Io;
using cg::test::sample_contacts;
using cg::test::sample_info;

// ---- the phased contact writer (create, rows by pwrite from anywhere, commit) --------------------------

// Rows [from, from + n) of c.
template <class Real>
Contacts<Real> slice_of(const Contacts<Real>& c, std::size_t from, std::size_t n) {
  Contacts<Real> s;
  s.full = c.full;
  cg::zip_contact_fields(s, c, true, [&](auto, auto& dst, const auto& src) {
    if (!src.empty()) dst.assign(src.begin() + from, src.begin() + from + n);
  });
  return s;
}

// Uneven slices (one row, empty, large, ...) written in a scrambled order with varying thread counts,
// through the layout's text form (as another process receives it): the file reads back as the
// contacts, and its datasets are byte for byte those of the one-call writer.
template <class Real>
void phased_round_trip(const std::string& dir, std::size_t k, bool full) {
  const bool fp32 = std::is_same_v<Real, float>;
  const Contacts<Real> c = sample_contacts<Real>(k, full);
  const std::string file = dir + "/phased.h5", whole = dir + "/whole.h5";
  cg::write_contacts(whole, c, sample_info(fp32 ? "fp32" : "fp64"), 1);
  const cg::ContactFileLayout layout =
      cg::create_contact_file(file, k, fp32 ? cg::Precision::fp32 : cg::Precision::fp64, full);
  const cg::ContactFileLayout remote = cg::ContactFileLayout::from_text(layout.to_text());
  std::vector<std::size_t> cuts{0,
                                std::min<std::size_t>(1, k),
                                std::min<std::size_t>(1, k),
                                k / 3,
                                k / 3 + std::min<std::size_t>(7, k - k / 3),
                                k};
  std::sort(cuts.begin(), cuts.end());
  const std::size_t order[] = {3, 0, 4, 2, 1};
  int threads = 1;
  for (std::size_t j : order) {
    cg::write_contact_rows(remote, cuts[j], slice_of(c, cuts[j], cuts[j + 1] - cuts[j]), threads);
    threads = threads % 3 + 1;
  }
  cg::commit_contact_file(layout, sample_info(fp32 ? "fp32" : "fp64"));
  cg::ContactFile back = cg::read_contacts(file);
  EXPECT_EQ(back.precision, fp32 ? "fp32" : "fp64");
  EXPECT_EQ(back.contacts.full, full);
  ASSERT_EQ(back.contacts.size(), k);
  EXPECT_EQ(cg::test::compare_contacts(c, back.contacts), "identical");
  EXPECT_EQ(std::get<std::int64_t>(back.attributes.at("contacts")), static_cast<std::int64_t>(k));
  for (std::size_t d = 0; d < (full ? 10u : 6u); ++d) {
    EXPECT_EQ(cg::inspect_dataset(file, cg::kContactFields[d].path)->dims,
              cg::inspect_dataset(whole, cg::kContactFields[d].path)->dims);
    EXPECT_EQ(cg::read_dataset_bytes(file, cg::kContactFields[d].path),
              cg::read_dataset_bytes(whole, cg::kContactFields[d].path))
        << cg::kContactFields[d].path;
  }
  if (!full) {
    EXPECT_FALSE(cg::inspect_dataset(file, "/contacts/local_point_a").has_value());
  }
}

TEST_F(Hdf5Io, PhasedContactsFp64Basic) { phased_round_trip<double>(m_dir.string(), 1000, false); }
TEST_F(Hdf5Io, PhasedContactsFp32Basic) { phased_round_trip<float>(m_dir.string(), 1000, false); }
TEST_F(Hdf5Io, PhasedContactsFp64Full) { phased_round_trip<double>(m_dir.string(), 1000, true); }
TEST_F(Hdf5Io, PhasedContactsFp32Full) { phased_round_trip<float>(m_dir.string(), 1000, true); }
TEST_F(Hdf5Io, PhasedContactsOneRow) { phased_round_trip<double>(m_dir.string(), 1, true); }
TEST_F(Hdf5Io, PhasedContactsEmptyFp64) { phased_round_trip<double>(m_dir.string(), 0, false); }
TEST_F(Hdf5Io, PhasedContactsEmptyFp32Full) { phased_round_trip<float>(m_dir.string(), 0, true); }

// Blocks of the writer are 4 MiB: 300 000 fp64 rows make several per vector dataset, written by
// several threads at once.
TEST_F(Hdf5Io, PhasedContactsManyBlocksManyThreads) {
  phased_round_trip<double>(m_dir.string(), 300000, true);
}

TEST_F(Hdf5Io, ContactFileLayoutTextRoundTrip) {
  cg::ContactFileLayout l;
  l.path = "dir with space/out\nnewline.h5";
  l.temp = l.path + ".tmp.17";
  l.rows = (std::uint64_t(1) << 40) + 3;
  l.precision = cg::Precision::fp32;
  l.fields = {true, true};
  l.datasets = {{"/contacts/id_a", 4096, 8}, {"/contacts/normal_on_b", (std::uint64_t(1) << 50), 12}};
  const cg::ContactFileLayout b = cg::ContactFileLayout::from_text(l.to_text());
  EXPECT_EQ(b.path, l.path);
  EXPECT_EQ(b.temp, l.temp);
  EXPECT_EQ(b.rows, l.rows);
  EXPECT_EQ(b.precision, l.precision);
  EXPECT_EQ(b.fields, l.fields);
  ASSERT_EQ(b.datasets.size(), 2u);
  EXPECT_EQ(b.datasets[1].name, "/contacts/normal_on_b");
  EXPECT_EQ(b.datasets[1].offset, std::uint64_t(1) << 50);
  EXPECT_EQ(b.datasets[1].row_bytes, 12u);
  EXPECT_THROW(cg::ContactFileLayout::from_text("garbage"), cg::Error);
}

TEST_F(Hdf5Io, PhasedRowsOutsideTheFileAreRejectedAndDiscardLeavesNothing) {
  const Contacts<double> c = sample_contacts<double>(10, false);
  const cg::ContactFileLayout layout = cg::create_contact_file(path("c.h5"), 10, cg::Precision::fp64, false);
  EXPECT_THROW(cg::write_contact_rows(layout, 5, slice_of(c, 0, 6)), cg::Error);
  EXPECT_THROW(cg::write_contact_rows(layout, 11, slice_of(c, 0, 0)), cg::Error);
  // precision and fields must match the file
  EXPECT_THROW(cg::write_contact_rows(layout, 0, sample_contacts<float>(2, false)), cg::Error);
  EXPECT_THROW(cg::write_contact_rows(layout, 0, sample_contacts<double>(2, true)), cg::Error);
  cg::discard_contact_file(layout);
  cg::discard_contact_file(layout);  // twice: no error
  EXPECT_TRUE(entries().empty());
}

// A write that fails in the row phase (the temporary is a link to /dev/full: every pwrite ENOSPC) is
// an IoError naming the file and the dataset; discarding leaves neither output nor temporary.
TEST_F(Hdf5Io, PhasedWriteFailureNamesTheDatasetAndLeavesNothing) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const cg::ContactFileLayout layout = cg::create_contact_file(path("c.h5"), 10, cg::Precision::fp64, true);
  fs::remove(layout.temp);
  fs::create_symlink("/dev/full", layout.temp);
  std::string msg =
      error_of<IoError>([&] { cg::write_contact_rows(layout, 2, sample_contacts<double>(3, true), 2); });
  EXPECT_CONTAINS(msg, path("c.h5"));
  EXPECT_CONTAINS(msg, "/contacts/id_a");
  EXPECT_CONTAINS(msg, "rows 2 to 4");
  cg::discard_contact_file(layout);
  EXPECT_TRUE(entries().empty());
  EXPECT_TRUE(fs::exists("/dev/full"));
}

TEST_F(Hdf5Io, PhasedCommitFailureRemovesTheTemporary) {
  fs::create_directories(path("c.h5/inside"));  // rename over a non-empty directory fails
  const cg::ContactFileLayout layout = cg::create_contact_file(path("c.h5"), 3, cg::Precision::fp32, false);
  cg::write_contact_rows(layout, 0, sample_contacts<float>(3, false));
  std::string msg = error_of<IoError>([&] { cg::commit_contact_file(layout, sample_info("fp32")); });
  EXPECT_CONTAINS(msg, path("c.h5"));
  EXPECT_EQ(entries(), std::vector<std::string>{"c.h5"});
}

TEST_F(Hdf5Io, PhasedCreateIntoMissingDirectoryLeavesNothing) {
  std::string msg = error_of<IoError>(
      [&] { cg::create_contact_file(path("missing/c.h5"), 3, cg::Precision::fp64, false); });
  EXPECT_CONTAINS(msg, path("missing/c.h5"));
  EXPECT_TRUE(entries().empty());
}

}  // namespace
