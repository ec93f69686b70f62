#pragma once
// Minimum-snap piecewise polynomials through waypoints (Richter, Bry and Roy, "Polynomial
// trajectory planning for aggressive quadrotor flight in dense indoor environments", ISRR 2013):
// the global reference trajectory of the replanner, the one the paper's benchmarks start every
// method from.
//
// Each segment is a degree-7 polynomial in normalised time tau = t / T. The cost is the integral of
// squared snap; written in terms of the derivatives (position to jerk) at the waypoints it is a
// quadratic form, and the free derivatives (velocity, acceleration and jerk at inner waypoints) have
// the closed-form optimum of the unconstrained QP. Positions at all waypoints and the derivatives
// at the two ends are fixed (rest to rest, or a given moving start/end state).

#include <Eigen/Core>
#include <string>
#include <vector>

namespace topo_planner {

/// Position and its first three derivatives at an instant.
struct FlatState {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d acceleration = Eigen::Vector3d::Zero();
  Eigen::Vector3d jerk = Eigen::Vector3d::Zero();

  /// At rest at p (all derivatives zero).
  static FlatState atRest(const Eigen::Vector3d& p) {
    FlatState s;
    s.position = p;
    return s;
  }
  bool allFinite() const {
    return position.allFinite() && velocity.allFinite() && acceleration.allFinite() && jerk.allFinite();
  }
};

enum class TrajectoryStatus {
  kSuccess,
  kInvalidInput,   ///< fewer than 2 waypoints, NaN/inf values, non-positive durations or limits
  kInfeasible,     ///< the limits could not be met within the time-scaling budget
};
const char* toString(TrajectoryStatus status);

class PolynomialTrajectory {
 public:
  static constexpr int kCoefficients = 8;  ///< degree 7
  struct Segment {
    double duration = 0.0;
    /// p(tau) = sum_k coefficients.row(k) * tau^k, tau = t / duration in [0, 1].
    Eigen::Matrix<double, kCoefficients, 3> coefficients = Eigen::Matrix<double, kCoefficients, 3>::Zero();
  };

  PolynomialTrajectory() = default;
  explicit PolynomialTrajectory(std::vector<Segment> segments) : segments_(std::move(segments)) {}

  double duration() const;
  bool empty() const { return segments_.empty(); }
  const std::vector<Segment>& segments() const { return segments_; }

  /// The order-th time derivative at t (clamped to [0, duration()]), order 0 to 4.
  Eigen::Vector3d derivative(double t, int order) const;
  Eigen::Vector3d position(double t) const { return derivative(t, 0); }
  Eigen::Vector3d velocity(double t) const { return derivative(t, 1); }
  Eigen::Vector3d acceleration(double t) const { return derivative(t, 2); }
  FlatState state(double t) const;

  /// Largest speed and acceleration norm, sampled every dt_s.
  double maxSpeed(double dt_s = 0.01) const;
  double maxAcceleration(double dt_s = 0.01) const;
  /// Integral of squared snap (the cost minimised) [m^2/s^7].
  double snapCost() const;

 private:
  std::vector<Segment> segments_;
};

/// Minimum-snap trajectory through waypoints with the given segment durations [s]; start and end
/// states give the end derivatives (their positions must equal the first and last waypoint).
TrajectoryStatus minimumSnapTrajectory(const std::vector<Eigen::Vector3d>& waypoints,
                                       const std::vector<double>& durations, const FlatState& start,
                                       const FlatState& end, PolynomialTrajectory* out);

struct ReferenceConfig {
  double max_vel_mps = 3.0;    ///< speed limit [m/s]
  double max_acc_mps2 = 2.5;   ///< acceleration limit [m/s^2]
  int max_rescales = 30;       ///< budget of time stretches to meet the limits
  /// Longer segments are split by evenly spaced waypoints on the straight line [m]; 0 = never.
  /// With cruise timing this gives a reference that cruises at max_vel_mps instead of the slow
  /// start and end of one long degree-7 segment.
  double max_segment_length_m = 0.0;
  /// Segment times dist / max_vel, plus max_vel / max_acc on the first and last segment (a
  /// trapezoid over the whole path), instead of a rest-to-rest trapezoid per segment.
  bool cruise_timing = false;
  /// Segment times from the time-optimal speed profile along the waypoints (PathSpeedProfile: the
  /// corners as arcs, a forward-backward pass at the limits), and only the segments that break the
  /// limits stretched (a corner slows the reference there, not everywhere). Overrides cruise_timing.
  bool profile_timing = false;
};

/// referenceTrajectory() refuses (kInfeasible) a trajectory stretched longer than this times its first
/// segment times (plus 10 s): no plan to fly, and a loop over its length would take forever.
constexpr double kMaxReferenceStretch = 20.0;

/// Minimum-snap trajectory through waypoints, segment times from a trapezoidal speed profile per
/// segment (or, with profile_timing, from the time-optimal profile along the path), then times
/// stretched until the speed and acceleration limits hold (sampled): all of them, or with
/// profile_timing those of the segments that break the limits (all of them as a last resort).
TrajectoryStatus referenceTrajectory(const std::vector<Eigen::Vector3d>& waypoints, const FlatState& start,
                                     const FlatState& end, const ReferenceConfig& config, PolynomialTrajectory* out);

/// The state a reference from `vehicle` along a first leg `leg` starts in. A vehicle moving along the
/// leg (within about 18 degrees) keeps its state; otherwise the reference starts with only the
/// velocity's component along the leg (none when moving away) and no acceleration. A vehicle moving
/// across or away from its route turns whatever the reference does, and a minimum-snap reference
/// from its velocity loops out and back, stretched to seconds: plans aimed at that loop chase it.
FlatState referenceStartState(const FlatState& vehicle, const Eigen::Vector3d& leg);

/// The time the reference, from t_from on, first passes within `radius` of `waypoint`: the closest
/// approach of that first pass (sampled every `step` seconds). NaN when it never comes that close,
/// or when that closest point lies within `radius` of where the reference is at t_from (the
/// waypoint is about reached: no use bounding a plan there). A plan's local goal bounded at this
/// time flies through an intermediate goal instead of cutting its corner.
double waypointPassTime(const PolynomialTrajectory& reference, const Eigen::Vector3d& waypoint, double t_from,
                        double radius, double step = 0.02);

}  // namespace topo_planner
