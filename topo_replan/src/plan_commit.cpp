#include "topo_planner/topo_replan/plan_commit.h"

#include <algorithm>
#include <cstdio>

namespace topo_planner {

bool commitPlan(const ReplanRequest& request, double t_take, const EsdfMap& map,
                const std::optional<Eigen::Vector3d>& anchor, const PlanCommitConfig& config, ReplanResult* result,
                ExecTrajectory* traj) {
  auto refuse = [&](const std::string& why) {
    result->status = ReplanStatus::kOptimizationFailed;
    result->message += (result->message.empty() ? "" : "; ") + why;
    return false;
  };
  const double step = (result->trajectory.derivative().evaluate(0.0) - request.start.velocity).norm();
  if (step > config.max_start_velocity_step_mps) {
    char text[128];
    std::snprintf(text, sizeof(text), "its start velocity is %.2f m/s off the commanded one (limit %.2f)", step,
                  config.max_start_velocity_step_mps);
    return refuse(text);
  }
  // On the map it was planned on.
  KnownSpaceCommitment::Committed c;
  std::string why;
  if (!KnownSpaceCommitment(config.commitment).commit(result->trajectory, map, anchor, &c, &why)) return refuse(why);
  traj->spline = std::move(c.spline);
  traj->start_time_s = t_take;
  traj->brake_start_s = t_take + c.brake_start_tau_s;
  traj->stops_before_unknown = c.stops_before_unknown;
  traj->has_heading_target = c.heading_target.has_value();
  if (c.heading_target) traj->heading_target = *c.heading_target;
  traj->reference_start_s = result->local_start_time_s;
  traj->reference_end_s = result->local_goal_time_s;
  if (traj->stops_before_unknown) {
    // It rejoins the reference only as far as it goes (proportionally, refined by referenceTimeAt).
    const double planned = result->trajectory.duration();
    const double frac = planned > 0.0 ? std::clamp((traj->brake_start_s - t_take) / planned, 0.0, 1.0) : 0.0;
    traj->reference_end_s = traj->reference_start_s + frac * (traj->reference_end_s - traj->reference_start_s);
  }
  traj->ends_at_goal = !traj->stops_before_unknown && request.reference &&
                       result->local_goal_time_s >= request.reference->duration() - 1e-6;
  return true;
}

}  // namespace topo_planner
