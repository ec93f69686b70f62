// From a plan to what the FSM commits to (plan_commit.h): a plan that does not start at the
// commanded velocity is refused, one in known free space is flown whole and rejoins the reference
// where the replanner said, one into unknown space is cut to a stop and rejoins it only as far as it goes.
#include "topo_planner/topo_replan/plan_commit.h"

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

// A 20 x 6 x 3 m hall, observed free up to x = known_until, unknown beyond.
SyntheticScene hall(double known_until) {
  SyntheticScene scene(Eigen::Vector3d(20.0, 6.0, 3.0));
  scene.fill([=](const Eigen::Vector3d& p) { return p.x() > known_until; }, VoxelState::kUnknown);
  return scene;
}

// A successful plan: 3 s along y = 3, z = 1.5 at 3 m/s from x = 2 (uniform cubic), covering the
// reference from 1 s to 4 s.
ReplanResult plan() {
  const double h = 0.05, v = 3.0;
  const int n = int(3.0 / h) + 3;
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i) q.row(i) << 2.0 + v * h * (i - 1), 3.0, 1.5;
  ReplanResult r;
  r.status = ReplanStatus::kSuccess;
  r.trajectory = UniformBspline(q, 3, h);
  r.local_start_time_s = 1.0;
  r.local_goal_time_s = 4.0;
  return r;
}

// Planned from the commanded state at 3 m/s along x, on a reference 3 m/s x reference_s long (at
// up to 10 m/s: it lasts less than reference_s).
struct Request {
  PolynomialTrajectory reference;
  ReplanRequest request;
  explicit Request(double reference_s) {
    FlatState start = FlatState::atRest(Eigen::Vector3d(2.0, 3.0, 1.5));
    start.velocity = Eigen::Vector3d(3.0, 0.0, 0.0);
    FlatState end = FlatState::atRest(Eigen::Vector3d(2.0 + 3.0 * reference_s, 3.0, 1.5));
    ReferenceConfig limits;
    limits.max_vel_mps = 10.0;
    limits.max_acc_mps2 = 10.0;
    EXPECT_EQ(referenceTrajectory({start.position, end.position}, start, end, limits, &reference),
              TrajectoryStatus::kSuccess);
    request.start = start;
    request.reference = &reference;
  }
};

PlanCommitConfig config() {
  PlanCommitConfig c;
  c.commitment.brake_acc_mps2 = 2.5;
  return c;
}

TEST(PlanCommit, APlanThatDoesNotStartAtTheCommandedVelocityIsRefused) {
  SyntheticScene scene = hall(20.0);
  const EsdfMap& map = scene.finish();
  Request r(30.0);
  r.request.start.velocity = Eigen::Vector3d(2.8, 0.0, 0.0);  // 0.2 m/s off, limit 0.1
  ReplanResult result = plan();
  result.message = "planned";
  ExecTrajectory traj;
  EXPECT_FALSE(commitPlan(r.request, 10.0, map, std::nullopt, config(), &result, &traj));
  EXPECT_EQ(result.status, ReplanStatus::kOptimizationFailed);
  EXPECT_EQ(result.message, "planned; its start velocity is 0.20 m/s off the commanded one (limit 0.10)");
}

TEST(PlanCommit, APlanInKnownFreeSpaceIsFlownWhole) {
  SyntheticScene scene = hall(20.0);
  const EsdfMap& map = scene.finish();
  Request r(30.0);
  ReplanResult result = plan();
  ExecTrajectory traj;
  ASSERT_TRUE(commitPlan(r.request, 10.0, map, std::nullopt, config(), &result, &traj)) << result.message;
  EXPECT_EQ(result.status, ReplanStatus::kSuccess);
  EXPECT_DOUBLE_EQ(traj.start_time_s, 10.0);
  EXPECT_FALSE(traj.stops_before_unknown);
  EXPECT_NEAR(traj.brake_start_s, 13.0, 1e-9);  // its end
  EXPECT_NEAR(traj.spline.duration(), 3.0, 1e-9);
  EXPECT_DOUBLE_EQ(traj.reference_start_s, 1.0);
  EXPECT_DOUBLE_EQ(traj.reference_end_s, 4.0);
  ASSERT_GT(r.reference.duration(), 4.0);
  EXPECT_FALSE(traj.ends_at_goal);  // the reference goes on past 4 s
  // On a reference that ends where the plan rejoins it: it ends at the goal.
  Request ending(4.0);
  ASSERT_LE(ending.reference.duration(), 4.0);
  result = plan();
  ASSERT_TRUE(commitPlan(ending.request, 10.0, map, std::nullopt, config(), &result, &traj));
  EXPECT_TRUE(traj.ends_at_goal);
}

TEST(PlanCommit, APlanIntoUnknownSpaceIsCutAndRejoinsTheReferenceOnlyAsFarAsItGoes) {
  SyntheticScene scene = hall(8.0);  // the plan runs to x = 11
  const EsdfMap& map = scene.finish();
  Request r(4.0);
  ReplanResult result = plan();
  ExecTrajectory traj;
  ASSERT_TRUE(commitPlan(r.request, 10.0, map, std::nullopt, config(), &result, &traj)) << result.message;
  EXPECT_TRUE(traj.stops_before_unknown);
  EXPECT_FALSE(traj.ends_at_goal);
  EXPECT_GT(traj.brake_start_s, 10.0);
  EXPECT_LT(traj.brake_start_s, 13.0);
  // The stop ends before x = 8 (less the clearance), at rest.
  EXPECT_LT(traj.spline.evaluate(traj.spline.duration()).x(), 8.0 - 0.2 + 1e-6);
  EXPECT_LT(traj.stateAt(traj.endTime()).velocity.norm(), 1e-9);
  // The reference it covers ends where its braking starts, proportionally.
  const double frac = (traj.brake_start_s - 10.0) / 3.0;
  EXPECT_NEAR(traj.reference_end_s, 1.0 + frac * 3.0, 1e-9);
  EXPECT_TRUE(traj.has_heading_target);  // the camera looks on along the plan
}

}  // namespace
}  // namespace topo_planner
