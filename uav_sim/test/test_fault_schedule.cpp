// The fault schedule of the simulator: what holds at each simulated time against a brute-force
// walk of the schedule at 1 ms steps (the simulator's step), the events of each step interval, and
// the parameter lists and their validation.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "topo_planner/uav_sim/fault_schedule.h"

namespace topo_planner {
namespace {

FaultSchedule example() {
  FaultSchedule s;
  std::string why;
  EXPECT_TRUE(FaultSchedule::fromLists({5.0, 8.0, 20.0, 21.5}, {10.0, 12.0}, {12.0, 1.0, 0.0, 0.0, 15.0, 0.0, -0.5, 0.2},
                                       {18.0, -3.0, 25.0, 4.0}, &s, &why))
      << why;
  return s;
}

TEST(FaultSchedule, StateAtTimes) {
  const FaultSchedule s = example();
  ASSERT_TRUE(s.validate(1.0, nullptr));
  EXPECT_FALSE(s.depthBlackout(4.999));
  EXPECT_TRUE(s.depthBlackout(5.0));  // [start, end)
  EXPECT_TRUE(s.depthBlackout(7.999));
  EXPECT_FALSE(s.depthBlackout(8.0));
  EXPECT_TRUE(s.depthBlackout(21.0));
  EXPECT_TRUE(s.odomBlackout(10.0));
  EXPECT_FALSE(s.odomBlackout(12.0));
  EXPECT_TRUE(s.odomOffset(11.999).isZero());
  EXPECT_TRUE(s.odomOffset(12.0).isApprox(Eigen::Vector3d(1.0, 0.0, 0.0)));
  EXPECT_TRUE(s.odomOffset(100.0).isApprox(Eigen::Vector3d(1.0, -0.5, 0.2)));  // jumps add up
  EXPECT_EQ(s.clockOffset(17.9), 0.0);
  EXPECT_EQ(s.clockOffset(18.0), -3.0);
  EXPECT_EQ(s.clockOffset(30.0), 1.0);
  EXPECT_DOUBLE_EQ(s.lastEventTime(), 25.0);
  EXPECT_FALSE(s.empty());
  EXPECT_TRUE(FaultSchedule().empty());
  EXPECT_EQ(FaultSchedule().describe(), "none");
  EXPECT_NE(s.describe().find("clock step at 18.00 s by -3.00 s"), std::string::npos) << s.describe();
}

// Walking the schedule in 1 ms steps (as the simulator does), the events of each step interval
// are exactly the changes of the state between its ends: the brute-force oracle.
TEST(FaultSchedule, EventsMatchTheStateChangesOfEveryStep) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> t(0.0, 10.0), d(0.01, 2.0), o(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    FaultSchedule s;
    for (int k = 0; k < 3; ++k) {
      const double a = t(rng);
      s.depth_blackouts.push_back({a, a + d(rng)});
      const double b = t(rng);
      s.odom_blackouts.push_back({b, b + d(rng)});
      s.odom_jumps.push_back({t(rng), Eigen::Vector3d(o(rng), o(rng), o(rng))});
      s.clock_steps.push_back({t(rng), o(rng)});
    }
    ASSERT_TRUE(s.validate(5.0, nullptr));
    const double dt = 0.001;
    int events = 0;
    for (int i = 0; i < 13000; ++i) {
      const double t0 = i * dt, t1 = (i + 1) * dt;
      const std::vector<FaultSchedule::Event> e = s.eventsIn(t0, t1);
      events += int(e.size());
      Eigen::Vector3d jump = Eigen::Vector3d::Zero();
      double step = 0.0;
      int depth_changes = 0, odom_changes = 0;
      for (const FaultSchedule::Event& x : e) {
        EXPECT_GT(x.t_s, t0);
        EXPECT_LE(x.t_s, t1);
        if (x.kind == FaultSchedule::Kind::kOdomJump) jump += x.offset_m;
        if (x.kind == FaultSchedule::Kind::kClockStep) step += x.step_s;
        if (x.kind == FaultSchedule::Kind::kDepthBlackout) ++depth_changes;
        if (x.kind == FaultSchedule::Kind::kOdomBlackout) ++odom_changes;
      }
      EXPECT_LT((s.odomOffset(t1) - s.odomOffset(t0) - jump).norm(), 1e-12);
      EXPECT_NEAR(s.clockOffset(t1) - s.clockOffset(t0), step, 1e-12);
      if (s.depthBlackout(t1) != s.depthBlackout(t0)) {
        EXPECT_GE(depth_changes, 1) << "at " << t1;
      }
      if (s.odomBlackout(t1) != s.odomBlackout(t0)) {
        EXPECT_GE(odom_changes, 1) << "at " << t1;
      }
    }
    EXPECT_EQ(events, 3 * 6);  // every start, end, jump and step once
  }
}

TEST(FaultSchedule, EventsAreSortedEndsFirst) {
  FaultSchedule s;
  s.depth_blackouts = {{2.0, 4.0}, {4.0, 6.0}};
  const std::vector<FaultSchedule::Event> e = s.eventsIn(3.0, 5.0);
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].phase, FaultSchedule::Event::Phase::kEnd);
  EXPECT_EQ(e[1].phase, FaultSchedule::Event::Phase::kStart);
  EXPECT_DOUBLE_EQ(e[1].end_s, 6.0);
  EXPECT_EQ(describe(e[1]), "depth_blackout start t=4.000 s until=6.000 s");
  FaultSchedule::Event j;
  j.t_s = 12.0;
  j.kind = FaultSchedule::Kind::kOdomJump;
  j.phase = FaultSchedule::Event::Phase::kStep;
  j.offset_m = Eigen::Vector3d(1.0, 0.0, 0.0);
  EXPECT_EQ(describe(j), "odom_jump step t=12.000 s offset=(1.000, 0.000, 0.000) m");
}

TEST(FaultSchedule, ListsAndValidation) {
  FaultSchedule s;
  std::string why;
  EXPECT_FALSE(FaultSchedule::fromLists({1.0}, {}, {}, {}, &s, &why));
  EXPECT_NE(why.find("depth_blackouts_s"), std::string::npos);
  EXPECT_FALSE(FaultSchedule::fromLists({}, {}, {1.0, 2.0, 3.0}, {}, &s, &why));
  EXPECT_NE(why.find("odom_jumps"), std::string::npos);
  EXPECT_FALSE(FaultSchedule::fromLists({}, {}, {}, {1.0}, &s, &why));
  EXPECT_NE(why.find("clock_steps"), std::string::npos);

  ASSERT_TRUE(FaultSchedule::fromLists({3.0, 2.0}, {}, {}, {}, &s, &why));
  EXPECT_FALSE(s.validate(1.0, &why));  // end before start
  EXPECT_NE(why.find("start < end"), std::string::npos);
  ASSERT_TRUE(FaultSchedule::fromLists({}, {-1.0, 2.0}, {}, {}, &s, &why));
  EXPECT_FALSE(s.validate(1.0, &why));  // negative time
  ASSERT_TRUE(FaultSchedule::fromLists({}, {}, {1.0, NAN, 0.0, 0.0}, {}, &s, &why));
  EXPECT_FALSE(s.validate(1.0, &why));
  // A backward step may not take the ROS time to zero or below: at t = 2 s the clock reads 3 s.
  ASSERT_TRUE(FaultSchedule::fromLists({}, {}, {}, {2.0, -2.5}, &s, &why));
  EXPECT_TRUE(s.validate(1.0, &why)) << why;
  ASSERT_TRUE(FaultSchedule::fromLists({}, {}, {}, {2.0, -2.5, 2.1, -1.0}, &s, &why));
  EXPECT_FALSE(s.validate(1.0, &why));
  EXPECT_NE(why.find("positive"), std::string::npos);
}

}  // namespace
}  // namespace topo_planner
