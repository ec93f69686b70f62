#include "topo_planner/topo_replan/path_speed_profile.h"

#include <gtest/gtest.h>

#include <cmath>

namespace topo_planner {
namespace {

PathSpeedProfile::Config limits(double v, double a) {
  PathSpeedProfile::Config c;
  c.max_vel_mps = v;
  c.max_acc_mps2 = a;
  c.step_m = 0.01;
  return c;
}

TEST(PathSpeedProfile, StraightLineIsTheTrapezoid) {
  // 10 m at 3 m/s and 2.5 m/s^2, rest to rest: 1.8 m to accelerate, 1.8 m to brake, 6.4 m cruise.
  const auto p = PathSpeedProfile::compute({Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(10, 0, 1)}, limits(3.0, 2.5));
  ASSERT_TRUE(p);
  EXPECT_NEAR(p->length(), 10.0, 1e-9);
  EXPECT_NEAR(p->duration(), 2.0 * 3.0 / 2.5 + 6.4 / 3.0, 0.01);
  EXPECT_NEAR(p->maxSpeed(), 3.0, 1e-9);
  EXPECT_NEAR(p->speedAt(5.0), 3.0, 1e-9);
  EXPECT_NEAR(p->speedAt(0.9), std::sqrt(2.0 * 2.5 * 0.9), 0.01);
}

TEST(PathSpeedProfile, ShortLineIsTheTriangle) {
  const auto p = PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(2, 0, 0)}, limits(3.0, 2.5));
  ASSERT_TRUE(p);
  EXPECT_NEAR(p->duration(), 2.0 * std::sqrt(2.0 / 2.5), 0.01);
  EXPECT_NEAR(p->maxSpeed(), std::sqrt(2.5 * 2.0), 0.01);
}

TEST(PathSpeedProfile, MovingEndsKeepTheirSpeeds) {
  // Cruise at the limit from end to end: dist / v.
  const auto p = PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 6, 0)}, limits(3.0, 2.5), 3.0, 3.0);
  ASSERT_TRUE(p);
  EXPECT_NEAR(p->duration(), 2.0, 1e-6);
  // A start above the limit is clamped to it.
  const auto q = PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 6, 0)}, limits(3.0, 2.5), 9.0, 3.0);
  ASSERT_TRUE(q);
  EXPECT_NEAR(q->duration(), 2.0, 1e-6);
}

// Every step of the profile keeps the limits: the speed, the normal acceleration on the corner's arc,
// and the tangential acceleration left over (checked by finite differences along the samples).
TEST(PathSpeedProfile, ACornerIsFlownOnAnArcWithinTheLimits) {
  const double v = 3.0, a = 2.5;
  // A right angle between 1 m legs: tangent 0.5 m, radius 0.5 m, at most sqrt(a r) = 1.118 m/s on it.
  const std::vector<Eigen::Vector3d> w{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(1, 1, 0)};
  const auto p = PathSpeedProfile::compute(w, limits(v, a));
  ASSERT_TRUE(p);
  const double r = 0.5, arc = r * M_PI / 2.0;
  EXPECT_NEAR(p->length(), 0.5 + arc + 0.5, 1e-9);
  EXPECT_NEAR(p->speedAt(0.5 + 0.5 * arc), std::sqrt(a * r), 0.01);
  // Finite differences: |dv^2 / 2ds| within the tangential acceleration left at the higher speed.
  const std::vector<double>& grid = p->sampleDistances();
  for (size_t i = 0; i + 1 < grid.size(); ++i) {
    const double s = grid[i], ds = grid[i + 1] - grid[i];
    ASSERT_GT(ds, 0.0);
    const double v0 = p->speedAt(s), v1 = p->speedAt(s + ds);
    EXPECT_LE(std::max(v0, v1), v + 1e-9);
    const bool on_arc = s >= 0.5 - 1e-9 && s + ds <= 0.5 + arc + 1e-9;
    const double normal = on_arc ? std::max(v0, v1) * std::max(v0, v1) / r : 0.0;
    EXPECT_LE(normal, a * 1.001) << "s " << s;
    const double tangential = std::abs(v1 * v1 - v0 * v0) / (2.0 * ds);
    EXPECT_LE(tangential, a * 1.001) << "s " << s;
  }
  // Waypoint times: 0, the middle of the arc, the end.
  ASSERT_EQ(p->waypointTimes().size(), 3u);
  EXPECT_EQ(p->waypointTimes()[0], 0.0);
  EXPECT_NEAR(p->waypointTimes()[1], p->duration() / 2.0, 0.01);  // symmetric
  EXPECT_EQ(p->waypointTimes()[2], p->duration());
  // Slower than the straight line of the same length, which needs no turn.
  const auto straight = PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(p->length(), 0, 0)}, limits(v, a));
  ASSERT_TRUE(straight);
  EXPECT_GT(p->duration(), straight->duration() + 0.05);
}

TEST(PathSpeedProfile, AGentleBendOnLongLegsNeedsNoSlowing) {
  // 10 m legs, 20 degrees: radius 5 / tan(10 deg) = 28 m, sqrt(a r) = 8.4 m/s, above the limit.
  const double turn = 20.0 * M_PI / 180.0;
  const std::vector<Eigen::Vector3d> w{Eigen::Vector3d::Zero(), Eigen::Vector3d(10, 0, 0),
                                       Eigen::Vector3d(10 + 10 * std::cos(turn), 10 * std::sin(turn), 0)};
  const auto p = PathSpeedProfile::compute(w, limits(3.0, 2.5));
  ASSERT_TRUE(p);
  EXPECT_NEAR(p->speedAt(p->length() / 2.0), 3.0, 1e-9);
}

TEST(PathSpeedProfile, AReversalStopsWhereItTurns) {
  const std::vector<Eigen::Vector3d> w{Eigen::Vector3d::Zero(), Eigen::Vector3d(5, 0, 0), Eigen::Vector3d(0, 0, 0)};
  const auto p = PathSpeedProfile::compute(w, limits(3.0, 2.5));
  ASSERT_TRUE(p);
  EXPECT_NEAR(p->length(), 10.0, 1e-9);
  EXPECT_LT(p->speedAt(5.0), 0.06);
  // Two rest-to-rest legs of 5 m.
  const auto leg = PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(5, 0, 0)}, limits(3.0, 2.5));
  ASSERT_TRUE(leg);
  EXPECT_NEAR(p->duration(), 2.0 * leg->duration(), 0.02);
}

TEST(PathSpeedProfile, RefusesBadInput) {
  std::string why;
  EXPECT_FALSE(PathSpeedProfile::compute({Eigen::Vector3d::Zero()}, limits(3, 2.5), 0, 0, &why));
  EXPECT_NE(why.find("two"), std::string::npos);
  EXPECT_FALSE(PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()}, limits(3, 2.5)));
  EXPECT_FALSE(PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(NAN, 0, 0)}, limits(3, 2.5)));
  EXPECT_FALSE(PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 0, 0)}, limits(0.0, 2.5)));
  EXPECT_FALSE(PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 0, 0)}, limits(3, 2.5), NAN));
  PathSpeedProfile::Config tiny = limits(3, 2.5);
  tiny.max_samples = 10;
  EXPECT_FALSE(PathSpeedProfile::compute({Eigen::Vector3d::Zero(), Eigen::Vector3d(100, 0, 0)}, tiny, 0, 0, &why));
  EXPECT_NE(why.find("max_samples"), std::string::npos);
}

}  // namespace
}  // namespace topo_planner
