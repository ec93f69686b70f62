// The cost terms against central finite differences in a random ESDF, and the closed-form guide
// phase against NLopt on the same quadratic.
#include <gtest/gtest.h>
#include <nlopt.hpp>

#include <functional>
#include <random>

#include "topo_planner/bspline_opt/bspline_costs.h"
#include "topo_planner/bspline_opt/path_guided_optimizer.h"
#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

using CostFn = std::function<double(const Eigen::MatrixX3d& q, Eigen::MatrixX3d* grad)>;

// Compares the analytic gradient of fn with central differences, element by element.
void expectGradientMatches(const CostFn& fn, const Eigen::MatrixX3d& q, const char* name) {
  Eigen::MatrixX3d grad = Eigen::MatrixX3d::Zero(q.rows(), 3);
  const double f0 = fn(q, &grad);
  EXPECT_TRUE(std::isfinite(f0)) << name;
  EXPECT_GT(f0, 0.0) << name << ": the term must be active for the check to mean something";
  const double h = 1e-6;
  double max_error = 0.0;
  for (int i = 0; i < q.rows(); ++i)
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixX3d qp = q, qm = q;
      qp(i, c) += h;
      qm(i, c) -= h;
      const double fd = (fn(qp, nullptr) - fn(qm, nullptr)) / (2 * h);
      const double error = std::abs(fd - grad(i, c)) / std::max(1.0, std::abs(fd));
      max_error = std::max(max_error, error);
      EXPECT_LT(error, 1e-5) << name << " row " << i << " axis " << c << ": analytic " << grad(i, c) << " fd " << fd;
    }
  EXPECT_LT(max_error, 1e-5) << name;
}

class CostGradients : public ::testing::Test {
 protected:
  CostGradients() : scene_({8.0, 8.0, 3.0}) {
    scene_.forest(ObstacleDensity::kHigh, 42);
    scene_.finish();
  }
  // Random control points over the map interior (many inside or near obstacles).
  Eigen::MatrixX3d randomControlPoints(int n, uint32_t seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> uxy(0.5, 7.5), uz(0.5, 2.5);
    Eigen::MatrixX3d q(n, 3);
    for (int i = 0; i < n; ++i) q.row(i) << uxy(rng), uxy(rng), uz(rng);
    return q;
  }
  SyntheticScene scene_;
};

TEST_F(CostGradients, EachTermMatchesCentralDifferences) {
  const EsdfMap& map = *scene_.esdf;
  for (uint32_t seed = 1; seed <= 5; ++seed) {
    const Eigen::MatrixX3d q = randomControlPoints(25, seed);
    const int first = 3, last = 21;
    std::mt19937 rng(seed + 100);
    std::uniform_real_distribution<double> u(0.0, 8.0);
    Eigen::MatrixX3d guide(last - first + 1, 3);
    for (int i = 0; i < guide.rows(); ++i) guide.row(i) << u(rng), u(rng), u(rng);
    const double dt = 0.5;  // random points ~2.7 m apart: some V_i and A_i above the limits, some below
    const double weight = 1.7;

    // Each term with weight 1 (plain gradient), and with a weight (the gradient scales, not the cost).
    for (double w : {1.0, weight}) {
      auto scaled = [w](auto term) {
        return CostFn([w, term](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) {
          Eigen::MatrixX3d local = Eigen::MatrixX3d::Zero(x.rows(), 3);
          const double f = term(x, g ? &local : nullptr);
          if (g) *g += local / w;  // undo the weight: compare with the plain derivative
          return f;
        });
      };
      expectGradientMatches(
          scaled([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) { return smoothnessCost(x, first, last, w, g); }),
          q, "smoothness");
      expectGradientMatches(
          scaled([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) { return guideCost(x, guide, first, last, w, g); }),
          q, "guide");
      expectGradientMatches(scaled([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) {
                              return collisionCost(x, first, last, map, 1.0, w, g);
                            }),
                            q, "collision");
      expectGradientMatches(
          scaled([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) { return velocityCost(x, dt, 3.0, w, g); }), q,
          "velocity");
      expectGradientMatches(
          scaled([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) { return accelerationCost(x, dt, 2.5, w, g); }), q,
          "acceleration");
    }
  }
}

TEST_F(CostGradients, InterpolationEqualsEsdfQuery) {
  const EsdfMap& map = *scene_.esdf;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.3, 8.3);  // inside, near the border and outside
  int inside = 0;
  for (int k = 0; k < 20000; ++k) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng) * 3.0 / 8.0);
    const DistanceQuery q = map.query(p);
    double d = 0.0;
    Eigen::Vector3d g;
    const bool ok = map.interpolate(p, &d, &g);
    ASSERT_EQ(ok, q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown) << p.transpose();
    if (!ok) continue;
    ++inside;
    EXPECT_EQ(d, q.distance);
    EXPECT_EQ(g, q.gradient);
  }
  EXPECT_GT(inside, 10000);
  double d;
  EXPECT_FALSE(map.interpolate(Eigen::Vector3d(NAN, 1, 1), &d, nullptr));
  EXPECT_FALSE(map.interpolate(Eigen::Vector3d(1e300, 1, 1), &d, nullptr));
}

TEST_F(CostGradients, TermsAreZeroWhereThePaperSaysSo) {
  const EsdfMap& map = *scene_.esdf;
  // Collision: zero beyond d0 (a point far from every obstacle: the largest distance in the map).
  Eigen::MatrixX3d q = randomControlPoints(10, 9);
  double best = -1.0;
  Eigen::Vector3d far = Eigen::Vector3d::Zero();
  for (double x = 1.0; x < 7.0; x += 0.1)  // (more than d0 inside the window's faces)
    for (double y = 1.0; y < 7.0; y += 0.1) {
      const DistanceQuery d = map.query({x, y, 1.5});
      if (d.status == QueryStatus::kOk && d.distance > best) best = d.distance, far = {x, y, 1.5};
    }
  ASSERT_GT(best, 0.6);
  q.rowwise() = far.transpose();
  EXPECT_EQ(collisionCost(q, 0, 9, map, 0.5, 1.0, nullptr), 0.0);
  EXPECT_GT(collisionCost(q, 0, 9, map, best + 0.1, 1.0, nullptr), 0.0);
  // Smoothness: zero on evenly spaced collinear points; feasibility zero below the limits.
  for (int i = 0; i < 10; ++i) q.row(i) << 0.1 * i, 0.2 * i, 1.0;
  EXPECT_NEAR(smoothnessCost(q, 3, 6, 1.0, nullptr), 0.0, 1e-24);
  EXPECT_EQ(velocityCost(q, 0.1, 3.0, 1.0, nullptr), 0.0);  // 2.24 m/s
  EXPECT_GT(velocityCost(q, 0.05, 3.0, 1.0, nullptr), 0.0);
  EXPECT_EQ(accelerationCost(q, 0.1, 2.5, 1.0, nullptr), 0.0);
}

// The faces of a height band count as obstacles: a point 0.2 m under its top is pushed down; the
// gradient matches.
TEST(CollisionCost, TheHeightBandFacesCountAsObstacles) {
  SyntheticScene scene({8.0, 8.0, 3.0});
  const EsdfMap& map = scene.finish();
  const double d0 = 0.5;
  Eigen::MatrixX3d q(1, 3);
  q.row(0) << 4.0, 4.0, 1.8;
  EXPECT_EQ(collisionCost(q, 0, 0, map, d0, 1.0, nullptr), 0.0);  // no band
  Eigen::MatrixX3d grad = Eigen::MatrixX3d::Zero(1, 3);
  EXPECT_NEAR(collisionCost(q, 0, 0, map, d0, 1.0, &grad, 0.5, 2.0), std::pow(d0 - 0.2, 2), 1e-12);
  EXPECT_GT(grad(0, 2), 0.0);  // descent moves it down
  Eigen::MatrixX3d pts(3, 3);
  pts << 4.0, 4.0, 1.8, 4.0, 4.0, 0.7, 4.0, 4.0, 2.2;
  expectGradientMatches([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) {
    return collisionCost(x, 0, 2, map, d0, 1.0, g, 0.5, 2.0);
  }, pts, "band");
}

// The band's excess: 0 inside and on the faces, the distance past the face outside, either side.
TEST(HeightBand, ExcessIsTheDistanceOutsideTheBand) {
  EXPECT_EQ(heightBandExcess(1.0, 0.5, 3.0), 0.0);
  EXPECT_EQ(heightBandExcess(0.5, 0.5, 3.0), 0.0);
  EXPECT_EQ(heightBandExcess(3.0, 0.5, 3.0), 0.0);
  EXPECT_NEAR(heightBandExcess(3.26, 0.5, 3.0), 0.26, 1e-12);
  EXPECT_NEAR(heightBandExcess(0.1, 0.5, 3.0), 0.4, 1e-12);
  EXPECT_EQ(heightBandExcess(-5.0, -1e9, 1e9), 0.0);  // the default: no band
}

// The window's faces count as obstacles: a point near the floor costs (d0 - its height above the
// interpolation domain)^2 and is pushed up; a point outside costs more; the gradient matches.
TEST(CollisionCost, TheWindowFacesCountAsObstacles) {
  SyntheticScene scene({8.0, 8.0, 3.0});  // empty: the ESDF is the truncation distance everywhere
  const EsdfMap& map = scene.finish();
  const double d0 = 0.5, half = 0.5 * map.geometry().resolution();
  Eigen::MatrixX3d q(1, 3);
  q.row(0) << 4.0, 4.0, 1.5;
  EXPECT_EQ(collisionCost(q, 0, 0, map, d0, 1.0, nullptr), 0.0);
  q.row(0) << 4.0, 4.0, 0.2;
  Eigen::MatrixX3d grad = Eigen::MatrixX3d::Zero(1, 3);
  const double inside = collisionCost(q, 0, 0, map, d0, 1.0, &grad);
  EXPECT_NEAR(inside, std::pow(d0 - (0.2 - half), 2), 1e-12);
  EXPECT_LT(grad(0, 2), 0.0);  // descent moves it up
  EXPECT_EQ(grad(0, 0), 0.0);
  q.row(0) << 4.0, 4.0, -0.3;  // below the window
  EXPECT_GT(collisionCost(q, 0, 0, map, d0, 1.0, nullptr), inside);
  q.row(0) << 7.9, 4.0, 1.5;  // near a side face
  grad.setZero();
  EXPECT_GT(collisionCost(q, 0, 0, map, d0, 1.0, &grad), 0.0);
  EXPECT_GT(grad(0, 0), 0.0);  // descent moves it back in (-x)
  Eigen::MatrixX3d pts(4, 3);
  pts << 4.0, 4.0, 0.2, 0.3, 4.0, 1.5, 4.0, 7.8, 1.5, 4.0, 4.0, 2.7;
  expectGradientMatches([&](const Eigen::MatrixX3d& x, Eigen::MatrixX3d* g) {
    return collisionCost(x, 0, 3, map, d0, 1.0, g);
  }, pts, "window");
}

// f_p1 = l1s f_s + l1g f_g over the free rows, for NLopt.
struct GuideProblem {
  Eigen::MatrixX3d q, g;
  int first = 0, last = 0;
  double l1s = 1.0, l1g = 1.0;
  static double objective(unsigned, const double* x, double* grad, void* data) {
    auto* p = static_cast<GuideProblem*>(data);
    for (int i = p->first; i <= p->last; ++i)
      for (int c = 0; c < 3; ++c) p->q(i, c) = x[3 * (i - p->first) + c];
    Eigen::MatrixX3d gr = Eigen::MatrixX3d::Zero(p->q.rows(), 3);
    const double f = p->l1s * smoothnessCost(p->q, p->first, p->last, p->l1s, &gr) +
                     p->l1g * guideCost(p->q, p->g, p->first, p->last, p->l1g, &gr);
    if (grad)
      for (int i = p->first; i <= p->last; ++i)
        for (int c = 0; c < 3; ++c) grad[3 * (i - p->first) + c] = gr(i, c);
    return f;
  }
};

TEST(GuidePhase, ClosedFormEqualsNloptMinimum) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int degree : {3, 4}) {
    for (double l1s : {0.1, 1.0, 10.0}) {
      const int n = 30;
      Eigen::MatrixX3d q0(n, 3);
      for (int i = 0; i < n; ++i) q0.row(i) << 0.3 * i + u(rng) * 0.1, u(rng) * 0.1, 1.0 + u(rng) * 0.1;
      const UniformBspline initial(q0, degree, 0.2);
      // A zig-zag guide path from the start to the goal.
      Path guide{q0.row(0).transpose()};
      for (int k = 1; k < 6; ++k) guide.push_back(Eigen::Vector3d(1.5 * k, u(rng), 1.0 + u(rng)));
      guide.push_back(q0.row(n - 1).transpose());

      PathGuidedOptimizer::Config config;
      config.l1s = l1s;
      config.l1g = 0.7;
      const PathGuidedOptimizer optimizer(config);
      const OptimizationResult closed = optimizer.guidePhase(initial, guide);
      ASSERT_EQ(closed.status, OptimizationStatus::kSuccess) << closed.message;
      // The fixed points are untouched.
      const int first = degree, last = n - 1 - degree;
      EXPECT_EQ(closed.spline.controlPoints().topRows(degree), q0.topRows(degree));
      EXPECT_EQ(closed.spline.controlPoints().bottomRows(degree), q0.bottomRows(degree));

      GuideProblem problem;
      problem.q = q0;
      problem.g = PathGuidedOptimizer::guideSamples(guide, last - first + 1);
      problem.first = first;
      problem.last = last;
      problem.l1s = config.l1s;
      problem.l1g = config.l1g;
      const double closed_cost = config.l1s * closed.cost.smoothness + config.l1g * closed.cost.guide;
      // The gradient vanishes at the closed-form solution.
      Eigen::MatrixX3d grad = Eigen::MatrixX3d::Zero(n, 3);
      smoothnessCost(closed.spline.controlPoints(), first, last, config.l1s, &grad);
      guideCost(closed.spline.controlPoints(), problem.g, first, last, config.l1g, &grad);
      EXPECT_LT(grad.middleRows(first, last - first + 1).cwiseAbs().maxCoeff(), 1e-9);

      std::vector<double> x(size_t(3 * (last - first + 1)));
      for (int i = first; i <= last; ++i)
        for (int c = 0; c < 3; ++c) x[size_t(3 * (i - first) + c)] = q0(i, c);  // start from the initial spline
      nlopt::opt opt(nlopt::LD_LBFGS, unsigned(x.size()));
      opt.set_min_objective(&GuideProblem::objective, &problem);
      opt.set_maxeval(20000);
      opt.set_ftol_rel(1e-15);
      opt.set_xtol_rel(1e-12);
      double f = 0.0;
      try {
        opt.optimize(x, f);
      } catch (const nlopt::roundoff_limited&) {
        // converged to machine precision
      }
      f = GuideProblem::objective(unsigned(x.size()), x.data(), nullptr, &problem);
      EXPECT_NEAR(f, closed_cost, 1e-8 * (1.0 + closed_cost));
      EXPECT_LE(closed_cost, f + 1e-10);
      double max_diff = 0.0;
      for (int i = first; i <= last; ++i)
        for (int c = 0; c < 3; ++c)
          max_diff = std::max(max_diff, std::abs(x[size_t(3 * (i - first) + c)] - closed.spline.controlPoints()(i, c)));
      EXPECT_LT(max_diff, 1e-4) << "degree " << degree << " l1s " << l1s;
    }
  }
}

TEST(GuidePhase, GuideSamplesAreUniformInArcLength) {
  const Path guide{{0, 0, 0}, {3, 0, 0}, {3, 4, 0}};
  const Eigen::MatrixX3d g = PathGuidedOptimizer::guideSamples(guide, 6);  // arc lengths 1..6 of 7
  ASSERT_EQ(g.rows(), 6);
  EXPECT_LT((g.row(0) - Eigen::RowVector3d(1, 0, 0)).norm(), 1e-12);
  EXPECT_LT((g.row(2) - Eigen::RowVector3d(3, 0, 0)).norm(), 1e-12);
  EXPECT_LT((g.row(5) - Eigen::RowVector3d(3, 3, 0)).norm(), 1e-12);
  const Eigen::MatrixX3d one = PathGuidedOptimizer::guideSamples({{1, 2, 3}}, 3);
  EXPECT_EQ(one.row(2), Eigen::RowVector3d(1, 2, 3));
}

}  // namespace
}  // namespace topo_planner
