#pragma once
// Uniform B-spline trajectory in 3-D, the representation of the paper's Sect. III-B (after Zhou et
// al., "Robust and Efficient Quadrotor Trajectory Generation for Fast Autonomous Flight", RA-L 2019).
//
// A degree-p spline with control points Q_0..Q_N and knot span dt has the knots t_m = m * dt,
// m = 0..N+p+1; it is defined on [t_p, t_{N+1}], which this class shifts to [0, duration()] with
// duration() = (N + 1 - p) * dt. Segment k (t in [k dt, (k+1) dt]) is sum_j N_j(u) Q_{k+j}, j = 0..p,
// u = t / dt - k, with the uniform basis N_j of de Boor-Cox.
//
// Derivatives are B-splines again: V_i = (Q_{i+1} - Q_i) / dt, degree p - 1, same knot span and the
// same time interval. By the convex hull property, ||v(t)|| <= max_i ||V_i|| and
// ||a(t)|| <= max_i ||A_i||, which is what maxVelocity() / maxAcceleration() return: bounds that the
// curve never exceeds (exact at the knots for the acceleration of a cubic, which is piecewise linear).
//
// Plain value, cheap to copy; no state beyond the control points, the degree and the knot span.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace topo_planner {

class UniformBspline {
 public:
  /// Highest supported degree (the exact quadratures below are tabulated up to it).
  static constexpr int kMaxDegree = 7;

  UniformBspline() = default;
  /// Any values are accepted; isValid() tells whether they make a spline (the optimizer turns an
  /// invalid one into kInvalidInput). control_points has one control point per row.
  UniformBspline(const Eigen::MatrixX3d& control_points, int degree, double knot_span_s)
      : control_points_(control_points), degree_(degree), knot_span_s_(knot_span_s) {}

  /// True for 1 <= degree <= kMaxDegree, at least degree + 1 control points, all finite, and a
  /// finite positive knot span; otherwise says why.
  bool isValid(std::string* why = nullptr) const;

  const Eigen::MatrixX3d& controlPoints() const { return control_points_; }
  Eigen::MatrixX3d& controlPoints() { return control_points_; }
  int numControlPoints() const { return int(control_points_.rows()); }
  int degree() const { return degree_; }
  double knotSpan() const { return knot_span_s_; }
  void setKnotSpan(double knot_span_s) { knot_span_s_ = knot_span_s; }
  /// Number of polynomial segments, N + 1 - p.
  int numSegments() const { return numControlPoints() - degree_; }
  /// (N + 1 - p) * dt [s].
  double duration() const { return numSegments() * knot_span_s_; }

  /// Position at time t in [0, duration()] (clamped to it). Precondition: isValid().
  Eigen::Vector3d evaluate(double t) const;
  /// The derivative spline: control points (Q_{i+1} - Q_i) / dt, degree p - 1, same knot span.
  /// Precondition: degree() >= 1.
  UniformBspline derivative() const;

  /// Length of the curve [m]: 5-point Gauss-Legendre quadrature of the speed on each half segment
  /// (exact for straight lines traversed without reversal).
  double arcLength() const;
  /// Exact integral of the squared jerk over the duration [m^2/s^5] (the paper's smoothness metric):
  /// the jerk spline has degree p - 3 and is integrated segment by segment with a Gauss-Legendre
  /// rule exact for its square. 0 for degree < 3 (the jerk vanishes between the knots).
  double jerkIntegral() const;

  /// max_i ||V_i|| over the velocity control points: an upper bound of the speed [m/s].
  double maxVelocity() const;
  /// max_i ||A_i|| over the acceleration control points: an upper bound of ||a(t)|| [m/s^2].
  double maxAcceleration() const;

  /// The same bounds without the derivative control points that depend on the first degree()
  /// control points alone (for a cubic: those the start's position, velocity and acceleration fix):
  /// what a curve planned from a given start state can be held to [m/s], [m/s^2].
  double maxVelocityPastStart() const;
  double maxAccelerationPastStart() const;

  /// Time reallocation: when maxVelocity() > max_vel_mps or maxAcceleration() > max_acc_mps2,
  /// lengthens the knot span by the smallest ratio r that brings both within the limits
  /// (velocity scales by 1/r, acceleration by 1/r^2) and returns r; returns 1 and changes nothing
  /// otherwise. The control points, hence the path, are unchanged; boundary velocities and
  /// accelerations scale with the rest. Preconditions: isValid(), positive limits.
  /// With exempt_start, the limits apply to the *PastStart() bounds only (the start state's own
  /// control points may exceed them: they scale with the rest).
  double reallocateTime(double max_vel_mps, double max_acc_mps2, bool exempt_start = false);

  /// Undoes a time reallocation at the start only: this spline was lengthened by `ratio` (e.g. by
  /// reallocateTime()); the result follows the same path, but its clock runs `ratio` times faster
  /// at t = 0 and eases to this spline's pace over `ease_s` (a smoothstep), so it starts with the
  /// velocity and acceleration from before the stretch (ratio * v(0), ratio^2 * a(0)) and ends as
  /// this one does, (ratio - 1) * ease_s / 2 sooner. A fit through the warped positions
  /// (fitToPoints) at a knot span at most this one's. False (out unchanged) when ratio < 1, ease_s
  /// <= 0 or not finite, the spline is too short to ease over, or the fit fails.
  bool easeIntoStretch(double ratio, double ease_s, UniformBspline* out) const;

  /// Basis weights N_0(u)..N_p(u) of one segment of a uniform degree-p spline, u in [0, 1].
  static Eigen::VectorXd basis(int degree, double u);

  /// Fits a degree-p spline to points sampled every interval_s seconds (the first at t = 0), with
  /// the boundary velocities and accelerations: K + 1 points give K segments and K + p control
  /// points. The first and last points and the four boundary derivatives are met exactly
  /// (equality constraints); the interior points in the least-squares sense (one KKT system, solved
  /// once for the three coordinates). Returns false, leaving *out unchanged, when the input is not
  /// finite, interval_s <= 0, degree < 2 or > kMaxDegree, or the points are too few for the six
  /// boundary conditions (K + p >= 6, e.g. at least 4 points for a cubic).
  static bool fitToPoints(const std::vector<Eigen::Vector3d>& points, double interval_s,
                          const Eigen::Vector3d& start_vel, const Eigen::Vector3d& start_acc,
                          const Eigen::Vector3d& end_vel, const Eigen::Vector3d& end_acc, int degree,
                          UniformBspline* out);

  /// A straight rest-to-rest spline: degree copies of start, then interior control points evenly
  /// spaced, then degree copies of goal (derivatives up to order p - 1 vanish at both ends).
  /// Precondition: num_control_points >= 2 * degree, degree >= 1.
  static UniformBspline straightLine(const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                                     int num_control_points, int degree, double knot_span_s);

 private:
  // Largest norm among the rows of the n-th difference of the control points, divided by dt^n;
  // with past_start, leaving out those computed from the first degree() control points alone.
  double maxDifferenceNorm(int order, bool past_start = false) const;

  Eigen::MatrixX3d control_points_;
  int degree_ = 3;
  double knot_span_s_ = 0.0;
};

}  // namespace topo_planner
