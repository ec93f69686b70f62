// Uniform B-spline: evaluation against the textbook recursion, derivatives against finite
// differences, exact jerk integral, fitting, time reallocation.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "topo_planner/bspline_opt/uniform_bspline.h"

namespace topo_planner {
namespace {

Eigen::MatrixX3d randomControlPoints(int n, uint32_t seed, double scale = 2.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-scale, scale);
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) q(i, c) = u(rng);
  return q;
}

// Cox-de Boor on the global knot vector t_m = m dt: an oracle independent of the segment-local code.
double coxDeBoor(int i, int p, double t, double dt) {
  if (p == 0) return (t >= i * dt && t < (i + 1) * dt) ? 1.0 : 0.0;
  const double a = (t - i * dt) / (p * dt), b = ((i + p + 1) * dt - t) / (p * dt);
  return a * coxDeBoor(i, p - 1, t, dt) + b * coxDeBoor(i + 1, p - 1, t, dt);
}

TEST(UniformBspline, BasisIsPartitionOfUnityAndCubicValuesAreTextbook) {
  const Eigen::VectorXd b0 = UniformBspline::basis(3, 0.0);
  EXPECT_NEAR(b0(0), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(b0(1), 4.0 / 6.0, 1e-15);
  EXPECT_NEAR(b0(2), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(b0(3), 0.0, 1e-15);
  for (int p = 0; p <= UniformBspline::kMaxDegree; ++p)
    for (double u : {0.0, 0.1, 0.37, 0.5, 0.99, 1.0}) {
      const Eigen::VectorXd b = UniformBspline::basis(p, u);
      EXPECT_NEAR(b.sum(), 1.0, 1e-13);
      EXPECT_GE(b.minCoeff(), -1e-15);
    }
}

TEST(UniformBspline, EvaluateMatchesCoxDeBoorRecursion) {
  for (int p = 1; p <= 5; ++p) {
    const Eigen::MatrixX3d q = randomControlPoints(12, 10 + p);
    const double dt = 0.37;
    const UniformBspline s(q, p, dt);
    ASSERT_TRUE(s.isValid());
    EXPECT_NEAR(s.duration(), (12 - p) * dt, 1e-12);
    for (int k = 0; k <= 200; ++k) {
      const double t = s.duration() * k / 200.0 * 0.999999;  // stay inside the half-open last knot interval
      const double global = t + p * dt;                     // the domain starts at knot t_p
      Eigen::Vector3d expected = Eigen::Vector3d::Zero();
      for (int i = 0; i < 12; ++i) expected += coxDeBoor(i, p, global, dt) * q.row(i).transpose();
      EXPECT_LT((s.evaluate(t) - expected).norm(), 1e-12) << "p=" << p << " t=" << t;
    }
  }
}

TEST(UniformBspline, DerivativesMatchFiniteDifferencesOfPosition) {
  for (int p = 3; p <= 5; ++p) {
    const UniformBspline s(randomControlPoints(15, 20 + p), p, 0.25);
    const UniformBspline v = s.derivative(), a = v.derivative(), j = a.derivative();
    EXPECT_EQ(v.degree(), p - 1);
    EXPECT_DOUBLE_EQ(v.duration(), s.duration());
    const double h = 1e-4;
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> ut(0.0, s.duration());
    for (int k = 0; k < 100; ++k) {
      const double t = ut(rng);
      // Stay away from the knots, where the jerk of a cubic jumps.
      const double frac = t / s.knotSpan() - std::floor(t / s.knotSpan());
      if (frac < 0.05 || frac > 0.95) continue;
      const Eigen::Vector3d fd_v = (s.evaluate(t + h) - s.evaluate(t - h)) / (2 * h);
      const Eigen::Vector3d fd_a = (s.evaluate(t + h) - 2 * s.evaluate(t) + s.evaluate(t - h)) / (h * h);
      const Eigen::Vector3d fd_j = (a.evaluate(t + h) - a.evaluate(t - h)) / (2 * h);
      EXPECT_LT((v.evaluate(t) - fd_v).norm(), 1e-6 * (1 + fd_v.norm()));
      EXPECT_LT((a.evaluate(t) - fd_a).norm(), 1e-3 * (1 + fd_a.norm()));
      EXPECT_LT((j.evaluate(t) - fd_j).norm(), 1e-6 * (1 + fd_j.norm()));
    }
  }
}

TEST(UniformBspline, JerkIntegralOfKnownControlPointsIsAnalytic) {
  // Cubic, Q_i = (i^3, 2 i^3, 0): the third difference is 6 (1, 2, 0), so the jerk is the constant
  // 6 (1, 2, 0) / dt^3 and the integral is 36 * 5 / dt^6 * duration.
  const int n = 10;
  const double dt = 0.5;
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i) q.row(i) << std::pow(i, 3), 2 * std::pow(i, 3), 0.0;
  const UniformBspline cubic(q, 3, dt);
  EXPECT_NEAR(cubic.jerkIntegral(), 36.0 * 5.0 / std::pow(dt, 6) * cubic.duration(), 1e-9);

  // Quartic: the jerk is piecewise linear, J(u) = (1 - u) a + u b on a segment, whose squared
  // integral is (|a|^2 + a.b + |b|^2) / 3 per unit of u.
  const UniformBspline quartic(randomControlPoints(12, 3), 4, 0.3);
  const UniformBspline jerk = quartic.derivative().derivative().derivative();
  double expected = 0.0;
  for (int k = 0; k < quartic.numSegments(); ++k) {
    const Eigen::Vector3d a = jerk.controlPoints().row(k), b = jerk.controlPoints().row(k + 1);
    expected += quartic.knotSpan() * (a.squaredNorm() + a.dot(b) + b.squaredNorm()) / 3.0;
  }
  EXPECT_NEAR(quartic.jerkIntegral(), expected, 1e-9 * expected);

  // Evenly spaced collinear control points: a line at constant speed (B-splines reproduce linear
  // functions), no jerk.
  Eigen::MatrixX3d line(n, 3);
  for (int i = 0; i < n; ++i) line.row(i) << i, 2.0 * i, -0.5 * i;
  EXPECT_NEAR(UniformBspline(line, 3, dt).jerkIntegral(), 0.0, 1e-12);
  EXPECT_NEAR(UniformBspline(line, 5, dt).jerkIntegral(), 0.0, 1e-12);
}

TEST(UniformBspline, ArcLength) {
  // Straight rest-to-rest line: exactly the distance.
  const UniformBspline line = UniformBspline::straightLine({0, 0, 1}, {3, 4, 1}, 20, 3, 0.2);
  EXPECT_NEAR(line.arcLength(), 5.0, 1e-9);
  // A random curve: against a dense polyline.
  const UniformBspline s(randomControlPoints(10, 8), 3, 0.4);
  double poly = 0.0;
  const int samples = 200000;
  for (int k = 1; k <= samples; ++k)
    poly += (s.evaluate(s.duration() * k / samples) - s.evaluate(s.duration() * (k - 1) / samples)).norm();
  EXPECT_NEAR(s.arcLength(), poly, 1e-5 * poly);
}

TEST(UniformBspline, StraightLineIsRestToRest) {
  const UniformBspline s = UniformBspline::straightLine({1, 2, 3}, {7, 2, 3}, 25, 3, 0.3);
  ASSERT_TRUE(s.isValid());
  EXPECT_LT((s.evaluate(0.0) - Eigen::Vector3d(1, 2, 3)).norm(), 1e-12);
  EXPECT_LT((s.evaluate(s.duration()) - Eigen::Vector3d(7, 2, 3)).norm(), 1e-12);
  const UniformBspline v = s.derivative(), a = v.derivative();
  EXPECT_LT(v.evaluate(0.0).norm(), 1e-12);
  EXPECT_LT(a.evaluate(0.0).norm(), 1e-12);
  EXPECT_LT(v.evaluate(s.duration()).norm(), 1e-12);
  EXPECT_LT(a.evaluate(s.duration()).norm(), 1e-12);
}

TEST(UniformBspline, FitReproducesBoundaryStatesAndFollowsThePoints) {
  // Samples of a smooth curve x(t) = (t, sin t, 0.1 t^2) every 0.1 s; its true boundary states.
  auto pos = [](double t) { return Eigen::Vector3d(t, std::sin(t), 0.1 * t * t); };
  auto vel = [](double t) { return Eigen::Vector3d(1.0, std::cos(t), 0.2 * t); };
  auto acc = [](double t) { return Eigen::Vector3d(0.0, -std::sin(t), 0.2); };
  const double ts = 0.1, duration = 3.0;
  std::vector<Eigen::Vector3d> points;
  for (int k = 0; k <= 30; ++k) points.push_back(pos(k * ts));
  for (int degree : {3, 4, 5}) {
    UniformBspline s;
    ASSERT_TRUE(UniformBspline::fitToPoints(points, ts, vel(0), acc(0), vel(duration), acc(duration), degree, &s));
    EXPECT_EQ(s.numControlPoints(), 30 + degree);
    EXPECT_NEAR(s.duration(), duration, 1e-12);
    const UniformBspline v = s.derivative(), a = v.derivative();
    EXPECT_LT((s.evaluate(0) - pos(0)).norm(), 1e-9);
    EXPECT_LT((v.evaluate(0) - vel(0)).norm(), 1e-8);
    EXPECT_LT((a.evaluate(0) - acc(0)).norm(), 1e-7);
    EXPECT_LT((s.evaluate(duration) - pos(duration)).norm(), 1e-9);
    EXPECT_LT((v.evaluate(duration) - vel(duration)).norm(), 1e-8);
    EXPECT_LT((a.evaluate(duration) - acc(duration)).norm(), 1e-7);
    for (int k = 0; k <= 30; ++k) EXPECT_LT((s.evaluate(k * ts) - points[size_t(k)]).norm(), 2e-3) << k;
  }
  // Different boundary states than the samples suggest are still met exactly.
  UniformBspline s;
  ASSERT_TRUE(UniformBspline::fitToPoints(points, ts, {0, 0, 0}, {0, 0, 0}, {0.5, 0, 0}, {0, 1, 0}, 3, &s));
  EXPECT_LT(s.derivative().evaluate(0).norm(), 1e-8);
  EXPECT_LT(s.derivative().derivative().evaluate(0).norm(), 1e-7);
  EXPECT_LT((s.derivative().evaluate(duration) - Eigen::Vector3d(0.5, 0, 0)).norm(), 1e-8);
  EXPECT_LT((s.derivative().derivative().evaluate(duration) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-7);
}

TEST(UniformBspline, FitRefusesBadInput) {
  const Eigen::Vector3d z = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> points{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  UniformBspline s;
  EXPECT_TRUE(UniformBspline::fitToPoints(points, 0.5, z, z, z, z, 3, &s));  // 4 points: 6 control points
  const UniformBspline kept = s;
  EXPECT_FALSE(UniformBspline::fitToPoints({points[0], points[1], points[2]}, 0.5, z, z, z, z, 3, &s));  // too few
  EXPECT_FALSE(UniformBspline::fitToPoints(points, 0.0, z, z, z, z, 3, &s));
  EXPECT_FALSE(UniformBspline::fitToPoints(points, -1.0, z, z, z, z, 3, &s));
  EXPECT_FALSE(UniformBspline::fitToPoints(points, 0.5, z, z, z, z, 1, &s));
  points[1].x() = NAN;
  EXPECT_FALSE(UniformBspline::fitToPoints(points, 0.5, z, z, z, z, 3, &s));
  EXPECT_EQ(s.controlPoints(), kept.controlPoints());
}

TEST(UniformBspline, TimeReallocationBringsTooFastSplineWithinLimitsWithoutMovingThePath) {
  const double max_vel = 3.0, max_acc = 2.5;
  for (uint32_t seed = 0; seed < 5; ++seed) {
    const UniformBspline original(randomControlPoints(20, 100 + seed, 3.0), 3, 0.1);
    ASSERT_TRUE(original.maxVelocity() > max_vel || original.maxAcceleration() > max_acc);
    UniformBspline s = original;
    const double ratio = s.reallocateTime(max_vel, max_acc);
    EXPECT_GT(ratio, 1.0);
    EXPECT_EQ(s.controlPoints(), original.controlPoints());  // same path
    EXPECT_NEAR(s.knotSpan(), original.knotSpan() * ratio, 1e-15);
    EXPECT_LE(s.maxVelocity(), max_vel);
    EXPECT_LE(s.maxAcceleration(), max_acc);
    // The smallest ratio: one of the limits is reached.
    EXPECT_TRUE(std::abs(s.maxVelocity() - max_vel) < 1e-9 || std::abs(s.maxAcceleration() - max_acc) < 1e-9);
    // Along the curve (convex hull bound) and at the same normalised times, the same points.
    const UniformBspline v = s.derivative(), a = v.derivative();
    for (int k = 0; k <= 1000; ++k) {
      const double f = k / 1000.0;
      EXPECT_LE(v.evaluate(f * s.duration()).norm(), max_vel + 1e-9);
      EXPECT_LE(a.evaluate(f * s.duration()).norm(), max_acc + 1e-9);
      EXPECT_LT((s.evaluate(f * s.duration()) - original.evaluate(f * original.duration())).norm(), 1e-9);
    }
    // Already within the limits: nothing changes.
    EXPECT_EQ(s.reallocateTime(max_vel, max_acc), 1.0);
  }
}

// A cruising spline slowed down by a stretch of its time, eased back into its old pace at the start:
// the start velocity and acceleration from before the stretch, the same path, the stretched end.
TEST(UniformBspline, EaseIntoStretchKeepsTheStartPaceAndThePath) {
  const double dt = 0.2;
  std::vector<Eigen::Vector3d> points;
  for (int k = 0; k <= 25; ++k) {
    const double t = k * dt;
    points.emplace_back(2.0 * t, 1.5 * std::sin(t), 0.3 * t);
  }
  UniformBspline original;
  ASSERT_TRUE(UniformBspline::fitToPoints(points, dt, Eigen::Vector3d(2.0, 1.5, 0.3), Eigen::Vector3d::Zero(),
                                          Eigen::Vector3d(2.0, 1.5 * std::cos(5.0), 0.3),
                                          Eigen::Vector3d(0.0, -1.5 * std::sin(5.0), 0.0), 3, &original));
  const double ratio = 1.4, ease_s = 1.0;
  const UniformBspline stretched(original.controlPoints(), 3, dt * ratio);
  UniformBspline eased;
  ASSERT_TRUE(stretched.easeIntoStretch(ratio, ease_s, &eased));
  const UniformBspline ov = original.derivative(), sv = stretched.derivative(), ev = eased.derivative();
  EXPECT_LT((ev.evaluate(0.0) - ov.evaluate(0.0)).norm(), 1e-6);  // the old pace at the start
  EXPECT_LT((ev.derivative().evaluate(0.0) - ov.derivative().evaluate(0.0)).norm(), 1e-6);
  EXPECT_GT((sv.evaluate(0.0) - ov.evaluate(0.0)).norm(), 0.5);  // what the stretch had made of it
  EXPECT_NEAR(eased.duration(), stretched.duration() - (ratio - 1.0) * 0.5 * ease_s, 1e-9);
  EXPECT_LT((eased.evaluate(eased.duration()) - stretched.evaluate(stretched.duration())).norm(), 1e-9);
  EXPECT_LT((ev.evaluate(eased.duration()) - sv.evaluate(stretched.duration())).norm(), 1e-6);
  EXPECT_LE(eased.knotSpan(), stretched.knotSpan());
  // The same path: every point of the eased spline lies on the original one (dense samples).
  std::vector<Eigen::Vector3d> path;
  for (int k = 0; k <= 5000; ++k) path.push_back(original.evaluate(original.duration() * k / 5000.0));
  double worst = 0.0;
  for (int k = 0; k <= 500; ++k) {
    const Eigen::Vector3d p = eased.evaluate(eased.duration() * k / 500.0);
    double nearest = INFINITY;
    for (const Eigen::Vector3d& q : path) nearest = std::min(nearest, (p - q).norm());
    worst = std::max(worst, nearest);
  }
  EXPECT_LT(worst, 0.02);
  // After the easing, the stretched pace, (ratio - 1) * ease_s / 2 ahead of the stretched clock.
  for (double t = ease_s + 0.5; t < eased.duration() - 0.5; t += 0.25)
    EXPECT_LT((ev.evaluate(t) - sv.evaluate(t + (ratio - 1.0) * 0.5 * ease_s)).norm(), 0.1) << t;
  // Refused: no stretch to undo, a bad easing time, a spline too short to ease over.
  UniformBspline untouched = eased;
  EXPECT_FALSE(stretched.easeIntoStretch(0.9, ease_s, &untouched));
  EXPECT_FALSE(stretched.easeIntoStretch(ratio, std::nan(""), &untouched));
  EXPECT_FALSE(stretched.easeIntoStretch(ratio, 0.0, &untouched));
  EXPECT_FALSE(stretched.easeIntoStretch(INFINITY, ease_s, &untouched));
  EXPECT_FALSE(stretched.easeIntoStretch(ratio, 100.0, &untouched));
  EXPECT_EQ(untouched.controlPoints(), eased.controlPoints());
}

// The bounds past the start leave out the difference control points computed from the first
// degree() control points alone (for a cubic: V0, V1 and A0, fixed by the start state).
TEST(UniformBspline, BoundsPastTheStartLeaveOutTheStartsControlPoints) {
  for (uint32_t seed = 0; seed < 5; ++seed) {
    const UniformBspline s(randomControlPoints(12, 300 + seed, 2.0), 3, 0.2);
    const Eigen::MatrixX3d& q = s.controlPoints();
    const int n = int(q.rows());
    double vel = 0.0, acc = 0.0;
    for (int i = 2; i + 1 < n; ++i) vel = std::max(vel, (q.row(i + 1) - q.row(i)).norm() / 0.2);
    for (int i = 1; i + 2 < n; ++i) acc = std::max(acc, (q.row(i + 2) - 2.0 * q.row(i + 1) + q.row(i)).norm() / 0.04);
    EXPECT_NEAR(s.maxVelocityPastStart(), vel, 1e-9);
    EXPECT_NEAR(s.maxAccelerationPastStart(), acc, 1e-9);
    EXPECT_LE(s.maxVelocityPastStart(), s.maxVelocity());
    EXPECT_LE(s.maxAccelerationPastStart(), s.maxAcceleration());
  }
  // A start far faster than the rest: only the exempt reallocation leaves the knot span alone.
  Eigen::MatrixX3d q = Eigen::MatrixX3d::Zero(10, 3);
  for (int i = 0; i < 10; ++i) q(i, 0) = i < 2 ? 0.5 * i : 0.5 + 0.1 * (i - 1);  // V0 = 5 m/s, then 1 m/s
  UniformBspline fast_start(q, 3, 0.1);
  EXPECT_NEAR(fast_start.maxVelocity(), 5.0, 1e-9);
  EXPECT_NEAR(fast_start.maxVelocityPastStart(), 1.0, 1e-9);
  EXPECT_EQ(fast_start.reallocateTime(3.0, 100.0, true), 1.0);
  EXPECT_GT(fast_start.reallocateTime(3.0, 100.0), 1.6);
}

TEST(UniformBspline, Validity) {
  const Eigen::MatrixX3d q = randomControlPoints(8, 1);
  std::string why;
  EXPECT_TRUE(UniformBspline(q, 3, 0.1).isValid(&why));
  EXPECT_FALSE(UniformBspline(q, 3, 0.0).isValid(&why));
  EXPECT_FALSE(UniformBspline(q, 3, -0.1).isValid(&why));
  EXPECT_FALSE(UniformBspline(q, 3, NAN).isValid(&why));
  EXPECT_FALSE(UniformBspline(q.topRows(3), 3, 0.1).isValid(&why));
  EXPECT_FALSE(UniformBspline(q, 0, 0.1).isValid(&why));
  EXPECT_FALSE(UniformBspline(q, UniformBspline::kMaxDegree + 1, 0.1).isValid(&why));
  Eigen::MatrixX3d bad = q;
  bad(4, 1) = NAN;
  EXPECT_FALSE(UniformBspline(bad, 3, 0.1).isValid(&why));
  EXPECT_FALSE(UniformBspline().isValid(&why));
}

}  // namespace
}  // namespace topo_planner
