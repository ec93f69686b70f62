#pragma once
// The safety thread's rules, as one verdict: what the trajectory flown, the odometry and the
// freshness of the inputs call for at time t. The replanning FSM (replan_fsm.h, checkSafety())
// asks at every safety tick and carries the verdict out (a braking stop of manoeuvres.h, a hold at
// the measured position, a replan); it knows which rule fired from the verdict's reason.
//
//   condition (first that holds)                              action
//   inputs stale, the commanded speed above stopped_speed     brake to a hover (unless braking already)
//   odometry farther than max_tracking_error_m from the       hold at the measured position, moving on
//     commanded position at its stamp (VIO jump, failsafe)      with the measured velocity to a stop
//   a manoeuvre (braking, escape, back-off) is flown          nothing (checked when made, ends at rest)
//   a collision ahead sooner than the stop takes at the       brake (and replan: collision_ahead)
//     back-up deceleration, or a trajectory that ends moving
//     sooner than the stop at brake_acc_mps2
//   a collision farther ahead                                 replan (collision_ahead)
//
// A function of its arguments: no state, no lock.

#include <string>

#include <Eigen/Core>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/topo_replan/exec_trajectory.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

class SafetyCheck {
 public:
  struct Config {
    double safety_clearance_m = 0.2;    ///< the trajectory collides below this ESDF distance [m]
    double safety_sample_s = 0.02;      ///< time step of the collision check [s]
    double brake_acc_mps2 = 2.5;        ///< the braking stop's deceleration [m/s^2]
    /// With the known-space commitment, the back-up every committed plan keeps (commit_brake_acc_mps2):
    /// a collision the stop at this deceleration still ends before is a replan's business [m/s^2].
    double collision_brake_acc_mps2 = 2.5;
    double emergency_margin_s = 0.3;    ///< added to the stopping time [s]
    double stopped_speed_mps = 0.2;     ///< below this the vehicle counts as stopped [m/s]
    double max_tracking_error_m = 0.6;  ///< odometry this far from the commanded position: hold [m]
  };

  /// The commanded trajectory at the check.
  struct Flown {
    const ExecTrajectory* current = nullptr;   ///< the trajectory commanded (not null)
    const ExecTrajectory* previous = nullptr;  ///< the one it replaced, flown until current starts
    double takeover_delay_s = 0.1;             ///< how late a replan takes over [s]
    bool waiting = false;                      ///< no mission (WAIT_TARGET): a trajectory that ended is done
  };

  struct Odometry {
    double stamp_s = 0.0;
    Eigen::Vector3d position = Eigen::Vector3d::Zero();
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  };

  struct Verdict {
    enum class Action {
      kNone,            ///< fly on
      kBrake,           ///< brake along the trajectory flown, now
      kHoldAtMeasured,  ///< brake from `from` (the measured state), re-anchoring there
    };
    Action action = Action::kNone;
    bool collision_ahead = false;  ///< the trajectory collides ahead: replan it
    std::string why;               ///< the rule that fired, for the log
    ReplanStatus status = ReplanStatus::kSuccess;  ///< the event's status of a stop
    FlatState from;                ///< kHoldAtMeasured: the measured state at t
  };

  explicit SafetyCheck(const Config& config) : config_(config) {}
  void setConfig(const Config& config) { config_ = config; }

  /// The rules at t on `map`. `stale`: why the inputs are stale, null when fresh.
  Verdict check(double t, const Flown& flown, const Odometry& odom, const std::string* stale, const EsdfMap& map) const;

  /// Time to stop from `speed` at `deceleration`, plus the emergency margin and the takeover delay:
  /// a collision (or the end of a trajectory that ends moving) closer than this cannot wait for a replan.
  double stopTime(double speed, double deceleration, double takeover_delay_s) const {
    return speed / deceleration + config_.emergency_margin_s + takeover_delay_s;
  }

 private:
  Config config_;
};

}  // namespace topo_planner
