#pragma once
// From a replanner's plan to the trajectory the FSM commits to: the plan must start at the
// commanded velocity (setpoints never step), and is cut to the known space (KnownSpaceCommitment);
// what is left rejoins the reference only as far as it goes. A function of its arguments.

#include <optional>
#include <string>

#include <Eigen/Core>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/topo_replan/exec_trajectory.h"
#include "topo_planner/topo_replan/known_space_commitment.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

struct PlanCommitConfig {
  KnownSpaceCommitment::Config commitment;
  /// A plan whose start velocity differs from the commanded one by more than this is refused [m/s].
  double max_start_velocity_step_mps = 0.1;
};

/// The successful plan of *result (made for `request`, taking over at t_take, on `map`), committed:
/// true with *traj filled (its spline, start and brake times, the reference times it covers, whether
/// it ends at the goal, its heading target); false when it is refused, with result->status
/// kOptimizationFailed and the reason appended to result->message. `anchor`: the known anchor.
bool commitPlan(const ReplanRequest& request, double t_take, const EsdfMap& map,
                const std::optional<Eigen::Vector3d>& anchor, const PlanCommitConfig& config, ReplanResult* result,
                ExecTrajectory* traj);

}  // namespace topo_planner
