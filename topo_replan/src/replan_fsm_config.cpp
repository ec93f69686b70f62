#include "topo_planner/topo_replan/replan_fsm_config.h"

#include <algorithm>
#include <cmath>

#include "topo_planner/topo_replan/replan_fsm.h"

namespace topo_planner {

bool ReplanFsmConfig::validate(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string sub;
  if (!replanner.validate(&sub)) return bad("replanner: " + sub);
  if (!(reference.max_vel_mps > 0.0) || !(reference.max_acc_mps2 > 0.0) || reference.max_rescales < 1)
    return bad("reference limits must be positive");
  if (!(takeover_delay_s >= 0.0) || !(takeover_delay_s < 5.0)) return bad("takeover_delay_s must be in [0, 5)");
  if (!(max_takeover_delay_s >= takeover_delay_s) || !(max_takeover_delay_s < 5.0))
    return bad("max_takeover_delay_s must be in [takeover_delay_s, 5)");
  if (!(replan_interval_s > 0.0)) return bad("replan_interval_s must be positive");
  if (!(safety_clearance_m >= 0.0) || !(safety_clearance_m <= OccupancyMap::kMaxKnownRadius))
    return bad("safety_clearance_m must be in [0, 1]");
  if (!(safety_sample_s >= 1e-3) || !std::isfinite(safety_sample_s)) return bad("safety_sample_s must be >= 0.001");
  if (!(brake_acc_mps2 > 0.0) || !std::isfinite(brake_acc_mps2)) return bad("brake_acc_mps2 must be positive");
  if (!(max_brake_acc_mps2 >= brake_acc_mps2) || !std::isfinite(max_brake_acc_mps2))
    return bad("max_brake_acc_mps2 must be >= brake_acc_mps2");
  if (!(commit_brake_acc_mps2 > 0.0 && commit_brake_acc_mps2 <= max_brake_acc_mps2))
    return bad("commit_brake_acc_mps2 must be in (0, max_brake_acc_mps2]");
  if (!(sensing_range_m >= 0.0) || !std::isfinite(sensing_range_m)) return bad("sensing_range_m must be >= 0");
  if (!(escape_clearance_m > 0.0) || !std::isfinite(escape_clearance_m)) return bad("escape_clearance_m must be positive");
  if (!(escape_speed_mps > 0.0) || !std::isfinite(escape_speed_mps)) return bad("escape_speed_mps must be positive");
  if (!(escape_min_clearance_m > 0.0) || !(escape_min_clearance_m <= escape_clearance_m))
    return bad("escape_min_clearance_m must be in (0, escape_clearance_m]");
  if (!(max_escape_length_m >= 0.0) || !(max_escape_length_m <= 10.0))
    return bad("max_escape_length_m must be in [0, 10]");
  if (!(emergency_margin_s >= 0.0) || !std::isfinite(emergency_margin_s)) return bad("emergency_margin_s must be >= 0");
  if (!(goal_clearance_m >= 0.0) || !std::isfinite(goal_clearance_m)) return bad("goal_clearance_m must be >= 0");
  if (!(goal_tolerance_m > 0.0) || !std::isfinite(goal_tolerance_m)) return bad("goal_tolerance_m must be positive");
  if (!(stopped_speed_mps > 0.0) || !std::isfinite(stopped_speed_mps)) return bad("stopped_speed_mps must be positive");
  if (max_plan_failures < 1) return bad("max_plan_failures must be >= 1");
  if (!route.validate(&sub)) return bad(sub);
  if (reroute_after_failures < 1) return bad("reroute_after_failures must be >= 1");
  if (!(route_check_length_m >= 0.0) || !std::isfinite(route_check_length_m))
    return bad("route_check_length_m must be >= 0 (0: off)");
  if (!(route_check_interval_s >= 0.0) || !std::isfinite(route_check_interval_s))
    return bad("route_check_interval_s must be >= 0");
  if (!(rest_retry_interval_s >= 0.0 && rest_retry_interval_s <= 10.0))
    return bad("rest_retry_interval_s must be in [0, 10] s");
  if (!(moving_retry_interval_s >= 0.0 && moving_retry_interval_s <= 10.0))
    return bad("moving_retry_interval_s must be in [0, 10] s");
  if (!(backoff_length_m >= 0.0) || !(max_backoff_length_m >= backoff_length_m) || !(max_backoff_length_m <= 20.0))
    return bad("backoff lengths must satisfy 0 <= backoff_length_m <= max_backoff_length_m <= 20");
  if (max_backoffs < 0) return bad("max_backoffs must be >= 0");
  if (max_look_holds < 1) return bad("max_look_holds must be >= 1");
  if (!(look_hold_min_s >= 0.0) || !std::isfinite(look_hold_min_s)) return bad("look_hold_min_s must be >= 0");
  if (!(backoff_speed_mps > 0.0) || !std::isfinite(backoff_speed_mps)) return bad("backoff_speed_mps must be positive");
  if (!(mission_timeout_s >= 0.0) || std::isnan(mission_timeout_s)) return bad("mission_timeout_s must be >= 0 (0: automatic)");
  if (!(progress_timeout_s >= 0.0) || std::isnan(progress_timeout_s)) return bad("progress_timeout_s must be >= 0 (0: off)");
  if (!(progress_min_gain_m > 0.0) || !std::isfinite(progress_min_gain_m)) return bad("progress_min_gain_m must be positive");
  if (!(stall_zone_radius_m >= 0.0) || !(stall_zone_radius_m <= 10.0)) return bad("stall_zone_radius_m must be in [0, 10]");
  if (!(known_start_radius_m >= 0.0) || !(known_start_radius_m <= 2.0)) return bad("known_start_radius_m must be in [0, 2]");
  if (!(commit_margin_m >= 0.0) || !(commit_margin_m <= 5.0)) return bad("commit_margin_m must be in [0, 5]");
  if (!(depth_timeout_s >= 0.0) || !std::isfinite(depth_timeout_s)) return bad("depth_timeout_s must be >= 0 (0: not required)");
  if (!(odom_timeout_s > 0.0) || !std::isfinite(odom_timeout_s)) return bad("odom_timeout_s must be positive");
  if (!(odom_max_age_s > 0.0) || !std::isfinite(odom_max_age_s)) return bad("odom_max_age_s must be positive");
  if (!(max_tracking_error_m > 0.0)) return bad("max_tracking_error_m must be positive");
  if (!(time_jump_threshold_s > 0.0) || !std::isfinite(time_jump_threshold_s))
    return bad("time_jump_threshold_s must be positive");
  if (!(waypoint_reached_radius_m >= 0.0) || !std::isfinite(waypoint_reached_radius_m))
    return bad("waypoint_reached_radius_m must be >= 0");
  if (!(max_start_velocity_step_mps >= 0.0)) return bad("max_start_velocity_step_mps must be >= 0");
  if (!(server_timeout_s > 0.0) || !std::isfinite(server_timeout_s)) return bad("server_timeout_s must be positive");
  if (!(server_grace_s >= 0.0) || !std::isfinite(server_grace_s)) return bad("server_grace_s must be >= 0");
  if (!(server_position_tolerance_m > 0.0) || !std::isfinite(server_position_tolerance_m))
    return bad("server_position_tolerance_m must be positive");
  return true;
}

// The replanner's settings with the route's height band (the geofence) applied to its searches and
// its final check.
TopoReplanner::Config ReplanFsm::replannerConfig(const Config& config) {
  TopoReplanner::Config c = config.replanner;
  c.search.roadmap.min_z_m = c.astar.min_z_m = c.optimizer.min_z_m = config.route.min_z_m;
  c.search.roadmap.max_z_m = c.astar.max_z_m = c.optimizer.max_z_m = config.route.max_z_m;
  // Not faster than the camera's depth allows (see sensing_range_m): the plans, their checks and their
  // time reallocation (which would otherwise stretch a curve to a speed that is never flown).
  if (config.sensing_range_m > 0.0) c.cruise_speed_mps = c.optimizer.max_vel_mps = cruiseSpeed(config);
  return c;
}

double ReplanFsm::cruiseSpeed(const Config& config) {
  const double max_vel = config.replanner.optimizer.max_vel_mps;
  if (!(config.sensing_range_m > 0.0)) return max_vel;
  // The largest v with v T + v^2 / 2a <= d: T the reaction (the take-over delay, a depth frame and a
  // tick: 0.1 s, and half of the stop's onset), a the committed stop's deceleration, d the depth the
  // map reaches less the committed stop's clearance and margin.
  const double a = config.commit_brake_acc_mps2, T = config.takeover_delay_s + 0.1 + 0.05;
  const double d = std::max(0.0, config.sensing_range_m - config.safety_clearance_m - config.commit_margin_m);
  const double v = a * (-T + std::sqrt(T * T + 2.0 * d / a));
  return std::min(max_vel, std::max(v, 0.5));
}

ManoeuvreConfig ReplanFsmConfig::manoeuvres() const {
  const ReplanFsmConfig& c = *this;
  ManoeuvreConfig m;
  m.safety_clearance_m = c.safety_clearance_m;
  m.safety_sample_s = c.safety_sample_s;
  m.brake_acc_mps2 = c.brake_acc_mps2;
  m.max_brake_acc_mps2 = c.max_brake_acc_mps2;
  m.escape_clearance_m = c.escape_clearance_m;
  m.escape_min_clearance_m = c.escape_min_clearance_m;
  m.escape_speed_mps = c.escape_speed_mps;
  m.max_escape_length_m = c.max_escape_length_m;
  m.commit_to_known_space = c.commit_to_known_space;
  m.known_start_radius_m = c.known_start_radius_m;
  m.backoff_length_m = c.backoff_length_m;
  m.max_backoff_length_m = c.max_backoff_length_m;
  m.backoff_speed_mps = c.backoff_speed_mps;
  return m;
}

MissionRemedies::Config ReplanFsmConfig::remedies() const {
  const ReplanFsmConfig& c = *this;
  MissionRemedies::Config r;
  r.global_route = c.global_route;
  r.max_plan_failures = c.max_plan_failures;
  r.reroute_after_failures = c.reroute_after_failures;
  r.max_backoffs = c.max_backoffs;
  r.max_look_holds = c.max_look_holds;
  r.look_hold_min_s = c.look_hold_min_s;
  r.progress_timeout_s = c.progress_timeout_s;
  r.mission_timeout_s = c.mission_timeout_s;
  return r;
}

RouteWatch::Config ReplanFsmConfig::routeWatch() const {
  const ReplanFsmConfig& c = *this;
  RouteWatch::Config w;
  w.safety_clearance_m = c.safety_clearance_m;
  w.route_clearance_m = c.route.clearance_m;
  w.min_z_m = c.route.min_z_m;
  w.max_z_m = c.route.max_z_m;
  w.check_length_m = c.route_check_length_m;
  return w;
}

ServerLink::Config ReplanFsmConfig::serverLink() const {
  const ReplanFsmConfig& c = *this;
  ServerLink::Config l;
  l.timeout_s = c.server_timeout_s;
  l.grace_s = c.server_grace_s;
  l.position_tolerance_m = c.server_position_tolerance_m;
  l.stopped_speed_mps = c.stopped_speed_mps;
  l.max_resync_s = std::min(c.time_jump_threshold_s, 1.0);
  return l;
}

InputMonitor::Config ReplanFsmConfig::inputMonitor() const {
  const ReplanFsmConfig& c = *this;
  InputMonitor::Config m;
  m.depth_timeout_s = c.depth_timeout_s;
  m.odom_timeout_s = c.odom_timeout_s;
  m.odom_max_age_s = c.odom_max_age_s;
  m.time_jump_threshold_s = c.time_jump_threshold_s;
  return m;
}

KnownSpaceCommitment::Config ReplanFsmConfig::commitment() const {
  const ReplanFsmConfig& c = *this;
  KnownSpaceCommitment::Config k;
  k.enabled = c.commit_to_known_space;
  k.clearance_m = c.safety_clearance_m;
  k.known_start_radius_m = c.known_start_radius_m;
  k.margin_m = c.commit_margin_m;
  k.brake_acc_mps2 = c.commit_brake_acc_mps2;
  k.max_brake_acc_mps2 = c.max_brake_acc_mps2;
  k.min_z_m = c.route.min_z_m;
  k.max_z_m = c.route.max_z_m;
  k.sample_s = c.safety_sample_s;
  return k;
}

SafetyCheck::Config ReplanFsmConfig::safetyCheck() const {
  SafetyCheck::Config s;
  s.safety_clearance_m = safety_clearance_m;
  s.safety_sample_s = safety_sample_s;
  s.brake_acc_mps2 = brake_acc_mps2;
  s.collision_brake_acc_mps2 = commit_to_known_space ? std::max(brake_acc_mps2, commit_brake_acc_mps2) : brake_acc_mps2;
  s.emergency_margin_s = emergency_margin_s;
  s.stopped_speed_mps = stopped_speed_mps;
  s.max_tracking_error_m = max_tracking_error_m;
  return s;
}

PlanCommitConfig ReplanFsmConfig::planCommit() const {
  PlanCommitConfig p;
  p.commitment = commitment();
  p.max_start_velocity_step_mps = max_start_velocity_step_mps;
  return p;
}

}  // namespace topo_planner
