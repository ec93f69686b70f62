// The health rules of /diagnostics (plan_manage/health.h), without a roscore.
#include <gtest/gtest.h>

#include <cmath>

#include "topo_planner/plan_manage/health.h"

namespace topo_planner {
namespace {

PlannerHealth::Inputs flying() {
  PlannerHealth::Inputs in;
  in.state = "EXEC_TRAJ";
  in.have_odometry = true;
  in.odom_age_s = 0.01;
  in.depth_age_s = 0.03;
  return in;
}

TEST(EventWindow, KeepsTheLastWindowAndRestartsWhenTimeGoesBack) {
  EventWindow w(2.0);
  for (int k = 0; k <= 10; ++k) w.add(0.5 * k, k);  // t = 0 .. 5
  EXPECT_EQ(w.size(), 5u);                          // t = 3, 3.5, 4, 4.5, 5
  EXPECT_DOUBLE_EQ(w.median(), 8.0);
  EXPECT_DOUBLE_EQ(w.max(), 10.0);
  EXPECT_EQ(w.countAbove(8.5), 2u);
  EXPECT_DOUBLE_EQ(w.increase(), 4.0);
  EXPECT_DOUBLE_EQ(w.increasePerSecond(), 2.0);
  w.prune(6.5);
  EXPECT_EQ(w.size(), 2u);  // t = 4.5, 5
  w.add(1.0, 3.0);          // the clock went back
  EXPECT_EQ(w.size(), 1u);
  EXPECT_TRUE(std::isnan(w.increasePerSecond()));
  w.add(NAN, 1.0);  // ignored
  EXPECT_EQ(w.size(), 1u);
  EventWindow empty(1.0);
  EXPECT_TRUE(std::isnan(empty.median()));
  EXPECT_TRUE(std::isnan(empty.max()));
}

TEST(PlannerHealth, OkWhileFlyingWithFreshInputsAndSucceedingPlans) {
  PlannerHealth h;
  for (int k = 0; k < 40; ++k) h.addPlanningCall(0.25 * k, k % 10 != 0, 2.0 + (k % 3));
  const HealthReport r = h.report(10.0, flying());
  EXPECT_EQ(r.level, HealthLevel::kOk) << r.message;
  EXPECT_EQ(r.value("state"), "EXEC_TRAJ");
  EXPECT_EQ(r.value("planning calls in window"), "40");
  EXPECT_EQ(r.value("failed calls in window"), "4");
  EXPECT_EQ(r.value("planning rate [Hz]"), "4.00");
  EXPECT_EQ(r.value("planning time median [ms]"), "3.00");
  EXPECT_EQ(r.value("planning time max [ms]"), "4.00");
  EXPECT_EQ(r.value("trajectories published total"), "36");
}

TEST(PlannerHealth, StaleInputsAreAnErrorAndMissingOdometryAWarning) {
  PlannerHealth h;
  PlannerHealth::Inputs in = flying();
  in.inputs_ok = false;
  in.inputs_why = "odometry 0.40 s old";
  HealthReport r = h.report(1.0, in);
  EXPECT_EQ(r.level, HealthLevel::kError);
  EXPECT_NE(r.message.find("odometry 0.40 s old"), std::string::npos) << r.message;
  // Before the first depth frame: waiting, not stale.
  in.depth_age_s = -1.0;
  in.inputs_why = "no depth frame yet";
  r = h.report(1.0, in);
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_NE(r.message.find("waiting for inputs"), std::string::npos) << r.message;
  in = PlannerHealth::Inputs();
  in.state = "INIT";
  in.inputs_ok = false;
  r = h.report(1.0, in);
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_EQ(r.message, "waiting for odometry");
  EXPECT_EQ(r.value("odometry age [s]"), "nan");
}

TEST(PlannerHealth, FailuresStopsAndGiveUpsWarnForTheirWindow) {
  PlannerHealth h;
  for (int k = 0; k < 10; ++k) h.addPlanningCall(0.1 * k, k < 4, 5.0);  // 6 of 10 failed
  HealthReport r = h.report(1.0, flying());
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_NE(r.message.find("6 of 10 planning calls failed"), std::string::npos) << r.message;
  r = h.report(20.0, flying());  // out of the window
  EXPECT_EQ(r.level, HealthLevel::kOk) << r.message;
  // Below min_calls no verdict on the fraction.
  h.addPlanningCall(21.0, false, 1.0);
  EXPECT_EQ(h.report(21.0, flying()).level, HealthLevel::kOk);

  h.addEmergencyStop(22.0);
  r = h.report(23.0, flying());
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_NE(r.message.find("emergency stop"), std::string::npos);
  EXPECT_EQ(h.report(40.0, flying()).level, HealthLevel::kOk);
  EXPECT_EQ(h.report(40.0, flying()).value("emergency stops total"), "1");

  h.addGiveUp(41.0, "goal 0 is unreachable");
  r = h.report(60.0, flying());
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_NE(r.message.find("goal 0 is unreachable"), std::string::npos);
  EXPECT_EQ(h.report(80.0, flying()).level, HealthLevel::kOk);  // after give_up_hold_s
}

TEST(MappingHealth, RatesRefusalsAndAStaleMap) {
  MappingHealth h;
  MappingHealth::Inputs in;
  HealthReport r = h.report(0.0, in);
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_EQ(r.message, "no depth frame yet");
  // 30 Hz for 4 s.
  for (int k = 1; k <= 4; ++k) {
    in.frames_fused = 30 * k;
    in.depth_arrival_s = in.depth_stamp_s = k - 0.01;
    in.pose_arrival_s = k - 0.005;
    r = h.report(k, in);
  }
  EXPECT_EQ(r.level, HealthLevel::kOk) << r.message;
  EXPECT_EQ(r.value("fusion rate [Hz]"), "30.00");
  EXPECT_EQ(r.value("map age [s]"), "0.010");
  // Frames refused: a warning while they are in the window.
  in.frames_refused = 3;
  in.frames_fused += 30;
  in.depth_arrival_s = 4.99;
  r = h.report(5.0, in);
  EXPECT_EQ(r.level, HealthLevel::kWarn);
  EXPECT_NE(r.message.find("3 depth frames refused"), std::string::npos) << r.message;
  in.frames_fused += 300;
  in.depth_arrival_s = 14.99;
  h.report(14.0, in);
  EXPECT_EQ(h.report(15.0, in).level, HealthLevel::kOk);
  // The camera stops: an error once the map is older than stale_s.
  r = h.report(15.8, in);
  EXPECT_EQ(r.level, HealthLevel::kError);
  EXPECT_NE(r.message.find("not updated"), std::string::npos) << r.message;
}

}  // namespace
}  // namespace topo_planner
