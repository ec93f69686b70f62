#pragma once
// The trajectory the replanning FSM commands: a B-spline from a start time, with what the vehicle
// must know about it (a plan on the reference, a braking stop, a slow manoeuvre; where its
// known-space commitment starts braking). Shared by the FSM and its manoeuvres (manoeuvres.h).

#include <cstdint>

#include <Eigen/Core>

#include "topo_planner/bspline_opt/uniform_bspline.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace topo_planner {

/// A trajectory the vehicle executes: a B-spline from start_time_s.
struct ExecTrajectory {
  int64_t id = -1;
  double start_time_s = 0.0;   ///< when it takes over [s, caller's clock]
  UniformBspline spline;
  double reference_start_s = 0.0;  ///< reference time at its start ...
  double reference_end_s = 0.0;    ///< ... and where it rejoins the reference
  bool ends_at_goal = false;       ///< rejoins the reference at its end (the last goal, at rest)
  bool braking = false;            ///< an emergency braking trajectory
  bool escape = false;             ///< a slow manoeuvre out of an obstacle's clearance, from rest to rest
  /// Known-space commitment: the planned (optimistic) trajectory is flown until this time, then the
  /// vehicle stops along its path within the space the map has observed free. Equal to endTime()
  /// when the whole plan lies in known-free space [s, caller's clock].
  double brake_start_s = 0.0;
  bool stops_before_unknown = false;  ///< the plan was cut: it ends at rest before unknown space
  /// Where the camera should look when the trajectory's own displacement gives no heading (a stop
  /// at the edge of the known space): a point ahead on the planned (optimistic) path.
  bool has_heading_target = false;
  Eigen::Vector3d heading_target = Eigen::Vector3d::Zero();
  /// Deliberately starts away from the commanded state (the hold at the measured position after an
  /// odometry jump): the trajectory server accepts the step.
  bool reanchor = false;
  double endTime() const { return start_time_s + spline.duration(); }
  /// Braking or escape: checked when made, ends at rest, not on the reference, not replanned.
  bool manoeuvre() const { return braking || escape; }
  /// The commanded state at t: before its start, its start; after its end, at rest at its end.
  FlatState stateAt(double t) const;
  /// The time on `reference` where the vehicle is at t: proportional between reference_start_s and
  /// reference_end_s, refined to the reference's point nearest the trajectory's (within 2 s); 0 for
  /// a manoeuvre.
  double referenceTimeAt(double t, const PolynomialTrajectory& reference) const;
  /// Moves it in time by dt (a time jump, a re-synchronisation with the trajectory server).
  void shift(double dt) {
    start_time_s += dt;
    brake_start_s += dt;
  }
};

/// The trajectory flown at t: `current`, or before its start the one it replaced (`previous`, may be
/// null): flown then, or (t a rounding error before its own start: 26.15 + 0.1 > 26.25) about to
/// be. The current one, clamped to its later start, would put the state where the vehicle is only
/// later (a stop from there stepped the setpoint).
inline const ExecTrajectory& flownAt(const ExecTrajectory& current, const ExecTrajectory* previous, double t) {
  return previous && t < current.start_time_s ? *previous : current;
}

}  // namespace topo_planner
