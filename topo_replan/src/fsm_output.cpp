#include "topo_planner/topo_replan/fsm_output.h"

namespace topo_planner {

const char* toString(FsmState state) {
  switch (state) {
    case FsmState::kInit: return "INIT";
    case FsmState::kWaitTarget: return "WAIT_TARGET";
    case FsmState::kGenNewTraj: return "GEN_NEW_TRAJ";
    case FsmState::kExecTraj: return "EXEC_TRAJ";
    case FsmState::kReplanTraj: return "REPLAN_TRAJ";
    case FsmState::kEmergencyStop: return "EMERGENCY_STOP";
  }
  return "unknown";
}

const char* toString(FsmEvent::Trigger trigger) {
  switch (trigger) {
    case FsmEvent::Trigger::kNewGoal: return "new_goal";
    case FsmEvent::Trigger::kCollisionAhead: return "collision_ahead";
    case FsmEvent::Trigger::kPeriodic: return "periodic";
    case FsmEvent::Trigger::kRetry: return "retry";
    case FsmEvent::Trigger::kEmergency: return "emergency";
    case FsmEvent::Trigger::kTimeJump: return "time_jump";
    case FsmEvent::Trigger::kReroute: return "reroute";
  }
  return "unknown";
}

}  // namespace topo_planner
