// The progress line's text (what the terminal shows; drawing itself needs a terminal).
#include <gtest/gtest.h>

#include "run/progress.hpp"

namespace cg {

TEST(Progress, LineSaysDoneTotalRateAndTimeLeft) {
  EXPECT_EQ(Progress::line("validate", "contacts", 1'200'000, 3'310'000, 3.0),
            "validate: 1.2 M / 3.31 M contacts (36 %)  400 k/s  ETA 5 s");
}

TEST(Progress, LineWithoutTotalHasNoPercentOrEta) {
  EXPECT_EQ(Progress::line("generate", "bodies", 500, 0, 2.0), "generate: 500 bodies  250/s");
}

TEST(Progress, LongWaitsInMinutesAndHours) {
  EXPECT_EQ(Progress::line("simulate", "steps", 10, 1000, 10.0),
            "simulate: 10 / 1 k steps (1 %)  1/s  ETA 16 min 30 s");
  EXPECT_EQ(Progress::line("simulate", "steps", 1, 10'000, 1.0),
            "simulate: 1 / 10 k steps (0 %)  1/s  ETA 2.8 h");
}

TEST(Progress, QuietOrNotATerminalDrawsNothing) {
  Progress quiet("detect", "steps", 10, false);
  EXPECT_FALSE(quiet.drawing());
  quiet.update(5);  // no output, no crash
}

}  // namespace cg
