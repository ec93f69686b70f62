#include <gtest/gtest.h>

#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace topo_planner {
namespace {

TEST(MinimumSnap, SingleRestToRestSegmentIsTheKnownPolynomial) {
  PolynomialTrajectory traj;
  ASSERT_EQ(minimumSnapTrajectory({{0, 0, 0}, {1, 0, 0}}, {2.0}, FlatState::atRest({0, 0, 0}), FlatState::atRest({1, 0, 0}), &traj),
            TrajectoryStatus::kSuccess);
  for (double tau = 0.0; tau <= 1.0; tau += 0.05) {
    const double expected = 35 * std::pow(tau, 4) - 84 * std::pow(tau, 5) + 70 * std::pow(tau, 6) - 20 * std::pow(tau, 7);
    EXPECT_NEAR(traj.position(2.0 * tau).x(), expected, 1e-9);
    EXPECT_NEAR(traj.position(2.0 * tau).y(), 0.0, 1e-12);
  }
  EXPECT_NEAR(traj.duration(), 2.0, 1e-12);
  for (int r = 1; r <= 3; ++r) {
    EXPECT_LT(traj.derivative(0.0, r).norm(), 1e-9);
    EXPECT_LT(traj.derivative(2.0, r).norm(), 1e-9);
  }
}

TEST(MinimumSnap, ThroughWaypointsWithSmoothJoinsAndGivenEnds) {
  const std::vector<Eigen::Vector3d> w{{0, 0, 1}, {2, 1, 1.5}, {4, -1, 1}, {5, 2, 2}, {8, 2, 1}};
  const std::vector<double> T{1.5, 2.0, 1.2, 2.5};
  FlatState start = FlatState::atRest(w.front()), end = FlatState::atRest(w.back());
  start.velocity = {1.0, 0.5, 0.0};
  start.acceleration = {0.2, -0.3, 0.1};
  end.velocity = {0.5, 0.0, -0.2};
  PolynomialTrajectory traj;
  ASSERT_EQ(minimumSnapTrajectory(w, T, start, end, &traj), TrajectoryStatus::kSuccess);
  EXPECT_TRUE(traj.state(0.0).velocity.isApprox(start.velocity, 1e-9));
  EXPECT_TRUE(traj.state(0.0).acceleration.isApprox(start.acceleration, 1e-9));
  EXPECT_LT(traj.state(0.0).jerk.norm(), 1e-9);
  EXPECT_TRUE(traj.state(traj.duration()).velocity.isApprox(end.velocity, 1e-9));
  double t = 0.0;
  for (size_t i = 0; i < w.size(); ++i) {
    EXPECT_LT((traj.position(t) - w[i]).norm(), 1e-9) << "waypoint " << i;
    if (i > 0 && i + 1 < w.size()) {
      // Derivatives up to snap agree on both sides of an inner waypoint: position to jerk by
      // construction, snap only at the optimum (its stationarity condition).
      for (int r = 0; r <= 4; ++r) {
        const Eigen::Vector3d left = traj.derivative(t - 1e-7, r), right = traj.derivative(t + 1e-7, r);
        EXPECT_LT((left - right).norm(), 1e-4 * std::max(1.0, left.norm())) << "order " << r << " at " << i;
      }
    }
    if (i < T.size()) t += T[i];
  }
  EXPECT_GT(traj.snapCost(), 0.0);
}

TEST(MinimumSnap, OptimumBeatsOtherJoins) {
  // The same waypoints and times with the inner derivatives forced by splitting into independent
  // rest-to-rest pieces cost more snap than the joint optimum.
  const std::vector<Eigen::Vector3d> w{{0, 0, 1}, {2, 1, 1}, {4, 0, 1}};
  PolynomialTrajectory joint, first, second;
  ASSERT_EQ(minimumSnapTrajectory(w, {1.5, 1.5}, FlatState::atRest(w[0]), FlatState::atRest(w[2]), &joint), TrajectoryStatus::kSuccess);
  ASSERT_EQ(minimumSnapTrajectory({w[0], w[1]}, {1.5}, FlatState::atRest(w[0]), FlatState::atRest(w[1]), &first), TrajectoryStatus::kSuccess);
  ASSERT_EQ(minimumSnapTrajectory({w[1], w[2]}, {1.5}, FlatState::atRest(w[1]), FlatState::atRest(w[2]), &second), TrajectoryStatus::kSuccess);
  EXPECT_LT(joint.snapCost(), first.snapCost() + second.snapCost());
}

TEST(ReferenceTrajectory, RespectsTheLimits) {
  const std::vector<Eigen::Vector3d> w{{0, 0, 1}, {10, 0, 1}, {10, 8, 2}, {0, 8, 1}};
  for (double vmax : {1.0, 3.0, 6.0}) {
    ReferenceConfig c;
    c.max_vel_mps = vmax;
    c.max_acc_mps2 = 2.5;
    PolynomialTrajectory traj;
    ASSERT_EQ(referenceTrajectory(w, FlatState::atRest(w.front()), FlatState::atRest(w.back()), c, &traj), TrajectoryStatus::kSuccess);
    EXPECT_LE(traj.maxSpeed(), vmax * (1 + 1e-6));
    EXPECT_LE(traj.maxAcceleration(), 2.5 * (1 + 1e-6));
    EXPECT_GT(traj.maxSpeed(), 0.5 * std::min(vmax, 3.0));  // and not needlessly slow
    EXPECT_LT((traj.position(traj.duration()) - w.back()).norm(), 1e-9);
  }
  // A moving start (replanning from flight).
  FlatState moving = FlatState::atRest({0, 0, 1});
  moving.velocity = {2.0, 0.0, 0.0};
  PolynomialTrajectory traj;
  ASSERT_EQ(referenceTrajectory({{0, 0, 1}, {6, 3, 1}}, moving, FlatState::atRest({6, 3, 1}), ReferenceConfig(), &traj),
            TrajectoryStatus::kSuccess);
  EXPECT_TRUE(traj.velocity(0.0).isApprox(moving.velocity, 1e-9));
  EXPECT_LE(traj.maxSpeed(), 3.0 * (1 + 1e-6));
}

TEST(ReferenceTrajectory, InvalidInputs) {
  PolynomialTrajectory traj;
  EXPECT_EQ(minimumSnapTrajectory({{0, 0, 0}}, {}, FlatState::atRest({0, 0, 0}), FlatState::atRest({0, 0, 0}), &traj), TrajectoryStatus::kInvalidInput);
  EXPECT_EQ(minimumSnapTrajectory({{0, 0, 0}, {1, 0, 0}}, {0.0}, FlatState::atRest({0, 0, 0}), FlatState::atRest({1, 0, 0}), &traj),
            TrajectoryStatus::kInvalidInput);
  EXPECT_EQ(minimumSnapTrajectory({{0, 0, 0}, {1, 0, 0}}, {1.0, 1.0}, FlatState::atRest({0, 0, 0}), FlatState::atRest({1, 0, 0}), &traj),
            TrajectoryStatus::kInvalidInput);
  EXPECT_EQ(minimumSnapTrajectory({{0, 0, 0}, {NAN, 0, 0}}, {1.0}, FlatState::atRest({0, 0, 0}), FlatState::atRest({1, 0, 0}), &traj),
            TrajectoryStatus::kInvalidInput);
  FlatState bad = FlatState::atRest({0, 0, 0});
  bad.velocity.x() = INFINITY;
  EXPECT_EQ(minimumSnapTrajectory({{0, 0, 0}, {1, 0, 0}}, {1.0}, bad, FlatState::atRest({1, 0, 0}), &traj), TrajectoryStatus::kInvalidInput);
  ReferenceConfig c;
  c.max_vel_mps = 0.0;
  EXPECT_EQ(referenceTrajectory({{0, 0, 0}, {1, 0, 0}}, FlatState::atRest({0, 0, 0}), FlatState::atRest({1, 0, 0}), c, &traj), TrajectoryStatus::kInvalidInput);
  EXPECT_TRUE(PolynomialTrajectory().derivative(1.0, 0).isZero());
}

// A vehicle braking harder than the reference's limit: the fixed start acceleration cannot be
// stretched away, and must not make the time scaling run away (it did: 2^30 longer, then a hang).
TEST(ReferenceTrajectory, StartBeyondTheLimitsTerminates) {
  FlatState start = FlatState::atRest({0, 0, 1});
  start.velocity = Eigen::Vector3d(0.8, 0, 0);
  start.acceleration = Eigen::Vector3d(-2.4, 0, 0);
  ReferenceConfig config;
  config.max_vel_mps = 2.25;
  config.max_acc_mps2 = 1.875;
  config.max_segment_length_m = 3.0;
  config.cruise_timing = true;
  PolynomialTrajectory ref;
  ASSERT_EQ(referenceTrajectory({start.position, {30, -9, 1}}, start, FlatState::atRest({30, -9, 1}), config, &ref),
            TrajectoryStatus::kSuccess);
  EXPECT_LT(ref.duration(), 60.0);
  EXPECT_LE(ref.maxAcceleration(), 2.4 * (1 + 1e-6));
}

}  // namespace
}  // namespace topo_planner
