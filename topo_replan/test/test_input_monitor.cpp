// Input liveness and the clock on their own (input_monitor.h): each freshness rule, the refusals of
// out-of-order and future stamps, and a time jump shifting the stamps of the old clock only.
#include "topo_planner/topo_replan/input_monitor.h"

#include <string>

#include <gtest/gtest.h>

namespace topo_planner {
namespace {

// Odometry and depth every 0.05 s from t = 0 up to `until`, the clock observed at each.
void feed(InputMonitor* m, double from, double until) {
  std::string why;
  for (double t = from; t <= until + 1e-9; t += 0.05) {
    m->observeClock(t);
    ASSERT_TRUE(m->acceptOdometry(t, t, &why)) << why;
    m->depthFused(t, t);
  }
}

TEST(InputMonitor, EachInputHasAFreshnessRule) {
  InputMonitor::Config config;  // odometry 0.25 s since arrival, stamp 0.5 s old; depth 0.5 s old
  InputMonitor m(config);
  std::string why;
  EXPECT_FALSE(m.fresh(0.0, &why));
  EXPECT_EQ(why, "no odometry");
  m.observeClock(0.0);
  ASSERT_TRUE(m.acceptOdometry(0.0, 0.0, &why));
  EXPECT_FALSE(m.fresh(0.0, &why));
  EXPECT_EQ(why, "no depth frame fused yet");
  feed(&m, 0.0, 1.0);
  EXPECT_TRUE(m.fresh(1.0, &why)) << why;
  EXPECT_TRUE(why.empty());
  // Odometry stops arriving.
  EXPECT_TRUE(m.fresh(1.24, &why)) << why;
  EXPECT_FALSE(m.fresh(1.26, &why));
  EXPECT_NE(why.find("no odometry for"), std::string::npos) << why;
  // Odometry arrives, but stamped long ago (a delayed estimator).
  ASSERT_TRUE(m.acceptOdometry(1.05, 1.6, &why));
  EXPECT_FALSE(m.fresh(1.6, &why));
  EXPECT_NE(why.find("odometry stamped 0.55 s ago"), std::string::npos) << why;
  // Fresh odometry, depth stopped at 1.0.
  ASSERT_TRUE(m.acceptOdometry(1.6, 1.6, &why));
  EXPECT_FALSE(m.fresh(1.6, &why));
  EXPECT_NE(why.find("depth frame fused is 0.60 s old"), std::string::npos) << why;
  const InputHealth h = m.health(1.6);
  EXPECT_FALSE(h.ok);
  EXPECT_NEAR(h.depth_age_s, 0.6, 1e-9);
  EXPECT_NEAR(h.odom_age_s, 0.0, 1e-9);
  // Depth not required.
  config.depth_timeout_s = 0.0;
  m.setConfig(config);
  EXPECT_TRUE(m.fresh(1.6, &why)) << why;
}

TEST(InputMonitor, RefusesOutOfOrderAndFutureStamps) {
  InputMonitor m{InputMonitor::Config()};
  std::string why;
  feed(&m, 0.0, 1.0);
  EXPECT_FALSE(m.acceptOdometry(0.9, 1.05, &why));
  EXPECT_NE(why.find("before the last odometry"), std::string::npos) << why;
  EXPECT_FALSE(m.acceptOdometry(1.7, 1.05, &why));  // 0.65 s ahead of its arrival
  EXPECT_NE(why.find("ahead of the clock"), std::string::npos) << why;
  EXPECT_NEAR(m.odometryStamp(), 1.0, 1e-9);
  // A depth frame from the future is ignored; so is an older one; the same one again changes nothing.
  m.depthFused(2.0, 1.05);
  m.depthFused(0.5, 1.05);
  m.depthFused(1.0, 1.05);
  EXPECT_NEAR(m.health(1.05).depth_age_s, 0.05, 1e-9);
}

TEST(InputMonitor, AClockStepIsATimeJumpThatShiftsTheOldStamps) {
  InputMonitor m{InputMonitor::Config()};  // jump: > 1 s forwards, > 0.15 s back
  feed(&m, 0.0, 2.0);
  EXPECT_EQ(m.timeJumps(), 0);
  // Small steps back are the callers' order, not a jump.
  EXPECT_FALSE(m.observeClock(1.9));
  EXPECT_NEAR(m.clock(), 2.0, 1e-9);
  // A step of 10 s forwards: the stamps of the old clock move by the step less the usual interval.
  const std::optional<InputMonitor::TimeJump> jump = m.observeClock(12.0);
  ASSERT_TRUE(jump);
  EXPECT_EQ(m.timeJumps(), 1);
  EXPECT_NEAR(jump->step_s, 10.0, 1e-9);
  EXPECT_GT(jump->shift_s, 9.95 - 1e-9);
  EXPECT_LT(jump->shift_s, 10.0);
  std::string why;
  EXPECT_TRUE(m.fresh(12.0, &why)) << why;  // not stale by the step alone
  // A stamp already in the new base (an input that came after the step) stays.
  double old_stamp = 1.5, new_stamp = 11.9;
  jump->shiftStamp(&old_stamp);
  jump->shiftStamp(&new_stamp);
  EXPECT_NEAR(old_stamp, 1.5 + jump->shift_s, 1e-9);
  EXPECT_EQ(new_stamp, 11.9);
  // Backwards by more than 0.15 s: a jump too; the last odometry is then not "in the future".
  ASSERT_TRUE(m.observeClock(11.0));
  EXPECT_EQ(m.timeJumps(), 2);
  EXPECT_TRUE(m.fresh(11.0, &why)) << why;
  // A non-finite clock is ignored.
  EXPECT_FALSE(m.observeClock(NAN));
  EXPECT_EQ(m.clock(), 11.0);
}

}  // namespace
}  // namespace topo_planner
