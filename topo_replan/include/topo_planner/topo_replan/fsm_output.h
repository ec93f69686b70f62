#pragma once
// What the replanning FSM (replan_fsm.h) says: its states, and what each call did (FsmOutput:
// a trajectory to publish, the planning event for the log and the ReplanEvent message, flags for
// the caller).

#include <optional>
#include <string>

#include <Eigen/Core>

#include "topo_planner/topo_replan/exec_trajectory.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

enum class FsmState { kInit, kWaitTarget, kGenNewTraj, kExecTraj, kReplanTraj, kEmergencyStop };
const char* toString(FsmState state);

/// What one call did, for logging and the ReplanEvent message.
struct FsmEvent {
  enum class Trigger { kNewGoal, kCollisionAhead, kPeriodic, kRetry, kEmergency, kTimeJump, kReroute };
  Trigger trigger = Trigger::kNewGoal;
  FsmState state = FsmState::kInit;     ///< state when it started
  bool published = false;               ///< a new trajectory was returned
  ReplanStatus status = ReplanStatus::kSuccess;
  /// none | keep_current | hover_retry | stop | escape | back_off | reroute | give_up | discarded_late |
  /// discarded_superseded
  std::string fallback = "none";
  std::string message;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  ///< start of the planned trajectory
  ReplanStats stats;
};
const char* toString(FsmEvent::Trigger trigger);

struct FsmOutput {
  std::optional<ExecTrajectory> trajectory;       ///< publish this (already checked)
  std::optional<FsmEvent> event;                  ///< a planning call happened
  std::optional<ReplanResult> plan;               ///< its full result (candidates etc., for rviz)
  bool new_reference = false;                     ///< reference() changed
  bool new_route = false;                         ///< route() changed
  bool goal_reached = false;                      ///< the last goal of the mission was reached
  /// Odometry jumped away from the commanded state (a VIO relocalisation): the map built in the old
  /// frame no longer lines up with the new one; the caller may forget it.
  bool odometry_jumped = false;
  /// The trajectory server does not follow the commanded trajectory: the caller sends no heartbeat
  /// (the server's watchdog then stops the vehicle) until the FSM has re-anchored on its hold.
  bool server_diverged = false;
  std::string message;                            ///< a notable transition, for the log
  /// Adds a line to the message ("; " between lines).
  void say(const std::string& text) {
    if (!message.empty()) message += "; ";
    message += text;
  }
};

}  // namespace topo_planner
