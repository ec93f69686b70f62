#include "topo_planner/bspline_opt/uniform_bspline.h"

#include <Eigen/LU>
#include <algorithm>
#include <cassert>
#include <cmath>

namespace topo_planner {
namespace {

// 5-point Gauss-Legendre rule on [0, 1]: exact for polynomials up to degree 9.
constexpr int kGaussPoints = 5;
constexpr double kGaussNodes[kGaussPoints] = {0.5 - 0.5 * 0.9061798459386640, 0.5 - 0.5 * 0.5384693101056831, 0.5,
                                              0.5 + 0.5 * 0.5384693101056831, 0.5 + 0.5 * 0.9061798459386640};
constexpr double kGaussWeights[kGaussPoints] = {0.5 * 0.2369268850561891, 0.5 * 0.4786286704993665,
                                                0.5 * 0.5688888888888889, 0.5 * 0.4786286704993665,
                                                0.5 * 0.2369268850561891};

// De Boor-Cox basis of one segment on integer knots (The NURBS Book, A2.2): with the segment on
// [0, 1], left[j] = u + j - 1 and right[j] = j - u, so every denominator is j.
void basisInto(int degree, double u, double* n) {
  double left[UniformBspline::kMaxDegree + 1], right[UniformBspline::kMaxDegree + 1];
  n[0] = 1.0;
  for (int j = 1; j <= degree; ++j) {
    left[j] = u + j - 1;
    right[j] = j - u;
    double saved = 0.0;
    for (int r = 0; r < j; ++r) {
      const double temp = n[r] / j;
      n[r] = saved + right[r + 1] * temp;
      saved = left[j - r] * temp;
    }
    n[j] = saved;
  }
}

}  // namespace

bool UniformBspline::isValid(std::string* why) const {
  auto fail = [&](const char* reason) {
    if (why) *why = reason;
    return false;
  };
  if (degree_ < 1 || degree_ > kMaxDegree) return fail("degree outside [1, kMaxDegree]");
  if (control_points_.rows() < degree_ + 1) return fail("fewer control points than degree + 1");
  if (!std::isfinite(knot_span_s_) || knot_span_s_ <= 0.0) return fail("knot span not finite and positive");
  if (!control_points_.allFinite()) return fail("control points not finite");
  return true;
}

Eigen::VectorXd UniformBspline::basis(int degree, double u) {
  assert(degree >= 0 && degree <= kMaxDegree);
  Eigen::VectorXd n(degree + 1);
  basisInto(degree, u, n.data());
  return n;
}

Eigen::Vector3d UniformBspline::evaluate(double t) const {
  assert(isValid());
  const int segments = numSegments();
  double s = t / knot_span_s_;
  s = s > 0.0 ? std::min(s, double(segments)) : 0.0;  // clamped; NaN gives the start
  const int k = std::min(int(s), segments - 1);
  double n[kMaxDegree + 1];
  basisInto(degree_, s - k, n);
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int j = 0; j <= degree_; ++j) p += n[j] * control_points_.row(k + j).transpose();
  return p;
}

UniformBspline UniformBspline::derivative() const {
  assert(degree_ >= 1 && control_points_.rows() >= 2);
  const int n = numControlPoints();
  Eigen::MatrixX3d d = (control_points_.bottomRows(n - 1) - control_points_.topRows(n - 1)) / knot_span_s_;
  return UniformBspline(d, degree_ - 1, knot_span_s_);
}

double UniformBspline::arcLength() const {
  assert(isValid());
  if (degree_ < 1) return 0.0;
  const UniformBspline vel = derivative();
  const double dt = knot_span_s_;
  double length = 0.0;
  for (int k = 0; k < numSegments(); ++k)
    for (int half = 0; half < 2; ++half)
      for (int g = 0; g < kGaussPoints; ++g) {
        const double t = (k + 0.5 * (half + kGaussNodes[g])) * dt;
        length += 0.5 * dt * kGaussWeights[g] * vel.evaluate(t).norm();
      }
  return length;
}

double UniformBspline::jerkIntegral() const {
  assert(isValid());
  if (degree_ < 3) return 0.0;
  const UniformBspline jerk = derivative().derivative().derivative();
  const double dt = knot_span_s_;
  double integral = 0.0;
  double n[kMaxDegree + 1];
  for (int k = 0; k < numSegments(); ++k)
    for (int g = 0; g < kGaussPoints; ++g) {
      basisInto(jerk.degree_, kGaussNodes[g], n);
      Eigen::Vector3d j = Eigen::Vector3d::Zero();
      for (int i = 0; i <= jerk.degree_; ++i) j += n[i] * jerk.control_points_.row(k + i).transpose();
      integral += dt * kGaussWeights[g] * j.squaredNorm();
    }
  return integral;
}

double UniformBspline::maxDifferenceNorm(int order, bool past_start) const {
  const int n = numControlPoints();
  if (n <= order) return 0.0;
  // Binomial coefficients with alternating signs: the order-th forward difference.
  double coeff[kMaxDegree + 2];
  coeff[0] = 1.0;
  for (int j = 1; j <= order; ++j) {
    coeff[j] = 0.0;
    for (int m = j; m >= 1; --m) coeff[m] -= coeff[m - 1];
  }
  double best_sq = 0.0;
  for (int i = 0; i + order < n; ++i) {
    // Difference i reads control points i..i + order: all among the first degree_ ones?
    if (past_start && i + order < degree_) continue;
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    for (int j = 0; j <= order; ++j) d += coeff[j] * control_points_.row(i + order - j).transpose();
    best_sq = std::max(best_sq, d.squaredNorm());
  }
  return std::sqrt(best_sq) / std::pow(knot_span_s_, order);
}

double UniformBspline::maxVelocity() const { return degree_ >= 1 ? maxDifferenceNorm(1) : 0.0; }

double UniformBspline::maxAcceleration() const { return degree_ >= 2 ? maxDifferenceNorm(2) : 0.0; }

double UniformBspline::maxVelocityPastStart() const { return degree_ >= 1 ? maxDifferenceNorm(1, true) : 0.0; }

double UniformBspline::maxAccelerationPastStart() const { return degree_ >= 2 ? maxDifferenceNorm(2, true) : 0.0; }

double UniformBspline::reallocateTime(double max_vel_mps, double max_acc_mps2, bool exempt_start) {
  assert(isValid() && max_vel_mps > 0.0 && max_acc_mps2 > 0.0);
  const auto vel = [&] { return maxDifferenceNorm(1, exempt_start); };
  const auto acc = [&] { return degree_ >= 2 ? maxDifferenceNorm(2, exempt_start) : 0.0; };
  double ratio = std::max({1.0, vel() / max_vel_mps, std::sqrt(acc() / max_acc_mps2)});
  if (ratio <= 1.0) return 1.0;
  const double dt0 = knot_span_s_;
  knot_span_s_ = dt0 * ratio;
  // The closed-form ratio can miss the limit by an ulp; lengthen by a hair until it does not.
  while (vel() > max_vel_mps || acc() > max_acc_mps2) {
    ratio *= 1.0 + 1e-12;
    knot_span_s_ = dt0 * ratio;
  }
  return ratio;
}

bool UniformBspline::easeIntoStretch(double ratio, double ease_s, UniformBspline* out) const {
  assert(out);
  if (!isValid() || !(ratio >= 1.0) || !std::isfinite(ratio) || !(ease_s > 0.0) || !std::isfinite(ease_s)) return false;
  const double duration = this->duration();
  // Warped time tau(t) = t + (ratio - 1) W(t), W' = 1 - smoothstep(t / ease_s): tau'(0) = ratio,
  // tau''(0) = 0, tau' = 1 from ease_s on, where W = ease_s / 2.
  const double gain = ratio - 1.0;
  const double end = duration - gain * 0.5 * ease_s;  // tau(end) = duration
  if (!(end >= ease_s)) return false;
  const auto tau = [&](double t) {
    if (t >= ease_s) return t + gain * 0.5 * ease_s;
    const double x = t / ease_s;
    return t + gain * (t - ease_s * (x * x * x - 0.5 * x * x * x * x));
  };
  const int segments = std::max(1, int(std::ceil(end / knot_span_s_ - 1e-9)));
  const double dt = end / segments;
  std::vector<Eigen::Vector3d> points;
  points.reserve(size_t(segments) + 1);
  for (int k = 0; k <= segments; ++k) points.push_back(evaluate(std::min(duration, tau(k * dt))));
  const UniformBspline vel = derivative(), acc = vel.derivative();
  return fitToPoints(points, dt, ratio * vel.evaluate(0.0), ratio * ratio * acc.evaluate(0.0), vel.evaluate(duration),
                     acc.evaluate(duration), degree_, out);
}

bool UniformBspline::fitToPoints(const std::vector<Eigen::Vector3d>& points, double interval_s,
                                 const Eigen::Vector3d& start_vel, const Eigen::Vector3d& start_acc,
                                 const Eigen::Vector3d& end_vel, const Eigen::Vector3d& end_acc, int degree,
                                 UniformBspline* out) {
  assert(out);
  if (degree < 2 || degree > kMaxDegree || !std::isfinite(interval_s) || interval_s <= 0.0) return false;
  if (points.size() < 2) return false;
  for (const Eigen::Vector3d& p : points)
    if (!p.allFinite()) return false;
  if (!start_vel.allFinite() || !start_acc.allFinite() || !end_vel.allFinite() || !end_acc.allFinite()) return false;
  const int p = degree;
  const int segments = int(points.size()) - 1;  // K
  const int n = segments + p;                   // control points
  if (n < 6) return false;
  const double dt = interval_s;

  // Rows are scaled to metres (velocity rows times dt, acceleration rows times dt^2) so that the
  // pivoting sees comparable magnitudes.
  double b[kMaxDegree + 1];
  // Constraints C Q = d: start position, velocity, acceleration; end position, velocity, acceleration.
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(6, n);
  Eigen::MatrixXd d(6, 3);
  basisInto(p, 0.0, b);
  for (int j = 0; j <= p; ++j) c(0, j) += b[j];
  basisInto(p - 1, 0.0, b);
  for (int j = 0; j < p; ++j) c(1, j + 1) += b[j], c(1, j) -= b[j];
  basisInto(p - 2, 0.0, b);
  for (int j = 0; j < p - 1; ++j) c(2, j + 2) += b[j], c(2, j + 1) -= 2.0 * b[j], c(2, j) += b[j];
  const int last = segments - 1;  // the end state is at u = 1 of the last segment
  basisInto(p, 1.0, b);
  for (int j = 0; j <= p; ++j) c(3, last + j) += b[j];
  basisInto(p - 1, 1.0, b);
  for (int j = 0; j < p; ++j) c(4, last + j + 1) += b[j], c(4, last + j) -= b[j];
  basisInto(p - 2, 1.0, b);
  for (int j = 0; j < p - 1; ++j)
    c(5, last + j + 2) += b[j], c(5, last + j + 1) -= 2.0 * b[j], c(5, last + j) += b[j];
  d.row(0) = points.front().transpose();
  d.row(1) = (start_vel * dt).transpose();
  d.row(2) = (start_acc * dt * dt).transpose();
  d.row(3) = points.back().transpose();
  d.row(4) = (end_vel * dt).transpose();
  d.row(5) = (end_acc * dt * dt).transpose();

  // Least squares on the interior points: position at knot k is sum_j N_j(0) Q_{k+j}.
  const int interior = std::max(0, segments - 1);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(interior, n);
  Eigen::MatrixXd target(interior, 3);
  basisInto(p, 0.0, b);
  for (int k = 1; k <= interior; ++k) {
    for (int j = 0; j <= p; ++j) a(k - 1, k + j) = b[j];
    target.row(k - 1) = points[size_t(k)].transpose();
  }

  // KKT system [A^T A  C^T; C  0] [Q; mu] = [A^T P; d].
  Eigen::MatrixXd kkt = Eigen::MatrixXd::Zero(n + 6, n + 6);
  kkt.topLeftCorner(n, n) = a.transpose() * a;
  kkt.topRightCorner(n, 6) = c.transpose();
  kkt.bottomLeftCorner(6, n) = c;
  Eigen::MatrixXd rhs(n + 6, 3);
  rhs.topRows(n) = a.transpose() * target;
  rhs.bottomRows(6) = d;
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(kkt);
  if (!lu.isInvertible()) return false;
  const Eigen::MatrixXd solution = lu.solve(rhs);
  if (!solution.allFinite()) return false;
  *out = UniformBspline(solution.topRows(n), p, dt);
  return true;
}

UniformBspline UniformBspline::straightLine(const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                                            int num_control_points, int degree, double knot_span_s) {
  assert(degree >= 1 && num_control_points >= 2 * degree);
  Eigen::MatrixX3d q(num_control_points, 3);
  const int steps = num_control_points - 2 * (degree - 1) - 1;  // gaps between the evenly spaced points
  for (int i = 0; i < num_control_points; ++i) {
    const double s = std::clamp(double(i - (degree - 1)) / steps, 0.0, 1.0);
    q.row(i) = (start + s * (goal - start)).transpose();
  }
  return UniformBspline(q, degree, knot_span_s);
}

}  // namespace topo_planner
