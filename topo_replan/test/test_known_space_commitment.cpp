// The known-space commitment on its own: a plan is cut to a stop before unknown space, the stop
// stays in the observed free space at its deceleration, a harder back-up deceleration lets the plan
// be flown further, the anchor and the height band.
#include "topo_planner/topo_replan/known_space_commitment.h"

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

// A 20 x 6 x 3 m hall, free and observed up to x = known_until, unknown beyond.
SyntheticScene hall(double known_until) {
  SyntheticScene scene(Eigen::Vector3d(20.0, 6.0, 3.0));
  scene.fill([=](const Eigen::Vector3d& p) { return p.x() > known_until; }, VoxelState::kUnknown);
  return scene;
}

// A straight plan along y = 3, z = 1.5 from x0 at constant speed v for duration T (uniform cubic).
UniformBspline cruise(double x0, double v, double T) {
  const double h = 0.1;
  const int n = int(T / h + 0.5);
  Eigen::MatrixX3d q(n + 3, 3);
  for (int i = 0; i < q.rows(); ++i) q.row(i) << x0 + v * h * (i - 1), 3.0, 1.5;
  return UniformBspline(q, 3, h);
}

KnownSpaceCommitment::Config config(double brake) {
  KnownSpaceCommitment::Config c;
  c.brake_acc_mps2 = brake;
  c.max_brake_acc_mps2 = 5.0;
  return c;
}

TEST(KnownSpaceCommitment, AllKnownIsFlownAsPlanned) {
  SyntheticScene scene = hall(100.0);
  const EsdfMap& map = scene.finish();
  const UniformBspline plan = cruise(2.0, 3.0, 3.0);
  KnownSpaceCommitment::Committed out;
  std::string why;
  ASSERT_TRUE(KnownSpaceCommitment(config(2.5)).commit(plan, map, std::nullopt, &out, &why)) << why;
  EXPECT_FALSE(out.stops_before_unknown);
  EXPECT_EQ(out.brake_start_tau_s, plan.duration());
  EXPECT_FALSE(out.heading_target);
}

// The stop ends before the unknown space, keeping every sample committable, and the part before the
// brake point is the plan; a harder back-up deceleration brakes later (flies further as planned).
TEST(KnownSpaceCommitment, CutsToAStopBeforeUnknownSpace) {
  const double known_until = 9.0;
  SyntheticScene scene = hall(known_until);
  const EsdfMap& map = scene.finish();
  const UniformBspline plan = cruise(2.0, 4.0, 3.0);  // would reach x = 14
  double brake_at[2] = {0.0, 0.0};
  for (int k = 0; k < 2; ++k) {
    const double brake = k == 0 ? 2.5 : 5.0;
    const KnownSpaceCommitment commitment(config(brake));
    KnownSpaceCommitment::Committed out;
    std::string why;
    ASSERT_TRUE(commitment.commit(plan, map, std::nullopt, &out, &why)) << why;
    EXPECT_TRUE(out.stops_before_unknown);
    ASSERT_TRUE(out.heading_target);
    EXPECT_GT(out.heading_target->x(), known_until - 0.5);  // it looks along the plan, past the stop
    const UniformBspline& s = out.spline;
    const UniformBspline vel = s.derivative(), acc = vel.derivative();
    // At rest at the end, before the unknown space (its clearance ball observed: 0.2 m, and the margin).
    EXPECT_LT(vel.evaluate(s.duration()).norm(), 1e-6);
    EXPECT_LT(s.evaluate(s.duration()).x(), known_until - 0.2 - 0.1 + 0.05);
    double worst_decel = 0.0;
    for (double tau = 0.0; tau <= s.duration(); tau += 0.01) {
      EXPECT_TRUE(commitment.committable(map, s.evaluate(tau), 0.0, std::nullopt)) << "tau " << tau;
      const Eigen::Vector3d v = vel.evaluate(tau);
      if (v.norm() > 0.1) worst_decel = std::max(worst_decel, -acc.evaluate(tau).dot(v) / v.norm());
      if (tau < out.brake_start_tau_s - 0.3)  // as planned (the fit blends into the stop near it)
        EXPECT_LT((s.evaluate(tau) - plan.evaluate(tau)).norm(), 0.02) << "tau " << tau;
    }
    EXPECT_LT(worst_decel, 1.1 * brake + 0.3) << "brake " << brake;
    EXPECT_GT(worst_decel, 0.8 * brake) << "brake " << brake;
    brake_at[k] = out.brake_start_tau_s;
  }
  // From 4 m/s: 3.2 m to stop at 2.5 m/s^2, 1.6 m at 5: the harder back-up flies about 1.6 m
  // (0.4 s) further as planned.
  EXPECT_GT(brake_at[1], brake_at[0] + 0.3);
}

// Where the vehicle hovers without having been flown there (a mission's start), the camera cannot
// see beside itself: the anchor's neighbourhood counts as known.
TEST(KnownSpaceCommitment, TheAnchorCountsAsKnown) {
  SyntheticScene scene(Eigen::Vector3d(20.0, 6.0, 3.0));
  scene.fill([](const Eigen::Vector3d& p) { return std::abs(p.x() - 2.0) < 0.25; }, VoxelState::kUnknown);
  const EsdfMap& map = scene.finish();
  const KnownSpaceCommitment commitment(config(2.5));
  const Eigen::Vector3d at(2.0, 3.0, 1.5);
  EXPECT_FALSE(commitment.committable(map, at + Eigen::Vector3d(0.1, 0, 0), 0.0, std::nullopt));
  EXPECT_TRUE(commitment.committable(map, at + Eigen::Vector3d(0.1, 0, 0), 0.0, at));
  EXPECT_FALSE(commitment.committable(map, at + Eigen::Vector3d(0.35, 0, 0), 0.0, std::nullopt));  // its ball reaches in
}

TEST(KnownSpaceCommitment, TheHeightBandIsAGeofence) {
  SyntheticScene scene = hall(100.0);
  const EsdfMap& map = scene.finish();
  KnownSpaceCommitment::Config c = config(2.5);
  c.min_z_m = 0.3;
  c.max_z_m = 2.0;
  const KnownSpaceCommitment commitment(c);
  EXPECT_TRUE(commitment.committable(map, Eigen::Vector3d(5, 3, 1.9), 0.0, std::nullopt));
  EXPECT_FALSE(commitment.committable(map, Eigen::Vector3d(5, 3, 2.1), 0.0, std::nullopt));
  EXPECT_TRUE(commitment.committable(map, Eigen::Vector3d(5, 3, 2.1), 0.2, std::nullopt));  // no farther out than the start
  EXPECT_DOUBLE_EQ(commitment.bandExcess(2.5), 0.5);
}

TEST(KnownSpaceCommitment, ConfigIsChecked) {
  KnownSpaceCommitment::Config c;
  std::string why;
  EXPECT_TRUE(c.validate(&why)) << why;
  c.brake_acc_mps2 = 6.0;  // above max_brake_acc_mps2
  EXPECT_FALSE(c.validate(&why));
  EXPECT_NE(why.find("max_brake_acc_mps2"), std::string::npos);
}

}  // namespace
}  // namespace topo_planner
