#include <gtest/gtest.h>

#include <cstdio>

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

// Profile timing: the reference keeps the limits and, on a route with corners, flies its straight
// parts faster than with the segments stretched all alike.
TEST(ReferenceTrajectory, ProfileTimingStretchesOnlyWhereTheLimitsAreBroken) {
  // A route with a sharp corner in the middle of long straight legs.
  const std::vector<Eigen::Vector3d> w{{0, 0, 1}, {12, 0, 1}, {12.5, 1.5, 1}, {24, 2, 1}};
  ReferenceConfig uniform;
  uniform.max_vel_mps = 5.0;
  uniform.max_acc_mps2 = 2.5;
  uniform.max_segment_length_m = 3.0;
  uniform.cruise_timing = true;
  ReferenceConfig profile = uniform;
  profile.profile_timing = true;
  PolynomialTrajectory a, b;
  ASSERT_EQ(referenceTrajectory(w, FlatState::atRest(w.front()), FlatState::atRest(w.back()), uniform, &a), TrajectoryStatus::kSuccess);
  ASSERT_EQ(referenceTrajectory(w, FlatState::atRest(w.front()), FlatState::atRest(w.back()), profile, &b), TrajectoryStatus::kSuccess);
  for (const PolynomialTrajectory* t : {&a, &b}) {
    EXPECT_LE(t->maxSpeed(), 5.0 * (1 + 1e-6));
    EXPECT_LE(t->maxAcceleration(), 2.5 * (1 + 1e-6));
  }
  EXPECT_LT(b.duration(), a.duration()) << "profile " << b.duration() << " s, uniform " << a.duration() << " s";
  EXPECT_GT(b.maxSpeed(), 4.0);
}

// A closed-loop flight at 5 m/s rebuilt this reference at rest: the segments stretched one by one
// pushed the excess into their neighbours and the stretching ran away (2e12 s for 30 m; every loop
// of the replanner over it then hung). Now it is a few times the profile's time, or refused.
TEST(ReferenceTrajectory, ProfileTimingDoesNotRunAway) {
  const std::vector<Eigen::Vector3d> w{{3.56039, 3.22677, 0.641217}, {0.998316, 2.83141, 0.642974}, {-1.56376, 2.43606, 0.64473},
                                       {-4.12584, 2.04071, 0.646487}, {-6.68792, 1.64535, 0.648243}, {-9.25, 1.25, 0.65},
                                       {-11.15, 1.75, 0.65}, {-13.075, 0.835, 0.95}, {-15, -0.08, 1.25}};
  ReferenceConfig c;
  c.max_vel_mps = 5.0;
  c.max_acc_mps2 = 2.5;
  c.profile_timing = true;
  PolynomialTrajectory ref;
  ASSERT_EQ(referenceTrajectory(w, FlatState::atRest(w.front()), FlatState::atRest(w.back()), c, &ref), TrajectoryStatus::kSuccess);
  EXPECT_LT(ref.duration(), 20.0);
  EXPECT_LE(ref.maxAcceleration(), 2.5 * (1 + 1e-6));
  // From a moving start against the way (a goal behind the vehicle): still bounded.
  FlatState back = FlatState::atRest(w.front());
  back.velocity = Eigen::Vector3d(1.5, 0.3, 0.0);
  const TrajectoryStatus s = referenceTrajectory(w, back, FlatState::atRest(w.back()), c, &ref);
  if (s == TrajectoryStatus::kSuccess) {
    EXPECT_LT(ref.duration(), kMaxReferenceStretch * 20.0 + 10.0);
  } else {
    EXPECT_EQ(s, TrajectoryStatus::kInfeasible);
  }
}

// The state a reference starts in: the vehicle's along the first leg; across or against it, only the
// velocity's component along the leg and no acceleration.
TEST(ReferenceStartState, KeepsAStateAlongTheLegAndOnlyTheComponentAlongItOtherwise) {
  FlatState v = FlatState::atRest({0, 0, 1});
  v.velocity = Eigen::Vector3d(2.0, 0.3, 0.0);  // 8.5 degrees off the leg
  v.acceleration = Eigen::Vector3d(0.5, -0.2, 0.0);
  const Eigen::Vector3d leg(10, 0, 0);
  FlatState s = referenceStartState(v, leg);
  EXPECT_TRUE(s.velocity.isApprox(v.velocity));
  EXPECT_TRUE(s.acceleration.isApprox(v.acceleration));
  v.velocity = Eigen::Vector3d(1.0, 1.5, 0.0);  // across
  s = referenceStartState(v, leg);
  EXPECT_TRUE(s.velocity.isApprox(Eigen::Vector3d(1.0, 0.0, 0.0)));
  EXPECT_TRUE(s.acceleration.isZero());
  EXPECT_TRUE(s.position.isApprox(v.position));
  v.velocity = Eigen::Vector3d(-1.7, 0.5, 0.0);  // away
  EXPECT_TRUE(referenceStartState(v, leg).velocity.isZero());
  EXPECT_TRUE(referenceStartState(v, Eigen::Vector3d::Zero()).velocity.isApprox(v.velocity));  // no leg: as it is
}

// A re-route while flying away from the new route's first leg (mixed world, seed 2, max_vel 3): a
// reference from the vehicle's velocity looped out and back over seconds, and the plans, aimed at
// the loop's start while the vehicle turned elsewhere, chased it in place for 22 s. From the start
// state above the reference leads along the route at once and is no slower.
TEST(ReferenceTrajectory, FromAVehicleMovingAwayItLeadsAlongTheRoute) {
  const std::vector<Eigen::Vector3d> w{{0, 0, 1}, {6, 0, 1}, {12, 3, 1}};
  ReferenceConfig c;
  c.max_vel_mps = 3.0;
  c.max_acc_mps2 = 2.5;
  c.max_segment_length_m = 3.0;
  c.profile_timing = true;
  FlatState vehicle = FlatState::atRest(w.front());
  vehicle.velocity = Eigen::Vector3d(-1.7, 0.5, 0.0);
  vehicle.acceleration = Eigen::Vector3d(0.0, 0.8, 0.0);
  auto backwards = [](const PolynomialTrajectory& ref) {  // how far it goes back against the first leg [m]
    double least_x = 0.0;
    for (double t = 0.0; t <= ref.duration(); t += 0.01) least_x = std::min(least_x, ref.position(t).x());
    return -least_x;
  };
  PolynomialTrajectory raw, from_rest, led;
  ASSERT_EQ(referenceTrajectory(w, vehicle, FlatState::atRest(w.back()), c, &raw), TrajectoryStatus::kSuccess);
  ASSERT_EQ(referenceTrajectory(w, FlatState::atRest(w.front()), FlatState::atRest(w.back()), c, &from_rest),
            TrajectoryStatus::kSuccess);
  ASSERT_EQ(referenceTrajectory(w, referenceStartState(vehicle, w[1] - w[0]), FlatState::atRest(w.back()), c, &led),
            TrajectoryStatus::kSuccess);
  EXPECT_GT(backwards(raw), 0.2) << "the velocity's loop";
  EXPECT_LT(backwards(led), 1e-6);
  EXPECT_LE(led.duration(), from_rest.duration() + 1e-6);
  std::printf("reference from a vehicle moving away: %.2f s, %.2f m back; led along the route: %.2f s\n", raw.duration(),
              backwards(raw), led.duration());
}


// The bound a plan's local goal gets at an intermediate goal: the closest approach of the first pass
// within the radius. A route that comes back by the same waypoint (out and back along a corridor)
// is bounded at the first pass, not at the later one, even when the later one passes closer.
TEST(WaypointPassTime, TheClosestPointOfTheFirstPassWithinTheRadius) {
  // Out along y = 0, past (4, 0.5, 1) at 0.5 m, and back along y = 0.8, past it at 0.3 m.
  const std::vector<Eigen::Vector3d> w{{0, 0, 1}, {8, 0, 1}, {8, 0.8, 1}, {0, 0.8, 1}};
  ReferenceConfig c;
  c.max_vel_mps = 2.0;
  c.max_segment_length_m = 1.0;  // as the FSM's references: close to the route's legs
  PolynomialTrajectory ref;
  ASSERT_EQ(referenceTrajectory(w, FlatState::atRest(w.front()), FlatState::atRest(w.back()), c, &ref),
            TrajectoryStatus::kSuccess);
  const Eigen::Vector3d wp(4, 0.5, 1);
  const double t = waypointPassTime(ref, wp, 0.0, 0.6);
  ASSERT_TRUE(std::isfinite(t));
  EXPECT_NEAR(ref.position(t).x(), 4.0, 0.2);
  EXPECT_LT(t, 0.5 * ref.duration());  // the way out
  // Sampled closest point of that pass: no sample of the pass is closer.
  for (double s = 0.0; s < 0.5 * ref.duration(); s += 0.01)
    EXPECT_GE((ref.position(s) - wp).norm(), (ref.position(t) - wp).norm() - 0.01);
  // Past the first pass, the way back.
  const double t_back = waypointPassTime(ref, wp, 0.5 * ref.duration(), 0.6);
  ASSERT_TRUE(std::isfinite(t_back));
  EXPECT_GT(t_back, 0.5 * ref.duration());
  EXPECT_NEAR(ref.position(t_back).x(), 4.0, 0.3);
  EXPECT_LT((ref.position(t_back) - wp).norm(), (ref.position(t) - wp).norm());  // closer, yet second
  // Never within the radius, or about there already: no bound.
  EXPECT_TRUE(std::isnan(waypointPassTime(ref, {4, 5, 1}, 0.0, 0.6)));
  double t_near = 0.0;
  while ((ref.position(t_near) - wp).norm() > 0.59) t_near += 0.01;
  EXPECT_TRUE(std::isnan(waypointPassTime(ref, wp, t_near, 0.6)));
  // Bad input.
  EXPECT_TRUE(std::isnan(waypointPassTime(ref, {NAN, 0, 1}, 0.0, 0.6)));
  EXPECT_TRUE(std::isnan(waypointPassTime(ref, wp, NAN, 0.6)));
  EXPECT_TRUE(std::isnan(waypointPassTime(ref, wp, 0.0, -1.0)));
  EXPECT_TRUE(std::isnan(waypointPassTime(PolynomialTrajectory(), wp, 0.0, 0.6)));
}

}  // namespace
}  // namespace topo_planner
