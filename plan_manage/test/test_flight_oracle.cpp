#include "topo_planner/plan_manage/flight_oracle.h"

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

FlightOracle::Config limits(double v, double a) {
  FlightOracle::Config c;
  c.max_vel_mps = v;
  c.max_acc_mps2 = a;
  c.min_z_m = 0.2;
  c.max_z_m = 2.8;
  return c;
}

// Rest to rest along a straight free line of length d at (v, a): the trapezoid (or the triangle).
double trapezoid(double d, double v, double a) {
  return d >= v * v / a ? d / v + v / a : 2.0 * std::sqrt(d / a);
}

TEST(FlightOracle, AnEmptyHallIsTheStraightLineAtTheLimits) {
  SyntheticScene scene(Eigen::Vector3d(24.0, 10.0, 3.0));
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d start(2, 5, 1.5), goal(22, 5, 1.5);
  const FlightOracle::Result r = FlightOracle::compute(map, start, {goal}, limits(3.0, 2.5));
  ASSERT_TRUE(r.ok) << r.why;
  ASSERT_EQ(r.time_s.size(), 1u);
  EXPECT_NEAR(r.length_m[0], 20.0, 0.05);
  EXPECT_NEAR(r.time_s[0], trapezoid(20.0, 3.0, 2.5), 0.05);
  // Faster limits, less time; the legs add up (the way back stops at the start again).
  const FlightOracle::Result fast = FlightOracle::compute(map, start, {goal, start}, limits(5.0, 2.5));
  ASSERT_TRUE(fast.ok) << fast.why;
  ASSERT_EQ(fast.time_s.size(), 2u);
  EXPECT_NEAR(fast.time_s[0], trapezoid(20.0, 5.0, 2.5), 0.05);
  EXPECT_NEAR(fast.total_s, fast.time_s[0] + fast.time_s[1], 1e-9);
  EXPECT_NEAR(fast.time_s[0], fast.time_s[1], 0.05);
  // Flown as waypoints of one mission: it does not stop at the first goal.
  FlightOracle::Config through = limits(5.0, 2.5);
  through.pass_through = true;
  const FlightOracle::Result once = FlightOracle::compute(map, start, {Eigen::Vector3d(12, 5, 1.5), goal}, through);
  ASSERT_TRUE(once.ok) << once.why;
  ASSERT_EQ(once.time_s.size(), 2u);
  EXPECT_NEAR(once.total_s, fast.time_s[0], 0.05);
}

TEST(FlightOracle, AWallIsFlownRoundThroughItsWindow) {
  // A wall at x = 12 with a 1 m window 4 m aside: the way is longer than the line and has corners.
  SyntheticScene scene(Eigen::Vector3d(24.0, 16.0, 3.0));
  scene.fill([](const Eigen::Vector3d& p) {
    return p.x() >= 11.9 && p.x() <= 12.1 && !(std::abs(p.y() - 12.0) <= 0.5 && std::abs(p.z() - 1.5) <= 0.5);
  });
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d start(2, 8, 1.5), goal(22, 8, 1.5), window(12, 12, 1.5);
  const FlightOracle::Result r = FlightOracle::compute(map, start, {goal}, limits(3.0, 2.5));
  ASSERT_TRUE(r.ok) << r.why;
  const double through_window = (window - start).norm() + (goal - window).norm();
  EXPECT_GT(r.length_m[0], 0.97 * through_window);  // the arcs cut the corners a little
  EXPECT_LT(r.length_m[0], 1.1 * through_window);
  EXPECT_GT(r.time_s[0], trapezoid(r.length_m[0], 3.0, 2.5));  // it slows for the turns
  // The route keeps the clearance (checked at voxel centres by the shortening: within half a voxel
  // of it when interpolated, on a shortcut that grazes the window's edge).
  for (const Eigen::Vector3d& p : resamplePath(r.routes[0], 0.05))
    if ((p - start).norm() > 0.6 && (p - goal).norm() > 0.6) EXPECT_GE(map.query(p).distance, 0.3 - 0.05);
}

TEST(FlightOracle, SaysWhyWhenThereIsNoWay) {
  SyntheticScene scene(Eigen::Vector3d(24.0, 16.0, 3.0));
  scene.fill([](const Eigen::Vector3d& p) { return p.x() >= 11.9 && p.x() <= 12.1; });  // closed
  const EsdfMap& map = scene.finish();
  FlightOracle::Result r = FlightOracle::compute(map, Eigen::Vector3d(2, 8, 1.5), {Eigen::Vector3d(22, 8, 1.5)}, limits(3, 2.5));
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.why.find("no route to goal 1"), std::string::npos) << r.why;
  r = FlightOracle::compute(map, Eigen::Vector3d(2, 8, 1.5), {}, limits(3, 2.5));
  EXPECT_FALSE(r.ok);
  r = FlightOracle::compute(map, Eigen::Vector3d(2, 8, 1.5), {Eigen::Vector3d(4, 8, 1.5)}, limits(0.0, 2.5));
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.why.find("max_vel_mps"), std::string::npos) << r.why;
}

}  // namespace
}  // namespace topo_planner
