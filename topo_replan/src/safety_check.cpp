#include "topo_planner/topo_replan/safety_check.h"

#include <algorithm>
#include <cstdio>

#include "topo_planner/topo_replan/manoeuvres.h"

namespace topo_planner {

SafetyCheck::Verdict SafetyCheck::check(double t, const Flown& flown, const Odometry& odom, const std::string* stale,
                                        const EsdfMap& map) const {
  const ExecTrajectory& current = *flown.current;
  auto commanded = [&](double s) { return flownAt(current, flown.previous, s).stateAt(s); };
  Verdict v;
  // At rest past the trajectory's end (stateAt), so a trajectory that ended counts as stopped.
  const double speed = commanded(t).velocity.norm();
  // Stale inputs: a moving vehicle brakes to a hover (a braking trajectory already does).
  if (stale) {
    if (!current.braking && speed > config_.stopped_speed_mps) {
      v.action = Verdict::Action::kBrake;
      v.why = "inputs stale (" + *stale + ")";
      v.status = ReplanStatus::kInvalidInput;
    }
    return v;
  }
  // Odometry far from where the vehicle was commanded to be at its stamp (a VIO jump, or a vehicle
  // that went its own way while the odometry was away, e.g. a flight controller's failsafe hold):
  // hold from the measured state, moving on with the measured velocity to a stop; replanned from
  // there. (With the commanded velocity instead, a vehicle that came back from a failsafe hold
  // moving the other way left the stop at once and was re-anchored a second time, a setpoint jump.)
  const bool covered =
      odom.stamp_s >= current.start_time_s || (flown.previous && odom.stamp_s >= flown.previous->start_time_s);
  const double tracking_error = covered ? (odom.position - commanded(odom.stamp_s).position).norm() : 0.0;
  if (tracking_error > config_.max_tracking_error_m) {
    v.action = Verdict::Action::kHoldAtMeasured;
    v.from.velocity = odom.velocity;
    v.from.position = odom.position + odom.velocity * std::max(0.0, t - odom.stamp_s);
    char text[160];
    std::snprintf(text, sizeof(text), "odometry %.2f m from the commanded position (limit %.2f m): holding at the "
                  "measured position", tracking_error, config_.max_tracking_error_m);
    v.why = text;
    v.status = ReplanStatus::kInvalidInput;
    return v;
  }
  // Braking and escapes were checked when made and are not replanned (they end at rest).
  if (current.manoeuvre()) return v;
  if (t > current.endTime() && flown.waiting) return v;
  // Time to stop from the current speed, plus the margin: a collision (or the end of a trajectory
  // that ends moving, past which nothing is planned) closer than that cannot wait for a replan.
  // Before a collision the vehicle may fly on, replanning at every tick, while a stop at the back-up
  // deceleration every committed plan keeps still ends before it: a collision seen at the end of a
  // plan cut before unknown space (a tree behind the edge of what was seen, a voxel that turned
  // occupied) is a replan's business, not an emergency stop's.
  const double hit = firstCollisionTime(current, t, map, config_.safety_clearance_m, config_.safety_sample_s);
  const double end_speed = current.spline.derivative().evaluate(std::max(0.0, current.spline.duration() - 1e-6)).norm();
  const bool runs_out = !current.ends_at_goal && end_speed > config_.stopped_speed_mps &&
                        current.endTime() - t <= stopTime(speed, config_.brake_acc_mps2, flown.takeover_delay_s);
  v.collision_ahead = hit >= 0.0;
  if (!runs_out &&
      (hit < 0.0 || hit - t > stopTime(speed, config_.collision_brake_acc_mps2, flown.takeover_delay_s)))
    return v;
  v.action = Verdict::Action::kBrake;
  v.why = hit >= 0.0 ? "collision in " + std::to_string(hit - t) + " s"
                     : "the trajectory ends moving in " + std::to_string(current.endTime() - t) + " s with no replan";
  v.status = ReplanStatus::kOptimizationFailed;
  return v;
}

}  // namespace topo_planner
