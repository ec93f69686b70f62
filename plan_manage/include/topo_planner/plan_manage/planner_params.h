#pragma once
// The planner node's FSM parameters (config/planner.yaml: fsm/, replan/, search/, astar/, optimizer/,
// route/, reference/, the limits) read into ReplanFsm::Config, in one place for every reader that has
//   template <typename T> void read(const std::string& name, T& value);  // leaves value when absent
//   std::ostringstream& errors();
// : uav_sim's ParamReader (ROS parameters) in the planner node, YamlParams (a YAML file) in the
// ROS-free closed loop (sim_flight.h), so both fly the configuration the node flies. Defaults are the
// structs' own, except where the node's differ (set here, before the reads).

#include <algorithm>
#include <sstream>
#include <string>

#include "topo_planner/topo_replan/replan_fsm.h"

namespace topo_planner {

/// The optimiser's limits are the vehicle's; the reference flies at reference_ratio of them.
inline void setFlightLimits(double max_vel, double max_acc, double reference_ratio, ReplanFsm::Config* f) {
  f->replanner.optimizer.max_vel_mps = max_vel;
  f->replanner.optimizer.max_acc_mps2 = max_acc;
  f->reference.max_vel_mps = reference_ratio * max_vel;
  f->reference.max_acc_mps2 = reference_ratio * max_acc;
}

/// Reads the FSM's parameters into *f and the reference's speed ratio into *reference_speed_ratio;
/// wrong types go to r.errors() (the range check is f->validate()).
template <typename Reader>
void readFsmParams(Reader& r, ReplanFsm::Config* fsm, double* reference_speed_ratio) {
  ReplanFsm::Config& f = *fsm;
  r.read("odom_timeout_s", f.odom_timeout_s);

  r.read("fsm/takeover_delay_s", f.takeover_delay_s);
  r.read("fsm/max_takeover_delay_s", f.max_takeover_delay_s);
  r.read("fsm/replan_interval_s", f.replan_interval_s);
  r.read("fsm/safety_clearance_m", f.safety_clearance_m);
  r.read("fsm/safety_sample_s", f.safety_sample_s);
  r.read("fsm/brake_acc_mps2", f.brake_acc_mps2);
  r.read("fsm/emergency_margin_s", f.emergency_margin_s);
  r.read("fsm/goal_clearance_m", f.goal_clearance_m);
  r.read("fsm/goal_tolerance_m", f.goal_tolerance_m);
  r.read("fsm/stopped_speed_mps", f.stopped_speed_mps);
  r.read("fsm/max_plan_failures", f.max_plan_failures);
  r.read("fsm/rest_retry_interval_s", f.rest_retry_interval_s);
  r.read("fsm/moving_retry_interval_s", f.moving_retry_interval_s);
  r.read("fsm/escape_clearance_m", f.escape_clearance_m);
  r.read("fsm/escape_min_clearance_m", f.escape_min_clearance_m);
  r.read("fsm/escape_speed_mps", f.escape_speed_mps);
  r.read("fsm/max_escape_length_m", f.max_escape_length_m);
  r.read("fsm/commit_to_known_space", f.commit_to_known_space);
  r.read("fsm/known_start_radius_m", f.known_start_radius_m);
  r.read("fsm/commit_margin_m", f.commit_margin_m);
  r.read("fsm/depth_timeout_s", f.depth_timeout_s);
  r.read("fsm/odom_max_age_s", f.odom_max_age_s);
  r.read("fsm/max_tracking_error_m", f.max_tracking_error_m);
  r.read("fsm/time_jump_threshold_s", f.time_jump_threshold_s);
  r.read("fsm/server_timeout_s", f.server_timeout_s);
  r.read("fsm/server_grace_s", f.server_grace_s);
  r.read("fsm/server_position_tolerance_m", f.server_position_tolerance_m);
  r.read("fsm/waypoint_reached_radius_m", f.waypoint_reached_radius_m);
  r.read("fsm/reroute_after_failures", f.reroute_after_failures);
  r.read("fsm/route_check_length_m", f.route_check_length_m);
  r.read("fsm/route_check_interval_s", f.route_check_interval_s);
  r.read("fsm/backoff_length_m", f.backoff_length_m);
  r.read("fsm/max_backoff_length_m", f.max_backoff_length_m);
  r.read("fsm/backoff_speed_mps", f.backoff_speed_mps);
  r.read("fsm/max_backoffs", f.max_backoffs);
  r.read("fsm/max_look_holds", f.max_look_holds);
  r.read("fsm/look_hold_min_s", f.look_hold_min_s);
  r.read("fsm/mission_timeout_s", f.mission_timeout_s);
  r.read("fsm/progress_timeout_s", f.progress_timeout_s);
  r.read("fsm/progress_min_gain_m", f.progress_min_gain_m);
  r.read("fsm/stall_zone_radius_m", f.stall_zone_radius_m);
  r.read("route/enabled", f.global_route);
  r.read("route/cell_voxels", f.route.cell_voxels);
  r.read("route/preferred_clearance_m", f.route.preferred_clearance_m);
  r.read("route/avoid_weight", f.route.avoid_weight);
  f.route.unknown_weight = 1.0;
  r.read("route/unknown_weight", f.route.unknown_weight);
  r.read("route/clearance_weight", f.route.clearance_weight);
  r.read("route/heuristic_weight", f.route.heuristic_weight);
  r.read("route/min_z_m", f.route.min_z_m);
  r.read("route/max_z_m", f.route.max_z_m);
  r.read("route/band_margin_m", f.route.band_margin_m);
  r.read("route/end_clearance_m", f.route.end_clearance_m);
  r.read("route/max_expansions", f.route.max_expansions);

  // Limits: the optimiser's are the vehicle's; the reference flies below them (reference_speed_ratio)
  // so detours around obstacles need no time stretching.
  double max_vel = f.replanner.optimizer.max_vel_mps, max_acc = f.replanner.optimizer.max_acc_mps2, ratio = 0.75;
  r.read("max_vel_mps", max_vel);
  r.read("max_acc_mps2", max_acc);
  r.read("reference/speed_ratio", ratio);
  *reference_speed_ratio = ratio;
  setFlightLimits(max_vel, max_acc, ratio, &f);
  f.reference.max_segment_length_m = 3.0;
  f.reference.cruise_timing = true;
  f.reference.profile_timing = true;
  r.read("reference/max_segment_length_m", f.reference.max_segment_length_m);
  r.read("reference/profile_timing", f.reference.profile_timing);
  f.brake_acc_mps2 = max_acc;
  r.read("fsm/brake_acc_mps2", f.brake_acc_mps2);
  f.max_brake_acc_mps2 = std::max(f.max_brake_acc_mps2, f.brake_acc_mps2);
  r.read("fsm/max_brake_acc_mps2", f.max_brake_acc_mps2);
  f.commit_brake_acc_mps2 = f.max_brake_acc_mps2;
  r.read("fsm/commit_brake_acc_mps2", f.commit_brake_acc_mps2);
  r.read("fsm/sensing_range_m", f.sensing_range_m);

  TopoReplanner::Config& p = f.replanner;
  p.local_goal_margin_m = 2.0;  // 1 m failed 44 of 344 moving-start replans, 2 m 4 (docs/modules.md)
  r.read("replan/horizon_m", p.horizon_m);
  p.horizon_time_s = 3.0;
  r.read("replan/horizon_time_s", p.horizon_time_s);
  r.read("replan/reference_clearance_m", p.reference_clearance_m);
  r.read("replan/local_goal_margin_m", p.local_goal_margin_m);
  r.read("replan/max_local_goal_extension_m", p.max_local_goal_extension_m);
  r.read("replan/control_point_spacing_m", p.control_point_spacing_m);
  p.profile_timing = true;
  r.read("replan/profile_timing", p.profile_timing);
  r.read("replan/max_selection_delay_ratio", p.max_selection_delay_ratio);
  r.read("replan/guide_timing_ratio", p.guide_timing_ratio);
  r.read("replan/max_search_start_offset_m", p.max_search_start_offset_m);
  r.read("replan/min_start_clearance_m", p.min_start_clearance_m);
  r.read("replan/num_threads", p.num_threads);
  r.read("search/clearance_m", p.search.clearance_m);
  r.read("search/max_paths", p.search.max_paths);
  r.read("search/max_length_ratio", p.search.max_length_ratio);
  r.read("search/max_time_s", p.search.roadmap.max_time_s);
  // Unknown space, per consumer: the search, the optimiser and A* plan through it optimistically by
  // default (so the planner explores); the committed part never enters it (fsm/commit_to_known_space).
  r.read("search/unknown_is_free", p.search.unknown_is_free);
  r.read("optimizer/unknown_is_free", p.optimizer.unknown_is_free);
  r.read("astar/unknown_is_free", p.astar.unknown_is_free);
  r.read("astar/margin_doublings", p.astar.margin_doublings);
  p.search.keep_raw_paths = true;  // the roadmap for rviz (~vis/roadmap)
  r.read("search/keep_roadmap", p.search.keep_raw_paths);
  r.read("optimizer/clearance_m", p.optimizer.clearance_m);
  r.read("optimizer/max_iterations", p.optimizer.max_iterations);
  r.read("optimizer/max_time_s", p.optimizer.max_time_s);
  r.read("optimizer/lambda_collision", p.optimizer.l2c);
  r.read("optimizer/feasibility_margin", p.optimizer.feasibility_margin);
  r.read("optimizer/stretched_retry", p.optimizer.stretched_retry);
  r.read("optimizer/guide_phase_fallback", p.optimizer.guide_phase_fallback);
  r.read("optimizer/max_time_ratio", p.optimizer.max_time_ratio);
  r.read("optimizer/face_offset_m", p.optimizer.face_offset_m);
  // The planning's wall-clock budgets (the roadmap's sampling time, NLopt's time per run) stretch on
  // a slow machine (sanitizers: the Makefile sets it with TOPO_PLANNER_BUDGET_SCALE); the counts
  // (samples, evaluations) stay as they are. 1 in flight.
  double budget_scale = 1.0;
  r.read("time_budget_scale", budget_scale);
  if (!(budget_scale >= 1.0 && budget_scale <= 100.0)) {
    r.errors() << "time_budget_scale must be in [1, 100]; ";
  } else {
    p.search.roadmap.max_time_s *= budget_scale;
    p.optimizer.max_time_s *= budget_scale;
  }
  p.astar.clearance_m = p.search.clearance_m;
  // The route keeps the guide search's clearance and its view of unknown space unless told otherwise.
  f.route.clearance_m = p.search.clearance_m;
  f.route.unknown_is_free = p.search.unknown_is_free;
  r.read("route/clearance_m", f.route.clearance_m);
  r.read("route/unknown_is_free", f.route.unknown_is_free);
}

}  // namespace topo_planner
