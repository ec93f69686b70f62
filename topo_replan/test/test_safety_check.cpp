// The safety thread's rules on their own (safety_check.h): stale inputs brake a moving vehicle only,
// odometry far from the commanded position holds at the measured one, a collision far ahead is
// replanned and a near one braked for (at the back-up deceleration the commitment keeps), a
// trajectory that ends moving is braked for before it runs out, manoeuvres are not checked.
#include "topo_planner/topo_replan/safety_check.h"

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

using Action = SafetyCheck::Verdict::Action;

// A 20 x 6 x 3 m hall, all observed free; with `pillar`, a pillar of radius 0.3 m at (12, 3).
SyntheticScene hall(bool pillar) {
  SyntheticScene scene(Eigen::Vector3d(20.0, 6.0, 3.0));
  if (pillar) scene.pillar(12.0, 3.0, 0.3);
  return scene;
}

// 4 s along y = 3, z = 1.5 at 3 m/s from x = 2, started at start_s; it ends moving.
ExecTrajectory straight(double start_s = 0.0) {
  const double h = 0.05, v = 3.0;
  const int n = int(4.0 / h) + 3;
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i) q.row(i) << 2.0 + v * h * (i - 1), 3.0, 1.5;
  ExecTrajectory traj;
  traj.start_time_s = start_s;
  traj.spline = UniformBspline(q, 3, h);
  traj.brake_start_s = traj.endTime();
  return traj;
}

// Odometry exactly where the trajectory commands the vehicle at `stamp`.
SafetyCheck::Odometry onTrack(const ExecTrajectory& traj, double stamp) {
  const FlatState s = traj.stateAt(stamp);
  return {stamp, s.position, s.velocity};
}

TEST(SafetyCheck, AClearWayWithFreshInputsFliesOn) {
  SyntheticScene scene = hall(false);
  const EsdfMap& map = scene.finish();
  const ExecTrajectory traj = straight();
  const SafetyCheck::Verdict v = SafetyCheck({}).check(0.5, {&traj}, onTrack(traj, 0.5), nullptr, map);
  EXPECT_EQ(v.action, Action::kNone);
  EXPECT_FALSE(v.collision_ahead);
}

TEST(SafetyCheck, StaleInputsBrakeAMovingVehicleOnly) {
  SyntheticScene scene = hall(false);
  const EsdfMap& map = scene.finish();
  const SafetyCheck check({});
  const std::string stale = "depth 0.8 s old";
  ExecTrajectory traj = straight();
  SafetyCheck::Verdict v = check.check(1.0, {&traj}, onTrack(traj, 1.0), &stale, map);
  EXPECT_EQ(v.action, Action::kBrake);
  EXPECT_EQ(v.why, "inputs stale (depth 0.8 s old)");
  EXPECT_EQ(v.status, ReplanStatus::kInvalidInput);
  // Already braking, or at rest after the trajectory: nothing more.
  traj.braking = true;
  EXPECT_EQ(check.check(1.0, {&traj}, onTrack(traj, 1.0), &stale, map).action, Action::kNone);
  traj.braking = false;
  EXPECT_EQ(check.check(5.0, {&traj}, onTrack(traj, 5.0), &stale, map).action, Action::kNone);
}

TEST(SafetyCheck, OdometryFarFromTheCommandedPositionHoldsAtTheMeasuredOne) {
  SyntheticScene scene = hall(false);
  const EsdfMap& map = scene.finish();
  const SafetyCheck check({});
  const ExecTrajectory traj = straight();
  SafetyCheck::Odometry odom = onTrack(traj, 0.9);
  odom.position.y() += 0.5;  // within max_tracking_error_m
  EXPECT_EQ(check.check(1.0, {&traj}, odom, nullptr, map).action, Action::kNone);
  odom.position.y() += 0.3;  // 0.8 m off: a VIO jump
  const SafetyCheck::Verdict v = check.check(1.0, {&traj}, odom, nullptr, map);
  ASSERT_EQ(v.action, Action::kHoldAtMeasured);
  EXPECT_NE(v.why.find("odometry 0.80 m from the commanded position"), std::string::npos) << v.why;
  // From the measured state carried on to t with the measured velocity; no acceleration.
  EXPECT_TRUE(v.from.position.isApprox(odom.position + 0.1 * odom.velocity, 1e-9));
  EXPECT_TRUE(v.from.velocity.isApprox(odom.velocity));
  EXPECT_TRUE(v.from.acceleration.isZero());
  // Odometry stamped before the trajectory (or the one it replaced) started is not judged by it.
  const ExecTrajectory later = straight(2.0);
  EXPECT_EQ(check.check(2.0, {&later}, odom, nullptr, map).action, Action::kNone);
  // ... but with the one it replaced, by that one.
  EXPECT_EQ(check.check(2.0, {&later, &traj}, odom, nullptr, map).action, Action::kHoldAtMeasured);
}

TEST(SafetyCheck, ACollisionFarAheadIsReplannedANearOneBrakedFor) {
  SyntheticScene scene = hall(true);
  const EsdfMap& map = scene.finish();
  const ExecTrajectory traj = straight();
  SafetyCheck::Config config;
  const SafetyCheck check(config);
  // At t = 0 the pillar is 3.2 s ahead, the stop takes 3 / 2.5 + 0.3 + 0.1 = 1.6 s: replan.
  SafetyCheck::Verdict v = check.check(0.0, {&traj}, onTrack(traj, 0.0), nullptr, map);
  EXPECT_EQ(v.action, Action::kNone);
  EXPECT_TRUE(v.collision_ahead);
  // At t = 2 it is 1.2 s ahead: brake.
  v = check.check(2.0, {&traj}, onTrack(traj, 2.0), nullptr, map);
  EXPECT_EQ(v.action, Action::kBrake);
  EXPECT_TRUE(v.collision_ahead);
  EXPECT_EQ(v.why.rfind("collision in 1.", 0), 0u) << v.why;
  EXPECT_EQ(v.status, ReplanStatus::kOptimizationFailed);
  // With a back-up stop at 5 m/s^2 (1.0 s), the same collision is still the replan's business.
  config.collision_brake_acc_mps2 = 5.0;
  v = SafetyCheck(config).check(2.0, {&traj}, onTrack(traj, 2.0), nullptr, map);
  EXPECT_EQ(v.action, Action::kNone);
  EXPECT_TRUE(v.collision_ahead);
}

TEST(SafetyCheck, ATrajectoryThatEndsMovingIsBrakedForBeforeItRunsOut) {
  SyntheticScene scene = hall(false);
  const EsdfMap& map = scene.finish();
  const SafetyCheck check({});
  ExecTrajectory traj = straight();
  EXPECT_EQ(check.check(2.3, {&traj}, onTrack(traj, 2.3), nullptr, map).action, Action::kNone);  // 1.7 s left
  const SafetyCheck::Verdict v = check.check(2.5, {&traj}, onTrack(traj, 2.5), nullptr, map);   // 1.5 s left
  EXPECT_EQ(v.action, Action::kBrake);
  EXPECT_EQ(v.why.rfind("the trajectory ends moving in 1.5", 0), 0u) << v.why;
  // One that ends at the goal (at rest) does not run out.
  traj.ends_at_goal = true;
  EXPECT_EQ(check.check(2.5, {&traj}, onTrack(traj, 2.5), nullptr, map).action, Action::kNone);
}

TEST(SafetyCheck, ManoeuvresAndFinishedTrajectoriesAreNotChecked) {
  SyntheticScene scene = hall(true);
  const EsdfMap& map = scene.finish();
  const SafetyCheck check({});
  ExecTrajectory traj = straight();
  traj.escape = true;  // made and checked by manoeuvres.h
  SafetyCheck::Verdict v = check.check(2.0, {&traj}, onTrack(traj, 2.0), nullptr, map);
  EXPECT_EQ(v.action, Action::kNone);
  EXPECT_FALSE(v.collision_ahead);
  // ... but the odometry still is.
  SafetyCheck::Odometry odom = onTrack(traj, 2.0);
  odom.position.z() += 1.0;
  EXPECT_EQ(check.check(2.0, {&traj}, odom, nullptr, map).action, Action::kHoldAtMeasured);
  // A trajectory that ended, with no mission: done.
  traj.escape = false;
  SafetyCheck::Flown done{&traj};
  done.waiting = true;
  EXPECT_EQ(check.check(4.5, done, onTrack(traj, 4.5), nullptr, map).action, Action::kNone);
}

}  // namespace
}  // namespace topo_planner
