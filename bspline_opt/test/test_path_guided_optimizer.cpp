// PGO and the GTO baseline: the paper's failure case (Fig. 2), enforced feasibility, an independent
// dense collision oracle on forest tasks, invalid input, determinism and parallel use.
#include <gtest/gtest.h>

#include <random>
#include <thread>

#include "topo_planner/bspline_opt/path_guided_optimizer.h"
#include "topo_planner/path_searching/grid_astar.h"
#include "topo_planner/path_searching/path_shortener.h"
#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

constexpr double kMaxVel = 3.0, kMaxAcc = 2.5, kClearance = 0.25;

PathGuidedOptimizer::Config testConfig() {
  PathGuidedOptimizer::Config c;
  c.max_vel_mps = kMaxVel;
  c.max_acc_mps2 = kMaxAcc;
  c.clearance_m = kClearance;
  c.max_iterations = 300;  // budgets by count only
  c.max_time_s = 0.0;
  return c;
}

// The reference segment: a straight rest-to-rest cubic with control points ~0.3 m apart, timed to
// the limits.
UniformBspline reference(const Eigen::Vector3d& start, const Eigen::Vector3d& goal) {
  const int n = std::clamp(int(std::lround((goal - start).norm() / 0.3)) + 5, 20, 40);
  UniformBspline s = UniformBspline::straightLine(start, goal, n, 3, 0.01);
  s.reallocateTime(kMaxVel, kMaxAcc);
  return s;
}

// Independent oracle: the smallest ESDF distance over 4000 samples evenly spaced in time, and the
// largest speed and acceleration magnitude over the same samples (from the derivative splines).
struct Oracle {
  double min_distance = 1e9, max_speed = 0.0, max_acc = 0.0;
  bool out_of_map = false;
};
Oracle oracle(const UniformBspline& s, const EsdfMap& map) {
  Oracle o;
  const UniformBspline v = s.derivative(), a = v.derivative();
  for (int k = 0; k <= 4000; ++k) {
    const double t = s.duration() * k / 4000.0;
    const DistanceQuery q = map.query(s.evaluate(t));
    if (q.status != QueryStatus::kOk && q.status != QueryStatus::kUnknown) o.out_of_map = true;
    o.min_distance = std::min(o.min_distance, q.distance);
    o.max_speed = std::max(o.max_speed, v.evaluate(t).norm());
    o.max_acc = std::max(o.max_acc, a.evaluate(t).norm());
  }
  return o;
}

void expectSafeAndFeasible(const OptimizationResult& r, const EsdfMap& map) {
  const Oracle o = oracle(r.spline, map);
  EXPECT_FALSE(o.out_of_map);
  EXPECT_GE(o.min_distance, kClearance);
  EXPECT_LE(o.max_speed, kMaxVel + 1e-9);
  EXPECT_LE(o.max_acc, kMaxAcc + 1e-9);
  EXPECT_LE(r.stats.max_vel_mps, kMaxVel + 1e-9);
  EXPECT_LE(r.stats.max_acc_mps2, kMaxAcc + 1e-9);
}

bool polylineFree(const Path& p, const EsdfMap& map, double clearance) {
  for (size_t i = 1; i < p.size(); ++i)
    for (int k = 0; k <= 200; ++k) {
      const DistanceQuery q = map.query(p[i - 1] + (p[i] - p[i - 1]) * (k / 200.0));
      if (q.status != QueryStatus::kOk || q.distance < clearance) return false;
    }
  return true;
}

// The paper's Fig. 2: a straight trajectory through the middle of a wide wall crosses the ESDF
// ridge inside it. The ESDF gradients on its control points point back and forth along the
// trajectory, never sideways, so phase 2 alone stays in collision; the guide path pulls it round.
TEST(PathGuidedOptimizer, WideBoxRidgeDefeatsGtoButNotPgo) {
  SyntheticScene scene({12.0, 10.0, 3.0});
  scene.box({5.0, 2.0, -1.0}, {7.0, 8.0, 4.0});  // 2 m thick, 6 m wide, full height
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d start(1.0, 5.0, 1.5), goal(11.0, 5.0, 1.5);
  const UniformBspline initial = reference(start, goal);
  const Path guide{start, {4.2, 1.2, 1.5}, {7.8, 1.2, 1.5}, goal};
  ASSERT_TRUE(polylineFree(guide, map, 0.4));

  const PathGuidedOptimizer optimizer(testConfig());
  const OptimizationResult before = optimizer.check(initial, map);
  EXPECT_EQ(before.status, OptimizationStatus::kInCollision);

  const OptimizationResult gto = optimizer.gto(initial, map);
  EXPECT_EQ(gto.status, OptimizationStatus::kInCollision) << toString(gto.status);
  EXPECT_LT(oracle(gto.spline, map).min_distance, 0.0);  // still inside the wall
  EXPECT_GT(gto.stats.iterations, 0);

  const OptimizationResult pgo = optimizer.optimize(initial, guide, map);
  EXPECT_EQ(pgo.status, OptimizationStatus::kSuccess) << pgo.message;
  expectSafeAndFeasible(pgo, map);
  EXPECT_GT(pgo.cost.guide, 0.0);
  EXPECT_GT(pgo.cost.jerk_integral_m2ps5, 0.0);
  EXPECT_NEAR(pgo.cost.duration_s, pgo.spline.duration(), 1e-12);
  // The ends are the reference's.
  EXPECT_LT((pgo.spline.evaluate(0.0) - start).norm(), 1e-9);
  EXPECT_LT((pgo.spline.evaluate(pgo.spline.duration()) - goal).norm(), 1e-9);
}

// Between two pillars 0.3 m apart the trajectory sits on the ESDF ridge of the gap (a saddle: a
// maximum across it, a minimum along it): the gradients push along the gap, not out of it.
TEST(PathGuidedOptimizer, NarrowGapBetweenPillarsDefeatsGtoButNotPgo) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0 + 0.55, 0.4);
  scene.pillar(5.0, 4.0 - 0.55, 0.4);
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d start(1.0, 4.0, 1.5), goal(9.0, 4.0, 1.5);
  const UniformBspline initial = reference(start, goal);
  const Path guide{start, {4.0, 2.3, 1.5}, {6.0, 2.3, 1.5}, goal};
  ASSERT_TRUE(polylineFree(guide, map, 0.4));

  const PathGuidedOptimizer optimizer(testConfig());
  const OptimizationResult gto = optimizer.gto(initial, map);
  EXPECT_EQ(gto.status, OptimizationStatus::kInCollision) << toString(gto.status);
  const OptimizationResult pgo = optimizer.optimize(initial, guide, map);
  EXPECT_EQ(pgo.status, OptimizationStatus::kSuccess) << pgo.message;
  expectSafeAndFeasible(pgo, map);
}

// Seeded forest tasks: every result reported successful passes the independent dense oracle, and
// PGO (guide from grid A* + shortening) succeeds at least as often as GTO, and on nearly all tasks.
// Seeded tasks in a medium forest of 20 x 20 x 3 m: start and goal 5-9 m apart and 0.6 m clear,
// the straight line between them blocked; fn(task, start, goal, guide) with the guide from grid A*
// at 0.4 m, shortened, for `count` of them.
template <typename Fn>
void forEachForestTask(const EsdfMap& map, uint32_t seed, int count, Fn&& fn) {
  GridAStar::Config ac;
  ac.clearance_m = 0.4;
  GridAStar astar(ac);
  const VisibilityChecker checker(map, 0.4, true), roomy(map, 0.6, true), blocked(map, kClearance, true);
  const PathShortener shortener(checker);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uxy(1.5, 18.5), uz(1.0, 2.0);
  for (int tasks = 0; tasks < count;) {
    const Eigen::Vector3d start(uxy(rng), uxy(rng), uz(rng)), goal(uxy(rng), uxy(rng), uz(rng));
    const double d = (goal - start).norm();
    if (d < 5.0 || d > 9.0 || !roomy.isFree(start) || !roomy.isFree(goal) || blocked.lineVisible(start, goal)) continue;
    const GridAStar::Result a = astar.search(map, start, goal);
    if (a.status != SearchStatus::kSuccess) continue;
    fn(++tasks, start, goal, shortener.shorten(a.path));
  }
}

TEST(PathGuidedOptimizer, ForestTasksSuccessMeansSafeAndFeasible) {
  SyntheticScene scene({20.0, 20.0, 3.0});
  scene.forest(ObstacleDensity::kMedium, 1001);
  const EsdfMap& map = scene.finish();
  const PathGuidedOptimizer optimizer(testConfig());
  int pgo_ok = 0, gto_ok = 0;
  forEachForestTask(map, 17, 12, [&](int tasks, const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                                     const Path& guide) {
    const UniformBspline initial = reference(start, goal);
    const OptimizationResult pgo = optimizer.optimize(initial, guide, map);
    const OptimizationResult gto = optimizer.gto(initial, map);
    for (const OptimizationResult* r : {&pgo, &gto}) {
      if (r->status != OptimizationStatus::kSuccess) continue;
      SCOPED_TRACE(tasks);
      expectSafeAndFeasible(*r, map);
    }
    pgo_ok += pgo.status == OptimizationStatus::kSuccess;
    gto_ok += gto.status == OptimizationStatus::kSuccess;
  });
  EXPECT_GE(pgo_ok, 11);
  EXPECT_GE(pgo_ok, gto_ok);
}

// Config::precondition: in y = L^T x the smoothness term's Hessian is the identity, so a refine
// that only smooths (no obstacle within d0, limits far away) is solved in a few evaluations, at the
// minimum the raw coordinates reach only after many. A wrong transform (gradient not the cost's)
// fails both: the line search stalls, or the two minima differ.
TEST(PathGuidedOptimizer, PreconditioningSolvesTheSmoothnessProblemInAFewEvaluations) {
  SyntheticScene scene({20.0, 10.0, 6.0});
  const EsdfMap& map = scene.finish();
  UniformBspline wiggly = UniformBspline::straightLine({2.0, 5.0, 3.0}, {18.0, 5.0, 3.0}, 30, 3, 1.0);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.3);
  for (int i = 3; i < 27; ++i)
    for (int c = 0; c < 3; ++c) wiggly.controlPoints()(i, c) += noise(rng);
  PathGuidedOptimizer::Config c = testConfig();
  c.max_iterations = 3000;
  c.xtol_rel = c.ftol_rel = 1e-12;
  c.precondition = false;
  const OptimizationResult plain = PathGuidedOptimizer(c).refinePhase(wiggly, map);
  c.precondition = true;
  const OptimizationResult pre = PathGuidedOptimizer(c).refinePhase(wiggly, map);
  ASSERT_EQ(plain.status, OptimizationStatus::kSuccess) << plain.message;
  ASSERT_EQ(pre.status, OptimizationStatus::kSuccess) << pre.message;
  EXPECT_EQ(pre.cost.collision, 0.0);
  EXPECT_EQ(pre.cost.feasibility, 0.0);
  EXPECT_NEAR(pre.cost.phase2, plain.cost.phase2, 1e-6 * (1.0 + plain.cost.phase2));
  EXPECT_LE((pre.spline.controlPoints() - plain.spline.controlPoints()).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LE(pre.stats.iterations, 5);
  EXPECT_GE(plain.stats.iterations, 5 * pre.stats.iterations);
  std::printf("smoothing alone: %d evaluations raw, %d preconditioned\n", plain.stats.iterations, pre.stats.iterations);
}

// On forest tasks (obstacles, limits), the preconditioned refine passes the check as often as the
// raw one, at a lower cost, in fewer evaluations of the same budget.
TEST(PathGuidedOptimizer, PreconditionedRefineNeedsFewerEvaluationsOnForestTasks) {
  SyntheticScene scene({20.0, 20.0, 3.0});
  scene.forest(ObstacleDensity::kMedium, 1002);
  const EsdfMap& map = scene.finish();
  PathGuidedOptimizer::Config c = testConfig();
  c.max_iterations = 200;
  c.precondition = false;
  const PathGuidedOptimizer raw(c);
  c.precondition = true;
  const PathGuidedOptimizer pre(c);
  int raw_ok = 0, pre_ok = 0, raw_evals = 0, pre_evals = 0;
  double raw_cost = 0.0, pre_cost = 0.0;
  forEachForestTask(map, 23, 10, [&](int, const Eigen::Vector3d& start, const Eigen::Vector3d& goal, const Path& guide) {
    const UniformBspline warm = raw.guidePhase(reference(start, goal), guide).spline;
    const OptimizationResult r = raw.refinePhase(warm, map), p = pre.refinePhase(warm, map);
    ASSERT_EQ(r.status, OptimizationStatus::kSuccess);
    ASSERT_EQ(p.status, OptimizationStatus::kSuccess);
    raw_evals += r.stats.iterations, pre_evals += p.stats.iterations;
    raw_cost += r.cost.phase2, pre_cost += p.cost.phase2;
    raw_ok += raw.check(r.spline, map).status == OptimizationStatus::kSuccess;
    pre_ok += pre.check(p.spline, map).status == OptimizationStatus::kSuccess;
  });
  EXPECT_GE(pre_ok, raw_ok);
  EXPECT_LT(pre_cost, raw_cost);
  EXPECT_LT(pre_evals, raw_evals * 7 / 10);
  std::printf("10 forest refines: raw %d evaluations, cost %.2f, %d pass; preconditioned %d, %.2f, %d\n", raw_evals,
              raw_cost, raw_ok, pre_evals, pre_cost, pre_ok);
}

TEST(PathGuidedOptimizer, FeasibilityIsEnforcedByTimeReallocation) {
  SyntheticScene scene({12.0, 10.0, 3.0});
  scene.box({5.0, 2.0, -1.0}, {7.0, 8.0, 4.0});
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d start(1.0, 5.0, 1.5), goal(11.0, 5.0, 1.5);
  UniformBspline fast = reference(start, goal);
  fast.setKnotSpan(fast.knotSpan() * 0.25);  // 4 times the speed, 16 times the acceleration
  const Path guide{start, {4.2, 1.2, 1.5}, {7.8, 1.2, 1.5}, goal};

  PathGuidedOptimizer::Config c = testConfig();
  c.l2d = 0.0;  // feasibility not even weighted: the reallocation alone must enforce it
  const OptimizationResult r = PathGuidedOptimizer(c).optimize(fast, guide, map);
  EXPECT_EQ(r.status, OptimizationStatus::kSuccess) << r.message;
  EXPECT_GT(r.stats.time_ratio, 1.2);
  expectSafeAndFeasible(r, map);
  EXPECT_NEAR(r.cost.feasibility, 0.0, 1e-12);

  c.reallocate_time = false;
  const OptimizationResult unstretched = PathGuidedOptimizer(c).optimize(fast, guide, map);
  EXPECT_EQ(unstretched.status, OptimizationStatus::kInfeasible);
  EXPECT_EQ(unstretched.stats.time_ratio, 1.0);
  c.reallocate_time = true;
  c.max_time_ratio = 1.0 + 0.5 * (r.stats.time_ratio - 1.0);  // the stretch needed is longer
  const OptimizationResult capped = PathGuidedOptimizer(c).optimize(fast, guide, map);
  EXPECT_EQ(capped.status, OptimizationStatus::kInfeasible);
  EXPECT_GT(capped.stats.time_ratio, c.max_time_ratio);
}

// A curve planned from hard braking (4 m/s^2, beyond the 2.5 m/s^2 limit) starts with that state:
// no knot span brings its first acceleration control point within the limit, and stretching time
// would change the start state. The check exempts the control points the start alone fixes and
// holds every other one to the limits: a start easing to 1 m/s^2 at once passes unstretched; the
// same start with a 5 m/s^2 step later is stretched until that step is within the limit.
TEST(PathGuidedOptimizer, AStartBeyondTheLimitIsExemptTheRestIsNot) {
  SyntheticScene scene({16.0, 10.0, 3.0});
  const EsdfMap& map = scene.finish();
  const double dt = 0.1;
  auto braking = [&](bool sharp) {
    // Velocity control points along x: 2.5 m/s, then 0.4 m/s less (A0 = -4 m/s^2), then 0.1 m/s
    // less per knot span (-1 m/s^2), with one step of 0.5 m/s (-5 m/s^2) later when sharp.
    Eigen::MatrixX3d q = Eigen::MatrixX3d::Zero(20, 3);
    q.col(1).setConstant(5.0);
    q.col(2).setConstant(1.5);
    double v = 2.5;
    for (int i = 1; i < 20; ++i) {
      q(i, 0) = q(i - 1, 0) + v * dt;
      v -= (i == 1 ? 0.4 : (sharp && i == 8) ? 0.5 : 0.1);
      v = std::max(v, 0.2);
    }
    return UniformBspline(q, 3, dt);
  };
  const UniformBspline gentle = braking(false);
  EXPECT_NEAR(gentle.derivative().derivative().evaluate(0.0).x(), -4.0, 1e-9);  // the start state
  EXPECT_NEAR(gentle.maxAcceleration(), 4.0, 1e-9);
  EXPECT_LE(gentle.maxAccelerationPastStart(), 1.0 + 1e-9);
  PathGuidedOptimizer::Config c = testConfig();
  for (const bool reallocate : {true, false}) {
    c.reallocate_time = reallocate;
    const OptimizationResult r = PathGuidedOptimizer(c).check(gentle, map);
    EXPECT_EQ(r.status, OptimizationStatus::kSuccess) << r.message;
    EXPECT_EQ(r.stats.time_ratio, 1.0);  // the start state is kept
  }
  const UniformBspline sharp = braking(true);
  EXPECT_NEAR(sharp.maxAccelerationPastStart(), 5.0, 1e-9);
  c.reallocate_time = false;
  EXPECT_EQ(PathGuidedOptimizer(c).check(sharp, map).status, OptimizationStatus::kInfeasible);
  c.reallocate_time = true;
  const OptimizationResult stretched = PathGuidedOptimizer(c).check(sharp, map);
  EXPECT_EQ(stretched.status, OptimizationStatus::kSuccess) << stretched.message;
  EXPECT_NEAR(stretched.stats.time_ratio, std::sqrt(5.0 / kMaxAcc), 1e-6);  // to the limit, not to 4 m/s^2
  EXPECT_LE(stretched.stats.max_acc_mps2, kMaxAcc * (1.0 + 1e-9));
}

// With guide_follows_initial the guide samples keep the initial curve's spacing: a curve timed to
// accelerate (control points closer together at its start) is guided by points equally close
// together there, at the same fractions of the guide's length as of the control polygon's.
TEST(PathGuidedOptimizer, GuideSamplesFollowTheInitialCurvesSpacing) {
  const Path guide{{0, 0, 1}, {4, 0, 1}, {4, 6, 1}};  // 10 m with a corner
  Eigen::MatrixX3d q(10, 3);
  for (int i = 0; i < 10; ++i) q.row(i) << 0.1 * i * i, 0.0, 1.0;  // accelerating along x, 8.1 m
  const int first = 3, last = 6;
  const Eigen::MatrixX3d g = PathGuidedOptimizer::guideSamplesAlong(guide, q, first, last);
  ASSERT_EQ(g.rows(), last - first + 1);
  double prev = -1.0;
  for (int j = 0; j < g.rows(); ++j) {
    const double frac = 0.1 * (first + j) * (first + j) / 8.1;  // the polygon is straight here
    const double along = 10.0 * frac;                        // the same fraction of the guide
    const Eigen::Vector3d expected =
        along <= 4.0 ? Eigen::Vector3d(along, 0, 1) : Eigen::Vector3d(4, along - 4.0, 1);
    EXPECT_LT((g.row(j).transpose() - expected).norm(), 1e-9) << "sample " << j;
    EXPECT_GT(along, prev);
    prev = along;
  }
  // The spacing grows as the control points' does (not even, as guideSamples gives).
  const Eigen::MatrixX3d even = PathGuidedOptimizer::guideSamples(guide, last - first + 1);
  EXPECT_GT((g.row(2) - g.row(1)).norm(), 1.2 * (g.row(1) - g.row(0)).norm());  // 1.11 m against 0.86 m
  EXPECT_NEAR((even.row(3) - even.row(2)).norm(), (even.row(1) - even.row(0)).norm(), 1e-9);
  // A polygon without length (a hold) falls back to the even samples; so does a one-point guide.
  Eigen::MatrixX3d hold(10, 3);
  hold.rowwise() = Eigen::RowVector3d(1, 2, 1);
  const Eigen::MatrixX3d fallback = PathGuidedOptimizer::guideSamplesAlong(guide, hold, first, last);
  EXPECT_LT((fallback - even).norm(), 1e-12);
  const Path point{{1, 1, 1}};
  const Eigen::MatrixX3d at_point = PathGuidedOptimizer::guideSamplesAlong(point, q, first, last);
  for (int j = 0; j < at_point.rows(); ++j) EXPECT_LT((at_point.row(j) - Eigen::RowVector3d(1, 1, 1)).norm(), 1e-12);
}

TEST(PathGuidedOptimizer, InvalidInputIsAStatusNotACrash) {
  SyntheticScene scene({6.0, 6.0, 3.0});
  const EsdfMap& map = scene.finish();
  const PathGuidedOptimizer optimizer(testConfig());
  const UniformBspline good = UniformBspline::straightLine({1, 1, 1}, {5, 5, 1}, 20, 3, 0.3);
  const Path guide{{1, 1, 1}, {5, 5, 1}};
  ASSERT_EQ(optimizer.optimize(good, guide, map).status, OptimizationStatus::kSuccess);

  std::vector<std::pair<std::string, UniformBspline>> bad;
  UniformBspline nan = good;
  nan.controlPoints()(7, 2) = NAN;
  bad.emplace_back("NaN control point", nan);
  UniformBspline inf = good;
  inf.controlPoints()(9, 0) = INFINITY;
  bad.emplace_back("inf control point", inf);
  UniformBspline zero = good;
  zero.setKnotSpan(0.0);
  bad.emplace_back("zero knot span", zero);
  UniformBspline negative = good;
  negative.setKnotSpan(-0.2);
  bad.emplace_back("negative knot span", negative);
  bad.emplace_back("fewer than degree + 1 control points", UniformBspline(good.controlPoints().topRows(3), 3, 0.3));
  bad.emplace_back("no free control point", UniformBspline(good.controlPoints().topRows(6), 3, 0.3));
  bad.emplace_back("degree 0", UniformBspline(good.controlPoints(), 0, 0.3));
  bad.emplace_back("empty spline", UniformBspline());
  for (const auto& [name, spline] : bad) {
    SCOPED_TRACE(name);
    for (const OptimizationResult& r :
         {optimizer.optimize(spline, guide, map), optimizer.gto(spline, map), optimizer.gtoWithRestarts(spline, map, 3, 1),
          optimizer.guidePhase(spline, guide), optimizer.refinePhase(spline, map), optimizer.check(spline, map)}) {
      EXPECT_EQ(r.status, OptimizationStatus::kInvalidInput);
      EXPECT_FALSE(r.message.empty());
    }
  }
  EXPECT_EQ(optimizer.optimize(good, Path{}, map).status, OptimizationStatus::kInvalidInput);
  EXPECT_EQ(optimizer.guidePhase(good, Path{}).status, OptimizationStatus::kInvalidInput);
  EXPECT_EQ(optimizer.optimize(good, Path{{1, NAN, 1}}, map).status, OptimizationStatus::kInvalidInput);

  // A valid spline far too long for a local check (10^4 km): refused, not sampled 10^8 times.
  const UniformBspline huge = UniformBspline::straightLine({1, 1, 1}, {1e7, 1, 1}, 20, 3, 1.0);
  EXPECT_EQ(optimizer.check(huge, map).status, OptimizationStatus::kInvalidInput);

  PathGuidedOptimizer::Config c = testConfig();
  c.algorithm = "LD_NO_SUCH_THING";
  EXPECT_EQ(PathGuidedOptimizer(c).optimize(good, guide, map).status, OptimizationStatus::kInvalidInput);
  c = testConfig();
  c.l1g = 0.0;
  EXPECT_EQ(PathGuidedOptimizer(c).optimize(good, guide, map).status, OptimizationStatus::kInvalidInput);
  c = testConfig();
  c.max_vel_mps = -1.0;
  EXPECT_EQ(PathGuidedOptimizer(c).gto(good, map).status, OptimizationStatus::kInvalidInput);
  c = testConfig();
  c.max_iterations = 0;
  EXPECT_EQ(PathGuidedOptimizer(c).gto(good, map).status, OptimizationStatus::kInvalidInput);
  for (const double margin : {0.0, -0.5, 1.01, double(NAN)}) {
    c = testConfig();
    c.feasibility_margin = margin;
    EXPECT_EQ(PathGuidedOptimizer(c).gto(good, map).status, OptimizationStatus::kInvalidInput) << margin;
  }
}

TEST(PathGuidedOptimizer, NonFiniteCostIsOptimizationFailed) {
  SyntheticScene scene({6.0, 6.0, 3.0});
  const EsdfMap& map = scene.finish();
  // A valid spline whose velocities overflow: (1 m / 1e-200 s)^2 is infinite.
  const UniformBspline s = UniformBspline::straightLine({1, 1, 1}, {5, 5, 1}, 20, 3, 1e-200);
  ASSERT_TRUE(s.isValid());
  const PathGuidedOptimizer optimizer(testConfig());
  const OptimizationResult r = optimizer.gto(s, map);
  EXPECT_EQ(r.status, OptimizationStatus::kOptimizationFailed);
  EXPECT_NE(r.message.find("not finite"), std::string::npos) << r.message;
  EXPECT_EQ(optimizer.optimize(s, {{1, 1, 1}, {5, 5, 1}}, map).status, OptimizationStatus::kOptimizationFailed);
}

TEST(PathGuidedOptimizer, OutOfMapIsReported) {
  SyntheticScene scene({6.0, 6.0, 3.0});
  const EsdfMap& map = scene.finish();
  const UniformBspline s = UniformBspline::straightLine({1, 1, 1}, {9, 1, 1}, 20, 3, 0.5);  // ends outside
  EXPECT_EQ(PathGuidedOptimizer(testConfig()).check(s, map).status, OptimizationStatus::kOutOfMap);
}

// The height band (a geofence): a curve that climbs out of it fails the check as leaving the map;
// one that starts below it (a take-off) may be as far out as its start.
TEST(PathGuidedOptimizer, TheHeightBandIsChecked) {
  SyntheticScene scene({10.0, 6.0, 4.0});
  const EsdfMap& map = scene.finish();
  PathGuidedOptimizer::Config config = testConfig();
  config.min_z_m = 0.5;
  config.max_z_m = 2.0;
  const PathGuidedOptimizer optimizer(config);
  auto through = [](std::vector<Eigen::Vector3d> points) {
    UniformBspline s;
    EXPECT_TRUE(UniformBspline::fitToPoints(points, 0.5, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                            Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 3, &s));
    return s;
  };
  const OptimizationResult over = optimizer.check(through({{1, 3, 1.5}, {3, 3, 2.0}, {5, 3, 2.6}, {7, 3, 2.0}, {9, 3, 1.5}}), map);
  EXPECT_EQ(over.status, OptimizationStatus::kOutOfMap);
  EXPECT_NE(over.message.find("height band"), std::string::npos) << over.message;
  EXPECT_EQ(optimizer.check(through({{1, 3, 1.0}, {3, 3, 1.4}, {5, 3, 1.6}, {7, 3, 1.4}, {9, 3, 1.0}}), map).status,
            OptimizationStatus::kSuccess);
  EXPECT_EQ(optimizer.check(through({{1, 3, 0.2}, {3, 3, 0.6}, {5, 3, 1.0}, {7, 3, 1.2}, {9, 3, 1.2}}), map).status,
            OptimizationStatus::kSuccess);  // from below the band into it
  EXPECT_EQ(PathGuidedOptimizer(testConfig()).check(through({{1, 3, 1.5}, {3, 3, 2.0}, {5, 3, 2.6}, {7, 3, 2.0}, {9, 3, 1.5}}), map).status,
            OptimizationStatus::kSuccess);  // no band
}

// A curve that starts inside the clearance (the map grew beside the trajectory being flown) passes
// while it moves out of it; one that stays inside, or comes closer than its start, does not; and a
// curve from outside is held to the whole clearance as before.
TEST(PathGuidedOptimizer, ACurveFromInsideTheClearanceMustMoveOut) {
  SyntheticScene scene({10.0, 6.0, 3.0});
  scene.box({4.0, 0.0, 0.0}, {5.0, 2.8, 3.0});  // a block: the ESDF counts from its voxels' centres, y = 2.75
  const EsdfMap& map = scene.finish();
  const PathGuidedOptimizer optimizer(testConfig());
  // A cubic through control points (x, y) at z = 1.5, from rest (the first three at the first).
  auto curve = [](std::vector<Eigen::Vector2d> xy) {
    xy.insert(xy.begin(), 2, xy.front());
    xy.insert(xy.end(), 2, xy.back());
    Eigen::MatrixX3d q(Eigen::Index(xy.size()), 3);
    for (size_t i = 0; i < xy.size(); ++i) q.row(Eigen::Index(i)) << xy[i].x(), xy[i].y(), 1.5;
    return UniformBspline(q, 3, 0.5);
  };
  const Eigen::Vector3d start(4.5, 2.92, 1.5);  // 0.17 m
  const double d0 = map.query(start).distance;
  ASSERT_GT(d0, 0.1);
  ASSERT_LT(d0, kClearance);
  // Away from the face, then on.
  const OptimizationResult out = optimizer.check(curve({{4.5, 2.92}, {4.5, 3.3}, {4.8, 3.7}, {6.0, 4.2}, {8.0, 4.2}}), map);
  EXPECT_EQ(out.status, OptimizationStatus::kSuccess) << out.message;
  EXPECT_NEAR(out.stats.min_clearance_m, d0, 0.01);
  // Along the face at the start's distance, then away: passes; 5 cm closer than the start: fails.
  EXPECT_EQ(optimizer.check(curve({{4.5, 2.92}, {4.7, 2.92}, {4.9, 2.92}, {5.5, 3.6}, {6.0, 4.2}}), map).status,
            OptimizationStatus::kSuccess);
  EXPECT_EQ(optimizer.check(curve({{4.5, 2.92}, {4.6, 2.87}, {4.8, 2.87}, {5.5, 3.6}, {6.0, 4.2}}), map).status,
            OptimizationStatus::kInCollision);
  // Out, then back in to 0.2 m (farther than the start): held to the clearance once it has left it.
  const std::vector<Eigen::Vector2d> dip{{4.5, 2.95}, {4.6, 2.95}, {4.7, 2.95}, {5.5, 3.8}, {6.0, 4.2}};
  std::vector<Eigen::Vector2d> back{{4.5, 2.92}, {4.3, 3.6}, {4.4, 3.6}};
  back.insert(back.end(), dip.begin(), dip.end());
  EXPECT_EQ(optimizer.check(curve(back), map).status, OptimizationStatus::kInCollision);
  // From outside the clearance into it: as before.
  std::vector<Eigen::Vector2d> in{{4.3, 3.6}, {4.4, 3.6}};
  in.insert(in.end(), dip.begin(), dip.end());
  EXPECT_EQ(optimizer.check(curve(in), map).status, OptimizationStatus::kInCollision);
}

// Under a low overhang near the window's floor (a table 0.55 m above the floor of the map, which is
// also the window's bottom face, as with the simulation's raised floor), the overhang's ESDF
// gradient pushes the control points down. The window's faces count as obstacles in the collision
// cost, so the curve settles between the two instead of leaving the map (it failed the final check
// as "out of map" before, every time: a vehicle stuck at rest near the floor).
TEST(PathGuidedOptimizer, TheWindowFloorKeepsTheCurveInsideTheMap) {
  SyntheticScene scene({12.0, 6.0, 3.0});
  scene.box({5.0, -1.0, 0.55}, {7.0, 7.0, 4.0});  // the whole width, from 0.55 m up
  const EsdfMap& map = scene.finish();
  const Eigen::Vector3d start(1.0, 3.0, 0.3), goal(11.0, 3.0, 0.3);
  const UniformBspline initial = reference(start, goal);
  const Path guide{start, {6.0, 3.0, 0.3}, goal};
  PathGuidedOptimizer::Config config = testConfig();
  config.clearance_m = 0.2;  // the gap: 0.05 (interpolation domain) .. 0.55 m (the box), d0 = 0.5
  const PathGuidedOptimizer optimizer(config);
  const OptimizationResult r = optimizer.optimize(initial, guide, map);
  EXPECT_EQ(r.status, OptimizationStatus::kSuccess) << toString(r.status) << " " << r.message;
  const Oracle o = oracle(r.spline, map);
  EXPECT_FALSE(o.out_of_map);
  EXPECT_GE(o.min_distance, config.clearance_m);
}

TEST(PathGuidedOptimizer, AlgorithmsAndRestartsAreRepeatable) {
  SyntheticScene scene({12.0, 10.0, 3.0});
  scene.box({5.0, 2.0, -1.0}, {7.0, 8.0, 4.0});
  const EsdfMap& map = scene.finish();
  const UniformBspline initial = reference({1.0, 5.0, 1.5}, {11.0, 5.0, 1.5});
  const Path guide{initial.evaluate(0), {4.2, 1.2, 1.5}, {7.8, 1.2, 1.5}, initial.evaluate(initial.duration())};
  for (const char* algorithm : {"LD_LBFGS", "LD_MMA", "LD_TNEWTON_PRECOND_RESTART"}) {
    SCOPED_TRACE(algorithm);
    PathGuidedOptimizer::Config c = testConfig();
    c.algorithm = algorithm;
    const PathGuidedOptimizer optimizer(c);
    const OptimizationResult a = optimizer.optimize(initial, guide, map), b = optimizer.optimize(initial, guide, map);
    EXPECT_EQ(a.status, OptimizationStatus::kSuccess) << a.message;
    EXPECT_EQ(a.spline.controlPoints(), b.spline.controlPoints());
    EXPECT_EQ(a.stats.iterations, b.stats.iterations);
    EXPECT_LE(a.stats.iterations, c.max_iterations);
  }
  const PathGuidedOptimizer optimizer(testConfig());
  const OptimizationResult r1 = optimizer.gtoWithRestarts(initial, map, 6, 99);
  const OptimizationResult r2 = optimizer.gtoWithRestarts(initial, map, 6, 99);
  EXPECT_EQ(r1.stats.runs, 6);
  EXPECT_EQ(r1.stats.best_run, r2.stats.best_run);
  EXPECT_EQ(r1.spline.controlPoints(), r2.spline.controlPoints());
  // Restarts can only help: the best of n is at least as good as the unperturbed run.
  const OptimizationResult single = optimizer.gto(initial, map);
  if (single.status == OptimizationStatus::kSuccess) {
    EXPECT_EQ(r1.status, OptimizationStatus::kSuccess);
  }
  if (r1.status == single.status) {
    EXPECT_LE(r1.cost.phase2, single.cost.phase2);
  }
  if (r1.status == OptimizationStatus::kSuccess) expectSafeAndFeasible(r1, map);
}

// One optimizer per worker (and one shared const optimizer) on a shared const map: the results equal
// the sequential ones bit for bit (no hidden shared state). Run under ThreadSanitizer too.
TEST(PathGuidedOptimizer, ParallelWorkersMatchSequential) {
  SyntheticScene scene({12.0, 10.0, 3.0});
  scene.box({5.0, 2.0, -1.0}, {7.0, 8.0, 4.0});
  scene.pillar(3.0, 7.0, 0.4);
  const EsdfMap& map = scene.finish();
  struct Job {
    UniformBspline initial;
    Path guide;
  };
  std::vector<Job> jobs;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d start(1.0, 4.0 + 0.25 * k, 1.2 + 0.05 * k), goal(11.0, 6.0 - 0.2 * k, 1.5);
    const double side = k % 2 ? 1.2 : 8.8;
    jobs.push_back({reference(start, goal), {start, {4.2, side, 1.5}, {7.8, side, 1.5}, goal}});
  }
  const PathGuidedOptimizer shared(testConfig());
  std::vector<OptimizationResult> sequential;
  for (const Job& j : jobs) sequential.push_back(shared.optimize(j.initial, j.guide, map));
  std::vector<OptimizationResult> own(jobs.size()), common(jobs.size());
  std::vector<std::thread> workers;
  for (int w = 0; w < 4; ++w)
    workers.emplace_back([&, w] {
      const PathGuidedOptimizer mine(testConfig());
      for (size_t k = size_t(w); k < jobs.size(); k += 4) {
        own[k] = mine.optimize(jobs[k].initial, jobs[k].guide, map);
        common[k] = shared.optimize(jobs[k].initial, jobs[k].guide, map);
      }
    });
  for (std::thread& t : workers) t.join();
  for (size_t k = 0; k < jobs.size(); ++k) {
    EXPECT_EQ(own[k].status, sequential[k].status);
    EXPECT_EQ(own[k].spline.controlPoints(), sequential[k].spline.controlPoints());
    EXPECT_EQ(own[k].spline.knotSpan(), sequential[k].spline.knotSpan());
    EXPECT_EQ(common[k].spline.controlPoints(), sequential[k].spline.controlPoints());
  }
}

TEST(OptimizationStatus, ToString) {
  for (OptimizationStatus s : {OptimizationStatus::kSuccess, OptimizationStatus::kInCollision, OptimizationStatus::kOutOfMap,
                               OptimizationStatus::kInfeasible, OptimizationStatus::kOptimizationFailed,
                               OptimizationStatus::kInvalidInput})
    EXPECT_STRNE(toString(s), "unknown status");
}

}  // namespace
}  // namespace topo_planner
