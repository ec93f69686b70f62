// The FSM's manoeuvres on their own (manoeuvres.h): the stop along the flown path and its harder
// deceleration, the back-off's way (flown path, else the hover it started from), the rest-to-rest
// flight and its look-first hold, the escape up the distance field.
#include "topo_planner/topo_replan/manoeuvres.h"

#include <cmath>

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

// A 20 x 6 x 3 m hall, all observed free.
SyntheticScene hall() { return SyntheticScene(Eigen::Vector3d(20.0, 6.0, 3.0)); }

ExecTrajectory flying(const UniformBspline& spline) {
  ExecTrajectory traj;
  traj.start_time_s = 0.0;
  traj.spline = spline;
  traj.brake_start_s = spline.duration();
  return traj;
}

FlatState stateOn(const UniformBspline& s, double tau) {
  FlatState st;
  st.position = s.evaluate(tau);
  st.velocity = s.derivative().evaluate(tau);
  st.acceleration = s.derivative().derivative().evaluate(tau);
  return st;
}

// Distance from p to the path of `s`, sampled finely.
double distanceToPath(const UniformBspline& s, const Eigen::Vector3d& p) {
  double best = INFINITY;
  for (double tau = 0.0; tau <= s.duration(); tau += 0.002) best = std::min(best, (s.evaluate(tau) - p).norm());
  return best;
}

// A quarter-circle turn of radius 2 m at about 3 m/s around (10, 1, 1.5), control points on the arc.
UniformBspline arc() {
  const double h = 0.05, r = 2.0, v = 3.0;
  const int n = int(M_PI / 2 * r / v / h) + 3;
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i) {
    const double a = -M_PI / 2 + (i - 1) * v * h / r;
    q.row(i) << 10.0 + r * std::cos(a), 3.0 + r * std::sin(a), 1.5;
  }
  return UniformBspline(q, 3, h);
}

TEST(Braking, AlongTheFlownPathItStaysOnTheCurveAndEndsAtRest) {
  SyntheticScene scene = hall();
  const EsdfMap& map = scene.finish();
  const UniformBspline path = arc();
  const ExecTrajectory flown = flying(path);
  const FlatState s0 = stateOn(path, 0.1);
  ManoeuvreConfig config;
  config.brake_acc_mps2 = 4.0;  // stops within the arc
  std::string report;
  const ExecTrajectory along = brakingTrajectory(s0, &flown, 0.1, map, config, true, &report);
  const ExecTrajectory straight = brakingTrajectory(s0, nullptr, 0.1, map, config, true, &report);
  for (const ExecTrajectory* b : {&along, &straight}) {
    EXPECT_TRUE(b->braking);
    EXPECT_LT((b->spline.evaluate(0.0) - s0.position).norm(), 1e-6);
    EXPECT_LT((b->spline.derivative().evaluate(0.0) - s0.velocity).norm(), 1e-6);
    EXPECT_LT(b->spline.derivative().evaluate(b->spline.duration()).norm(), 1e-6);
  }
  double along_off = 0.0, straight_off = 0.0;
  for (double tau = 0.0; tau <= along.spline.duration(); tau += 0.02)
    along_off = std::max(along_off, distanceToPath(path, along.spline.evaluate(tau)));
  for (double tau = 0.0; tau <= straight.spline.duration(); tau += 0.02)
    straight_off = std::max(straight_off, distanceToPath(path, straight.spline.evaluate(tau)));
  EXPECT_LT(along_off, 0.03);     // on the curve
  EXPECT_GT(straight_off, 0.15);  // along the tangent, off it
}

// Towards a wall seen late: the planner's deceleration would come within the safety clearance, so
// the stop brakes harder (up to the vehicle's limit) when it may; from a re-anchored state it may not.
TEST(Braking, BrakesHarderOnlyWhenItMustAndMay) {
  SyntheticScene scene = hall();
  scene.box(Eigen::Vector3d(8.0, 0.0, 0.0), Eigen::Vector3d(8.4, 6.0, 3.0));
  const EsdfMap& map = scene.finish();
  FlatState s0;
  s0.position = Eigen::Vector3d(4.8, 3.0, 1.5);
  s0.velocity = Eigen::Vector3d(4.0, 0.0, 0.0);  // 3.2 m to stop at 2.5 m/s^2 (into the wall), 1.6 m at 5
  ManoeuvreConfig config;
  std::string report;
  const ExecTrajectory harder = brakingTrajectory(s0, nullptr, 0.0, map, config, true, &report);
  EXPECT_NE(report.find("collision-free"), std::string::npos) << report;
  EXPECT_EQ(report.find("2.50 m/s^2"), std::string::npos) << report;
  EXPECT_LT(firstCollisionTime(harder, 0.0, map, config.safety_clearance_m, config.safety_sample_s), 0.0);
  const ExecTrajectory planner = brakingTrajectory(s0, nullptr, 0.0, map, config, false, &report);
  EXPECT_NE(report.find("2.50 m/s^2"), std::string::npos) << report;
  EXPECT_NE(report.find("within the safety clearance"), std::string::npos) << report;
  EXPECT_GE(firstCollisionTime(planner, 0.0, map, config.safety_clearance_m, config.safety_sample_s), 0.0);
  // In the open, the planner's deceleration.
  s0.position.x() = 1.0;
  s0.velocity.x() = 2.0;
  brakingTrajectory(s0, nullptr, 0.0, map, config, true, &report);
  EXPECT_NE(report.find("2.50 m/s^2"), std::string::npos) << report;
}

// Flown positions 0.25 m apart along y = 3 from x = 2 to the vehicle at x = 8.
std::vector<Eigen::Vector3d> flownLine() {
  std::vector<Eigen::Vector3d> flown;
  for (double x = 2.0; x <= 8.0 + 1e-9; x += 0.25) flown.emplace_back(x, 3.0, 1.5);
  return flown;
}

TEST(Backoff, GoesBackAlongTheFlownPathUntilItHasItsClearance) {
  SyntheticScene scene = hall();
  // A pillar beside the flown path 1.5-2.5 m back: the back-off goes on past it.
  scene.box(Eigen::Vector3d(5.5, 3.3, 0.0), Eigen::Vector3d(6.5, 4.0, 3.0));
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d p0(8.0, 3.0, 1.5);
  const ManoeuvreConfig config;
  std::string why;
  const std::optional<BackoffWalk> walk = backoffWalk(p0, 3.0, flownLine(), std::nullopt, map, config, &why);
  ASSERT_TRUE(walk) << why;
  EXPECT_FALSE(walk->to_anchor);
  EXPECT_GE(walk->length_m, 2.5 - 1e-9);  // past the pillar, where the clearance is back
  EXPECT_LE(walk->length_m, config.max_backoff_length_m);
  EXPECT_GE(walk->end_clearance_m, config.escape_clearance_m);
  // A straight flown path is one segment: no corners left.
  ASSERT_EQ(walk->points.size(), 2u);
  EXPECT_NEAR(walk->points.back().x(), 8.0 - walk->length_m, 1e-9);
  // Without the pillar it stops after backoff_length_m.
  SyntheticScene open = hall();
  const std::optional<BackoffWalk> short_walk =
      backoffWalk(p0, 3.0, flownLine(), std::nullopt, open.finish(), config, &why);
  ASSERT_TRUE(short_walk) << why;
  EXPECT_NEAR(short_walk->length_m, config.backoff_length_m, 1e-9);
}

// With no flown path (the map was cleared, or the vehicle never flew), back to the hover it started
// from, when it crept away from it within the anchor's zone; not when it is there, nor from afar.
TEST(Backoff, WithNoFlownPathGoesBackToTheAnchorWithinItsZone) {
  SyntheticScene scene = hall();
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d p0(8.0, 3.0, 1.5);
  const ManoeuvreConfig config;  // zone: 0.1 to 0.35 m
  std::string why;
  for (const double away : {0.05, 0.2, 0.34, 0.5}) {
    const Eigen::Vector3d anchor = p0 - Eigen::Vector3d(away, 0.0, 0.0);
    const std::optional<BackoffWalk> walk = backoffWalk(p0, 3.0, {}, anchor, map, config, &why);
    const bool in_zone = away >= 0.1 && away <= 0.35;
    ASSERT_EQ(bool(walk), in_zone) << "away " << away;
    if (!walk) {
      EXPECT_NE(why.find("no flown path"), std::string::npos) << why;
      continue;
    }
    EXPECT_TRUE(walk->to_anchor);
    ASSERT_EQ(walk->points.size(), 2u);
    EXPECT_EQ(walk->points.back(), anchor);
    EXPECT_NEAR(walk->length_m, away, 1e-9);
  }
  EXPECT_FALSE(backoffWalk(p0, 3.0, {}, std::nullopt, map, config, &why));
  // A flown path counts first, the anchor not.
  const std::optional<BackoffWalk> walk = backoffWalk(p0, 3.0, flownLine(), p0 - Eigen::Vector3d(0.2, 0, 0), map, config, &why);
  ASSERT_TRUE(walk) << why;
  EXPECT_FALSE(walk->to_anchor);
}

TEST(RestToRest, FliesTheWalkSlowlyFromRestToRest) {
  SyntheticScene scene = hall();
  const EsdfMap& map = scene.finish();
  const std::vector<Eigen::Vector3d> walk{{8.0, 3.0, 1.5}, {7.0, 3.0, 1.5}, {6.5, 3.5, 1.5}};
  const ManoeuvreConfig config;
  std::string report;
  const std::optional<ExecTrajectory> m =
      restToRest(walk, FlatState::atRest(walk.front()), 2.0, map, 3.0, 1.0, "back-off", config, &report);
  ASSERT_TRUE(m) << report;
  EXPECT_TRUE(report.empty()) << report;
  EXPECT_TRUE(m->escape);
  EXPECT_EQ(m->start_time_s, 2.0);
  const UniformBspline& s = m->spline;
  EXPECT_LT((s.evaluate(s.duration()) - walk.back()).norm(), 0.02);
  EXPECT_LT(s.derivative().evaluate(s.duration()).norm(), 1e-6);
  double peak = 0.0;
  for (double tau = 0.0; tau <= s.duration(); tau += 0.01) peak = std::max(peak, s.derivative().evaluate(tau).norm());
  EXPECT_LT(peak, 1.0 + 0.1);
  // Slowed at the corner (the fitted curve's acceleration bound above half the braking deceleration).
  EXPECT_GT(s.duration(), 1.4 * 1.5 * (1.0 + std::sqrt(0.5)) / 1.0);
}

// A walk into unknown space is not flown: a hold at the start, looking at the walk's end.
TEST(RestToRest, HoldsAndLooksWhereTheWayCrossesUnknownSpace) {
  SyntheticScene scene = hall();
  scene.fill([](const Eigen::Vector3d& p) { return p.x() < 6.0; }, VoxelState::kUnknown);
  const EsdfMap& map = scene.finish();
  const std::vector<Eigen::Vector3d> walk{{8.0, 3.0, 1.5}, {5.5, 3.0, 1.5}};
  std::string report;
  const std::optional<ExecTrajectory> m =
      restToRest(walk, FlatState::atRest(walk.front()), 0.0, map, 3.0, 1.0, "back-off", ManoeuvreConfig(), &report);
  ASSERT_TRUE(m);
  EXPECT_NE(report.find("unknown space"), std::string::npos) << report;
  EXPECT_TRUE(m->has_heading_target);
  EXPECT_EQ(m->heading_target, walk.back());
  EXPECT_LT((m->spline.evaluate(m->spline.duration()) - walk.front()).norm(), 1e-9);
  // Without the known-space rule, flown.
  ManoeuvreConfig optimistic;
  optimistic.commit_to_known_space = false;
  const std::optional<ExecTrajectory> flown =
      restToRest(walk, FlatState::atRest(walk.front()), 0.0, map, 3.0, 1.0, "back-off", optimistic, &report);
  ASSERT_TRUE(flown);
  EXPECT_TRUE(report.empty()) << report;
}

TEST(Escape, ClimbsTheDistanceFieldOutOfAnObstaclesClearance) {
  SyntheticScene scene = hall();
  scene.box(Eigen::Vector3d(8.0, 0.0, 0.0), Eigen::Vector3d(8.4, 6.0, 3.0));
  const EsdfMap& map = scene.finish();
  const FlatState s0 = FlatState::atRest(Eigen::Vector3d(7.9, 3.0, 1.5));
  const double d0 = map.query(s0.position).distance;
  ASSERT_LT(d0, 0.2);
  ManoeuvreConfig config;
  std::string report;
  const std::optional<ExecTrajectory> escape = escapeTrajectory(s0, 0.0, map, config, &report);
  ASSERT_TRUE(escape) << report;
  EXPECT_NE(report.find("escape:"), std::string::npos) << report;
  const UniformBspline& s = escape->spline;
  EXPECT_GE(map.query(s.evaluate(s.duration())).distance, config.escape_min_clearance_m);
  for (double tau = 0.0; tau <= s.duration(); tau += 0.01)
    EXPECT_GE(map.query(s.evaluate(tau)).distance, d0 - 0.03) << "tau " << tau;
  config.max_escape_length_m = 0.0;
  EXPECT_FALSE(escapeTrajectory(s0, 0.0, map, config, &report));
  EXPECT_NE(report.find("disabled"), std::string::npos) << report;
}

TEST(FlownPath, KeepsPositionsApartDropsTheOldestAndIsUsedUpByABackOff) {
  FlownPath flown;
  for (int i = 0; i <= 100; ++i) flown.record(Eigen::Vector3d(0.05 * i, 0.0, 1.0));  // 5 m at 5 cm steps
  ASSERT_EQ(flown.points().size(), 21u);  // every 0.25 m
  EXPECT_TRUE(flown.points().back().isApprox(Eigen::Vector3d(5.0, 0.0, 1.0)));
  // A back-off to x = 3.9: the points beyond (more than 0.3 m from its end) are used up.
  flown.useUpTo(Eigen::Vector3d(3.9, 0.0, 1.0));
  EXPECT_NEAR(flown.points().back().x(), 4.0, 1e-9);
  // A long flight keeps the newest kMaxPoints at most.
  for (int i = 0; i < 1000; ++i) flown.record(Eigen::Vector3d(4.0 + 0.25 * i, 0.0, 1.0));
  EXPECT_LE(flown.points().size(), FlownPath::kMaxPoints);
  EXPECT_GT(flown.points().size(), FlownPath::kMaxPoints / 2);
  EXPECT_NEAR(flown.points().back().x(), 4.0 + 0.25 * 999, 1e-9);
  flown.clear();
  EXPECT_TRUE(flown.points().empty());
}

}  // namespace
}  // namespace topo_planner
