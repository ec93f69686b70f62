// The trajectory server's core: take-over at the start time, hold at the end, and the yaw policy.
#include <gtest/gtest.h>

#include <cmath>

#include "topo_replan/setpoint_generator.h"

namespace topo_planner {
namespace {

UniformBspline line(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return UniformBspline::straightLine(a, b, 12, 3, 0.5);
}

TEST(SetpointGenerator, NothingBeforeTheFirstTrajectoryStarts) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  Setpoint sp;
  EXPECT_FALSE(gen.sample(0.0, &sp));
  ASSERT_TRUE(gen.add(0, 1.0, line({0, 0, 1}, {5, 0, 1})));
  EXPECT_FALSE(gen.sample(0.5, &sp));
  EXPECT_TRUE(gen.sample(1.0, &sp));
  EXPECT_EQ(sp.trajectory_id, 0);
  EXPECT_LT((sp.state.position - Eigen::Vector3d(0, 0, 1)).norm(), 1e-9);
}

TEST(SetpointGenerator, RefusesStaleOrInvalidTrajectories) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  ASSERT_TRUE(gen.add(3, 0.0, line({0, 0, 1}, {5, 0, 1})));
  EXPECT_FALSE(gen.add(3, 1.0, line({0, 0, 1}, {5, 0, 1})));  // not newer
  EXPECT_FALSE(gen.add(4, NAN, line({0, 0, 1}, {5, 0, 1})));
  Eigen::MatrixX3d bad = line({0, 0, 1}, {5, 0, 1}).controlPoints();
  bad(2, 0) = NAN;
  EXPECT_FALSE(gen.add(5, 1.0, UniformBspline(bad, 3, 0.5)));
}

TEST(SetpointGenerator, TakesOverAtTheStartTimeAndHoldsTheEnd) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = line({0, 0, 1}, {5, 0, 1});
  ASSERT_TRUE(gen.add(0, 0.0, a));
  // The second starts at t = 2 from where the first is then, heading to y = 3.
  const Eigen::Vector3d p2 = a.evaluate(2.0);
  ASSERT_TRUE(gen.add(1, 2.0, line(p2, p2 + Eigen::Vector3d(0, 3, 0))));
  Setpoint sp;
  ASSERT_TRUE(gen.sample(1.99, &sp));
  EXPECT_EQ(sp.trajectory_id, 0);
  ASSERT_TRUE(gen.sample(2.0, &sp));
  EXPECT_EQ(sp.trajectory_id, 1);
  EXPECT_LT((sp.state.position - p2).norm(), 1e-9);
  ASSERT_TRUE(gen.sample(100.0, &sp));
  EXPECT_TRUE(sp.holding);
  EXPECT_LT((sp.state.position - (p2 + Eigen::Vector3d(0, 3, 0))).norm(), 1e-9);
  EXPECT_EQ(sp.state.velocity.norm(), 0.0);
}

TEST(SetpointGenerator, YawFollowsTheDirectionOfTravelAtALimitedRate) {
  SetpointGenerator::Config config;
  config.max_yaw_rate_radps = 1.0;
  SetpointGenerator gen(config);
  gen.setYaw(0.0);
  ASSERT_TRUE(gen.add(0, 0.0, line({0, 0, 1}, {0, 6, 1})));  // along +y: yaw pi/2
  Setpoint sp;
  double previous = 0.0, max_rate = 0.0;
  for (int k = 0; k <= 300; ++k) {
    ASSERT_TRUE(gen.sample(k * 0.01, &sp));
    max_rate = std::max(max_rate, std::abs(sp.yaw - previous) / 0.01);
    previous = sp.yaw;
  }
  EXPECT_LE(max_rate, 1.0 + 1e-9);
  EXPECT_NEAR(sp.yaw, M_PI / 2, 1e-6);  // reached after pi/2 s
  EXPECT_NEAR(sp.yaw_rate, 0.0, 1e-9);
}

TEST(SetpointGenerator, YawTakesTheShortWayRound) {
  SetpointGenerator::Config config;
  config.max_yaw_rate_radps = 10.0;
  SetpointGenerator gen(config);
  gen.setYaw(3.0);  // near +pi; travel along -x -0.1 y: yaw near -pi
  ASSERT_TRUE(gen.add(0, 0.0, line({0, 0, 1}, {-6, -0.6, 1})));
  Setpoint sp;
  ASSERT_TRUE(gen.sample(0.0, &sp));
  ASSERT_TRUE(gen.sample(0.01, &sp));
  EXPECT_GT(sp.yaw_rate, 0.0);  // increasing through pi, not turning back through 0
}

}  // namespace
}  // namespace topo_planner
