// Small parts of the kernels' design that both backends share: the typed stage ids (their names and
// order are the public timing table's) and the CUDA tuning knobs, read in one place (g++-safe).
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <vector>

#include "cuda/tuning.hpp"
#include "stage.hpp"

namespace cg::test {
namespace {

TEST(StageIds, NamesInPipelineOrder) {
  std::vector<std::string> names;
  for (int i = 0; i < detail::kStageCount; ++i) names.push_back(detail::name(detail::stage_at(i)));
  const std::vector<std::string> expect{"plan",  "upload", "skin",   "pack",    "entries", "sort",
                                        "pairs", "order",  "narrow", "history", "download"};
  EXPECT_EQ(names, expect);
}

TEST(StageIds, HostTimerAppendsLapsByName) {
  StageTimes times;
  detail::HostStageTimer t(times);
  t.lap(detail::EngineStage::pack);
  t.lap(detail::EngineStage::narrow);
  ASSERT_EQ(times.size(), 2u);
  EXPECT_EQ(times[0].name, "pack");
  EXPECT_EQ(times[1].name, "narrow");
  EXPECT_GE(times[1].seconds, 0.0);
}

TEST(CudaTuning, KnobsReadInOnePlace) {
  const char* knobs[] = {"CONTACTGRID_CUDA_TYPE_PASSES",  "CONTACTGRID_DEVICE_MEMORY_LIMIT",
                         "CONTACTGRID_CUDA_UPLOAD",       "CONTACTGRID_CUDA_RENUMBER",
                         "CONTACTGRID_CUDA_ORDER",        "CONTACTGRID_CUDA_DOWNLOAD",
                         "CONTACTGRID_CUDA_TRANSFER_SLOT"};
  struct Unset {  // the knobs are removed even when an assertion fails
    const char* const* names;
    ~Unset() {
      for (int i = 0; i < 7; ++i) ::unsetenv(names[i]);
    }
  } unset{knobs};
  for (const char* k : knobs) ::unsetenv(k);
  detail::Tuning t = detail::read_tuning();
  EXPECT_FALSE(t.type_passes);
  EXPECT_FALSE(t.memory_limit.has_value());
  EXPECT_EQ(t.renumber, detail::Forced::automatic);
  EXPECT_TRUE(detail::tuned(t.counting_order, true));
  EXPECT_EQ(detail::upload_transfer(t, std::size_t(1) << 20), detail::HostTransfer::streamed);
  EXPECT_EQ(detail::upload_transfer(t, 1000), detail::HostTransfer::single);
  // automatic download: an engine's first streams (from 64 MiB: registered) unless its staging buffer
  // holds the rows already; later ones use the staging buffer
  EXPECT_EQ(detail::download_transfer(t, 0, 1000, true), detail::HostTransfer::streamed);
  EXPECT_EQ(detail::download_transfer(t, 0, (std::size_t(64) << 20) - 1, true),
            detail::HostTransfer::streamed);
  EXPECT_EQ(detail::download_transfer(t, 0, std::size_t(64) << 20, true), detail::HostTransfer::registered);
  EXPECT_EQ(detail::download_transfer(t, std::size_t(1) << 30, std::size_t(64) << 20, true),
            detail::HostTransfer::single);
  EXPECT_EQ(detail::download_transfer(t, 4096, 1000, true), detail::HostTransfer::single);
  EXPECT_EQ(detail::download_transfer(t, 0, 1000, false), detail::HostTransfer::single);
  EXPECT_EQ(t.transfer_slot_bytes, std::size_t(4) << 20);

  ::setenv("CONTACTGRID_CUDA_TYPE_PASSES", "1", 1);
  ::setenv("CONTACTGRID_DEVICE_MEMORY_LIMIT", "73400320", 1);
  ::setenv("CONTACTGRID_CUDA_UPLOAD", "pageable", 1);
  ::setenv("CONTACTGRID_CUDA_RENUMBER", "0", 1);
  ::setenv("CONTACTGRID_CUDA_ORDER", "radix", 1);
  ::setenv("CONTACTGRID_CUDA_DOWNLOAD", "registered", 1);
  ::setenv("CONTACTGRID_CUDA_TRANSFER_SLOT", "65536", 1);
  t = detail::read_tuning();
  EXPECT_TRUE(t.type_passes);
  ASSERT_TRUE(t.memory_limit.has_value());
  EXPECT_EQ(*t.memory_limit, std::size_t(70) << 20);
  EXPECT_EQ(t.upload, detail::HostTransfer::single);
  EXPECT_EQ(t.renumber, detail::Forced::off);
  EXPECT_FALSE(detail::tuned(t.counting_order, true));
  EXPECT_EQ(detail::download_transfer(t, 0, 1000, true), detail::HostTransfer::registered);
  EXPECT_EQ(detail::download_transfer(t, 0, 1000, false), detail::HostTransfer::registered);
  EXPECT_EQ(t.transfer_slot_bytes, std::size_t(65536));

  ::setenv("CONTACTGRID_CUDA_TYPE_PASSES", "0", 1);
  ::setenv("CONTACTGRID_CUDA_ORDER", "something", 1);  // unknown spelling: automatic
  ::setenv("CONTACTGRID_CUDA_UPLOAD", "streamed", 1);
  t = detail::read_tuning();
  EXPECT_FALSE(t.type_passes);
  EXPECT_EQ(t.counting_order, detail::Forced::automatic);
  EXPECT_EQ(t.upload, detail::HostTransfer::streamed);
}

}  // namespace
}  // namespace cg::test
