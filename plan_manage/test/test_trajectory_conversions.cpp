// The B-spline message's checks at the edge (fromMsg): a spline the planner would send round-trips,
// spans and coordinates whose derivatives overflow are refused with a reason.
#include <gtest/gtest.h>

#include <string>

#include "topo_planner/plan_manage/trajectory_conversions.h"

namespace topo_planner {
namespace {

Bspline straightMsg(double knot_span_s, double far_m = 0.0) {
  Bspline msg;
  msg.order = 3;
  msg.knot_span_s = knot_span_s;
  for (int i = 0; i < 8; ++i) {
    geometry_msgs::Point p;
    p.x = 0.2 * i + far_m;
    p.z = 1.0;
    msg.control_points.push_back(p);
  }
  return msg;
}

TEST(TrajectoryConversions, PlannerSplineIsAccepted) {
  ReceivedTrajectory r;
  std::string why;
  ASSERT_TRUE(fromMsg(straightMsg(0.1), &r, &why)) << why;
  EXPECT_NEAR(r.spline.duration(), 0.5, 1e-12);
  EXPECT_TRUE(r.spline.evaluate(0.25).allFinite());
}

// What the flight monitor's speed account reads: the kind and where the committed stop begins.
TEST(TrajectoryConversions, KindAndBrakeStartRoundTrip) {
  ExecTrajectory t;
  t.id = 4;
  t.start_time_s = 100.0;
  t.spline = UniformBspline::straightLine(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(2, 0, 1), 8, 3, 0.2);
  t.brake_start_s = 100.4;  // cut: stops before unknown space from 0.4 s on
  ReceivedTrajectory r;
  std::string why;
  ASSERT_TRUE(fromMsg(toMsg(t, "world", 9), &r, &why)) << why;
  EXPECT_EQ(r.kind, Bspline::KIND_PLAN);
  EXPECT_NEAR(r.brake_start_s, 100.4, 1e-6);
  t.braking = true;
  t.brake_start_s = 1e9;  // past the end: the end
  ASSERT_TRUE(fromMsg(toMsg(t, "world", 9), &r, &why)) << why;
  EXPECT_EQ(r.kind, Bspline::KIND_BRAKING);
  EXPECT_NEAR(r.brake_start_s, t.endTime(), 1e-6);
  t.braking = false;
  t.escape = true;
  ASSERT_TRUE(fromMsg(toMsg(t, "world", 9), &r, &why)) << why;
  EXPECT_EQ(r.kind, Bspline::KIND_MANOEUVRE);
  // A foreign kind is a plan; a brake point before the start is the start.
  Bspline msg = toMsg(t, "world", 9);
  msg.kind = 200;
  msg.brake_start = ros::Time(50.0);
  ASSERT_TRUE(fromMsg(msg, &r, &why)) << why;
  EXPECT_EQ(r.kind, Bspline::KIND_PLAN);
  EXPECT_NEAR(r.brake_start_s, 100.0, 1e-6);
}

// The trajectory_msgs fuzz harness: a knot span of 1.4e-156 s passed isValid(), and the setpoint
// generator sampled non-finite states from it.
TEST(TrajectoryConversions, KnotSpansAndCoordinatesBeyondTheBoundsAreRefused) {
  for (const double span : {1.4e-156, 0.999 * kMinKnotSpanS, 1.001 * kMaxKnotSpanS}) {
    ReceivedTrajectory r;
    std::string why;
    EXPECT_FALSE(fromMsg(straightMsg(span), &r, &why)) << span;
    EXPECT_NE(why.find("knot span"), std::string::npos) << why;
  }
  ReceivedTrajectory r;
  std::string why;
  EXPECT_TRUE(fromMsg(straightMsg(kMinKnotSpanS), &r, &why)) << why;
  EXPECT_TRUE(fromMsg(straightMsg(kMaxKnotSpanS), &r, &why)) << why;
  EXPECT_FALSE(fromMsg(straightMsg(0.1, 2.0 * kMaxCoordinateM), &r, &why));
  EXPECT_NE(why.find("control points beyond"), std::string::npos) << why;
}

}  // namespace
}  // namespace topo_planner
