#include "topo_planner/topo_replan/replan_fsm.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include "topo_planner/bspline_opt/bspline_costs.h"
#include "topo_planner/topo_replan/stop_profile.h"

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

const char* toString(GoalStatus status) {
  switch (status) {
    case GoalStatus::kAccepted: return "kAccepted";
    case GoalStatus::kNoOdometry: return "kNoOdometry";
    case GoalStatus::kInvalidInput: return "kInvalidInput";
    case GoalStatus::kGoalInObstacle: return "kGoalInObstacle";
    case GoalStatus::kGoalOutOfMap: return "kGoalOutOfMap";
    case GoalStatus::kReferenceFailed: return "kReferenceFailed";
    case GoalStatus::kInputsStale: return "kInputsStale";
    case GoalStatus::kUnreachable: return "kUnreachable";
    case GoalStatus::kGivenUp: return "kGivenUp";
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

bool ReplanFsm::Config::validate(std::string* why) const {
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

std::unique_ptr<ReplanFsm> ReplanFsm::create(const Config& config, std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid FSM config: " + why;
    return nullptr;
  }
  std::unique_ptr<TopoReplanner> replanner = TopoReplanner::create(replannerConfig(config), error);
  if (!replanner) return nullptr;
  return std::unique_ptr<ReplanFsm>(new ReplanFsm(config, std::move(replanner)));
}

namespace {
// The route search that may leave a narrow passage around the vehicle (routeLocked).
GlobalRouter::Config startRouterConfig(const ReplanFsm::Config& config) {
  GlobalRouter::Config c = config.route;
  c.start_radius_m = std::max(c.start_radius_m, config.max_backoff_length_m + 1.0);
  return c;
}
}  // namespace

ReplanFsm::ReplanFsm(const Config& config, std::unique_ptr<TopoReplanner> replanner)
    : config_(config),
      replanner_(std::move(replanner)),
      router_(std::make_unique<GlobalRouter>(config.route)),
      start_router_(std::make_unique<GlobalRouter>(startRouterConfig(config))),
      takeover_delay_s_(config.takeover_delay_s) {}

ReplanFsm::Config ReplanFsm::config() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return config_;
}

bool ReplanFsm::reconfigure(const Config& config, std::string* why) {
  std::string reason;
  if (!config.validate(&reason)) {
    if (why) *why = "invalid settings: " + reason;
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  pending_config_ = config;
  return true;
}

void ReplanFsm::applyPendingConfigLocked(FsmOutput* out) {
  if (!pending_config_) return;
  std::string error;
  std::unique_ptr<TopoReplanner> replanner = TopoReplanner::create(replannerConfig(*pending_config_), &error);
  if (!out->message.empty()) out->message += "; ";
  if (replanner) {
    config_ = *pending_config_;
    replanner_ = std::move(replanner);
    router_ = std::make_unique<GlobalRouter>(config_.route);
    start_router_ = std::make_unique<GlobalRouter>(startRouterConfig(config_));
    takeover_delay_s_ = std::max(takeover_delay_s_, config_.takeover_delay_s);
    route_stale_ = true;  // its clearance may have changed: searched again at the next reference
    out->message += "new settings applied";
  } else {
    out->message += "new settings not applied: " + error;
  }
  pending_config_.reset();
}

FsmState ReplanFsm::state() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_;
}

GoalStatus ReplanFsm::lastGoalStatus() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_goal_status_;
}

std::optional<ExecTrajectory> ReplanFsm::current() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_;
}

PolynomialTrajectory ReplanFsm::reference() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return reference_;
}

bool ReplanFsm::setOdometry(double t, const Eigen::Vector3d& position, const Eigen::Vector3d& velocity,
                            double arrival_s, std::string* why) {
  if (std::isnan(arrival_s)) arrival_s = t;
  if (!std::isfinite(t) || !std::isfinite(arrival_s) || !position.allFinite() || !velocity.allFinite()) {
    if (why) *why = "NaN/inf values";
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  FsmOutput ignored;
  observeClockLocked(arrival_s, &ignored);  // a time jump shifts odom_time_s_ before the order check
  // Stamped ahead of the clock: another time base (the clock's step has not reached this process
  // yet) or a skewed sensor clock. Accepting it would make every later odometry look backwards.
  if (t - arrival_s > config_.odom_max_age_s) {
    if (why) *why = "stamped " + std::to_string(t - arrival_s) + " s ahead of the clock";
    return false;
  }
  if (have_odom_ && t < odom_time_s_) {
    if (why) *why = "stamped " + std::to_string(odom_time_s_ - t) + " s before the last odometry";
    return false;
  }
  have_odom_ = true;
  odom_time_s_ = t;
  odom_arrival_s_ = arrival_s;
  odom_position_ = position;
  odom_velocity_ = velocity;
  // Intermediate goals the vehicle came close to are done (the last one ends the mission in tick()).
  while (next_goal_ + 1 < goals_.size() && (position - goals_[next_goal_]).norm() <= config_.waypoint_reached_radius_m)
    ++next_goal_;
  return true;
}

bool ReplanFsm::setServerSetpoint(const ServerSetpoint& setpoint) {
  if (!std::isfinite(setpoint.stamp_s) || !setpoint.position.allFinite() || !setpoint.velocity.allFinite()) return false;
  std::lock_guard<std::mutex> lock(mutex_);
  if (std::isfinite(setpoint.arrival_s) && setpoint.stamp_s - setpoint.arrival_s > config_.server_timeout_s) return false;
  if (server_ && setpoint.stamp_s < server_->stamp_s) return false;  // out of order
  server_ = setpoint;
  return true;
}

bool ReplanFsm::followServerLocked(double t, const EsdfMap& map, FsmOutput* out) {
  if (!server_ || !(std::abs(t - server_->stamp_s) <= config_.server_timeout_s)) return false;
  const ServerSetpoint& sp = *server_;
  // A setpoint sampled before this FSM's last re-anchoring predates it: nothing new.
  if (sp.stamp_s <= server_anchor_s_) return false;
  const double grace = config_.server_grace_s;
  // The server should follow the current trajectory once its start (plus the message latency) has
  // passed ("settled"), the one it replaced until then.
  const bool settled = current_ && sp.stamp_s >= current_->start_time_s + grace;
  std::string why;
  if (sp.mode == ServerSetpoint::Mode::kStopping) {
    why = "it stops on its own (watchdog or end stop)";
  } else if (sp.mode == ServerSetpoint::Mode::kTrajectory) {
    const ExecTrajectory* on = nullptr;  // the trajectory of ours it follows
    if (sp.own_session && current_ && sp.trajectory_id == current_->id) on = &*current_;
    if (sp.own_session && !settled && previous_ && sp.trajectory_id == previous_->id) on = &*previous_;
    if (!on && (!current_ || settled)) {
      why = "it follows a trajectory this planner did not command (or no longer commands)";
    } else if (on && sp.velocity.norm() > config_.stopped_speed_mps) {
      // On our trajectory: keep the timing in step with the server's (a clock step each side saw
      // at another moment and shifted by another estimate of the time between calls).
      const double tau = sp.stamp_s - on->start_time_s, d = on->spline.duration();
      auto error = [&](double delta) {
        return (on->spline.evaluate(std::clamp(tau + delta, 0.0, d)) - sp.position).norm();
      };
      if (error(0.0) > 0.01) {
        double best = 0.0, best_error = error(0.0);
        const double range = std::min(config_.time_jump_threshold_s, 1.0);
        for (double delta = -range; delta <= range; delta += 0.005)
          if (const double e = error(delta); e < best_error) best = delta, best_error = e;
        for (double delta = best - 0.005; delta <= best + 0.005; delta += 0.0005)
          if (const double e = error(delta); e < best_error) best = delta, best_error = e;
        if (best_error <= 0.01 && best != 0.0) {
          for (std::optional<ExecTrajectory>* traj : {&current_, &previous_})
            if (*traj) {
              (*traj)->start_time_s -= best;
              (*traj)->brake_start_s -= best;
            }
          ++server_resyncs_;
          char text[160];
          std::snprintf(text, sizeof(text), "timing re-synchronised with the trajectory server by %+.3f s", -best);
          if (!out->message.empty()) out->message += "; ";
          out->message += text;
        }
      }
    }
  } else if (sp.mode == ServerSetpoint::Mode::kHold && settled) {
    const FlatState commanded = takeoverStateLocked(sp.stamp_s);
    if (commanded.velocity.norm() > config_.stopped_speed_mps)
      why = "it holds while the commanded trajectory moves";
    else if ((commanded.position - sp.position).norm() > config_.server_position_tolerance_m)
      why = "it holds away from the commanded position";
  }
  if (why.empty()) {
    server_reported_ = false;
    return false;
  }
  out->server_diverged = true;
  if (sp.mode != ServerSetpoint::Mode::kHold) {
    if (!server_reported_) {
      server_reported_ = true;
      if (!out->message.empty()) out->message += "; ";
      out->message += "the trajectory server does not follow the commanded trajectory (" + why +
                      "): waiting for its hold (no heartbeat meanwhile, so its watchdog stops the vehicle)";
    }
    return true;
  }
  // At its hold: that is the commanded state now. Hold there (a trajectory at rest, continuous with
  // the server's setpoint) and replan from it (EMERGENCY_STOP: from rest through the goals left).
  server_reported_ = false;
  server_anchor_s_ = t;
  const FlatState hold = FlatState::atRest(sp.position);
  emergencyStopLocked(t, map, "the trajectory server holds on its own (" + why + "): holding there", out, &hold,
                      ReplanStatus::kInvalidInput);
  return true;
}

int ReplanFsm::serverResyncs() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return server_resyncs_;
}

void ReplanFsm::setDepthFused(double stamp_s, double arrival_s) {
  if (std::isnan(arrival_s)) arrival_s = stamp_s;
  if (!std::isfinite(stamp_s) || !std::isfinite(arrival_s)) return;
  std::lock_guard<std::mutex> lock(mutex_);
  // Stamped ahead of its arrival (another time base, a forged stamp): taken, every later frame would
  // look older than it, and depth stale.
  if (stamp_s - arrival_s > config_.odom_max_age_s) return;
  // The caller may pass the same (last) frame again and again; only a new one counts. Its arrival is
  // history, not the clock, so it does not feed the time-jump detection.
  if (have_raw_depth_ && stamp_s == raw_depth_stamp_s_) return;
  have_raw_depth_ = true;
  raw_depth_stamp_s_ = stamp_s;
  if (have_depth_ && stamp_s < depth_stamp_s_) return;
  have_depth_ = true;
  depth_stamp_s_ = stamp_s;
  depth_arrival_s_ = arrival_s;
}

bool ReplanFsm::inputsFreshLocked(double now, std::string* why) const {
  char text[128];
  if (!have_odom_) {
    *why = "no odometry";
    return false;
  }
  if (now - odom_arrival_s_ > config_.odom_timeout_s) {
    std::snprintf(text, sizeof(text), "no odometry for %.2f s", now - odom_arrival_s_);
    *why = text;
    return false;
  }
  if (std::abs(now - odom_time_s_) > config_.odom_max_age_s) {
    std::snprintf(text, sizeof(text), "odometry stamped %.2f s %s", std::abs(now - odom_time_s_),
                  now > odom_time_s_ ? "ago" : "in the future");
    *why = text;
    return false;
  }
  if (config_.depth_timeout_s > 0.0) {
    if (!have_depth_) {
      *why = "no depth frame fused yet";
      return false;
    }
    if (std::abs(now - depth_stamp_s_) > config_.depth_timeout_s) {
      std::snprintf(text, sizeof(text), "last depth frame fused is %.2f s old", now - depth_stamp_s_);
      *why = text;
      return false;
    }
  }
  why->clear();
  return true;
}

InputHealth ReplanFsm::inputHealth(double t) const {
  std::lock_guard<std::mutex> lock(mutex_);
  InputHealth h;
  h.ok = inputsFreshLocked(t, &h.why);
  h.depth_age_s = have_depth_ ? t - depth_stamp_s_ : -1.0;
  h.odom_age_s = have_odom_ ? t - odom_time_s_ : -1.0;
  return h;
}

void ReplanFsm::observeClockLocked(double now, FsmOutput* out) {
  if (!std::isfinite(now)) return;
  if (!have_clock_) {
    have_clock_ = true;
    last_clock_s_ = now;
    return;
  }
  const double step = now - last_clock_s_;
  // Calls from several threads read the clock before taking the lock, so small steps back are
  // ordering, not time jumps; a longer step back is one (the trajectory server shifts at any step
  // back: a 0.78 s step back, taken for ordering, left every later input "out of order" and the
  // two a vehicle-length apart, in make bench-faults).
  const double backward_limit = std::min(config_.time_jump_threshold_s, kMaxClockDisorderS);
  if (step <= config_.time_jump_threshold_s && step >= -backward_limit) {
    if (step > 0.0) typical_step_s_ = 0.9 * typical_step_s_ + 0.1 * step;
    last_clock_s_ = std::max(last_clock_s_, now);
    return;
  }
  // The clock also went on by about one usual interval between the two calls.
  const double shift = step - typical_step_s_;
  // A time jump: everything stamped on the old clock moves with it, so the commanded motion goes
  // on where it was (the trajectory server shifts its copy the same way) and inputs are not
  // taken for stale (or fresh) by the step alone.
  for (std::optional<ExecTrajectory>* traj : {&current_, &previous_})
    if (*traj) {
      (*traj)->start_time_s += shift;
      (*traj)->brake_start_s += shift;
    }
  // Input stamps may already be in the new time base (an input that arrived before this process's
  // clock stepped): only those nearer the old clock than the new one move.
  auto shiftOld = [&](double* x) {
    if (std::abs(*x - last_clock_s_) < std::abs(*x - now)) *x += shift;
  };
  shiftOld(&odom_time_s_);
  odom_arrival_s_ += shift;  // arrivals are read from this clock
  shiftOld(&depth_stamp_s_);
  shiftOld(&depth_arrival_s_);
  if (server_) shiftOld(&server_->stamp_s);
  shiftOld(&server_anchor_s_);
  last_progress_s_ += shift;  // read from this clock
  look_hold_since_s_ += shift;
  progress_.shift(shift);
  progress_tick_s_ += shift;
  rest_retry_after_s_ += shift;    // the paced retries keep their pace
  moving_retry_after_s_ += shift;
  last_clock_s_ = now;
  ++time_jumps_;
  time_jumped_ = true;
  time_jump_clock_s_ = now;
  if (!out->message.empty()) out->message += "; ";
  char text[128];
  std::snprintf(text, sizeof(text), "time jump of %+.3f s: timing shifted by %+.3f s, replanning from the current state",
                step, shift);
  out->message += text;
}

int ReplanFsm::timeJumps() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return time_jumps_;
}

std::vector<Eigen::Vector3d> ReplanFsm::remainingGoalsLocked() const {
  if (next_goal_ >= goals_.size()) return goals_.empty() ? goals_ : std::vector<Eigen::Vector3d>{goals_.back()};
  return std::vector<Eigen::Vector3d>(goals_.begin() + long(next_goal_), goals_.end());
}

std::vector<Eigen::Vector3d> ReplanFsm::remainingGoals() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return remainingGoalsLocked();
}

Path ReplanFsm::route() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return route_;
}

GoalStatus ReplanFsm::setGoals(const std::vector<Eigen::Vector3d>& goals) {
  std::lock_guard<std::mutex> lock(mutex_);
  return acceptGoalsLocked(goals);
}

GoalStatus ReplanFsm::setGoals(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map) {
  std::lock_guard<std::mutex> lock(mutex_);
  bool finite = !goals.empty();
  for (const Eigen::Vector3d& g : goals) finite = finite && g.allFinite();
  std::string why;
  const GoalStatus on_map = finite ? checkGoalsLocked(goals, map, &why) : GoalStatus::kAccepted;
  if (on_map != GoalStatus::kAccepted) return last_goal_status_ = on_map;
  return acceptGoalsLocked(goals);
}

GoalStatus ReplanFsm::checkGoalsLocked(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map,
                                       std::string* why) const {
  for (size_t i = 0; i < goals.size(); ++i) {
    const DistanceQuery q = map.query(goals[i]);
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput) {
      *why = "goal " + std::to_string(i) + " is outside the map";
      return GoalStatus::kGoalOutOfMap;
    }
    if (q.distance < config_.goal_clearance_m) {
      *why = "goal " + std::to_string(i) + " is " + std::to_string(q.distance) + " m from an obstacle";
      return GoalStatus::kGoalInObstacle;
    }
  }
  return GoalStatus::kAccepted;
}

GoalStatus ReplanFsm::acceptGoalsLocked(const std::vector<Eigen::Vector3d>& goals) {
  if (goals.empty()) return last_goal_status_ = GoalStatus::kInvalidInput;
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) return last_goal_status_ = GoalStatus::kInvalidInput;
  if (!have_odom_) return last_goal_status_ = GoalStatus::kNoOdometry;
  std::string why;
  if (!have_clock_ || !inputsFreshLocked(last_clock_s_, &why)) return last_goal_status_ = GoalStatus::kInputsStale;
  // Refused here, not at the next tick: a flood of such goals (any host can publish them) would
  // otherwise replace valid goals not yet taken up, and clear the global route of the mission flown.
  if (map_geometry_)
    for (const Eigen::Vector3d& g : goals)
      if (!map_geometry_->inWindow(g)) return last_goal_status_ = GoalStatus::kGoalOutOfMap;
  pending_goals_ = goals;
  goals_pending_ = true;
  new_mission_ = true;
  rerouting_ = false;
  rerouted_since_success_ = false;
  route_stale_ = true;
  ++route_epoch_;
  return GoalStatus::kAccepted;
}

void ReplanFsm::setState(FsmState s, FsmOutput* out, const std::string& why) {
  if (s == state_) return;
  if (!out->message.empty()) out->message += "; ";
  out->message += std::string(toString(state_)) + " -> " + toString(s) + (why.empty() ? "" : " (" + why + ")");
  state_ = s;
}

void ReplanFsm::replaceCurrentLocked(const ExecTrajectory& next) {
  // The one it replaces is still flown until the new one's start time (a planned trajectory takes
  // over takeover_delay_s after planning began): the state before then is on it.
  if (current_) previous_ = current_;
  current_ = next;
}

const ExecTrajectory* ReplanFsm::flownAtLocked(double t) const {
  if (!current_) return nullptr;
  // Before the current one's start, the one it replaces: flown then, or (t a rounding error before
  // its own start: 26.15 + 0.1 > 26.25) about to be. The current one, clamped to its later start,
  // would put the state where the vehicle is only later (a stop from there stepped the setpoint).
  if (previous_ && t < current_->start_time_s) return &*previous_;
  return &*current_;
}

FlatState ReplanFsm::takeoverStateLocked(double t_takeover) const {
  if (!current_) {
    // Not commanded yet: the trajectory server holds (a restarted planner: where its stop ended), or
    // the controller holds the position where it started.
    if (server_ && (server_->mode == ServerSetpoint::Mode::kHold || server_->mode == ServerSetpoint::Mode::kBeforeFirst) &&
        std::abs(t_takeover - server_->stamp_s) <= config_.server_timeout_s + 1.0)
      return FlatState::atRest(server_->position);
    return FlatState::atRest(odom_position_);
  }
  const ExecTrajectory& flown = *flownAtLocked(t_takeover);
  const UniformBspline& s = flown.spline;
  const double tau = std::clamp(t_takeover - flown.start_time_s, 0.0, s.duration());
  FlatState st;
  st.position = s.evaluate(tau);
  const UniformBspline vel = s.derivative();
  st.velocity = vel.evaluate(tau);
  if (vel.degree() >= 1) {
    const UniformBspline acc = vel.derivative();
    st.acceleration = acc.evaluate(tau);
    if (acc.degree() >= 1) st.jerk = acc.derivative().evaluate(tau);
  }
  if (tau >= s.duration()) st.velocity = st.acceleration = st.jerk = Eigen::Vector3d::Zero();
  return st;
}

double ReplanFsm::referenceTimeAtLocked(double t) const {
  if (!current_ || current_->manoeuvre()) return 0.0;
  const double d = current_->spline.duration();
  const double frac = d > 0.0 ? std::clamp((t - current_->start_time_s) / d, 0.0, 1.0) : 1.0;
  const double estimate = current_->reference_start_s + frac * (current_->reference_end_s - current_->reference_start_s);
  // The local trajectory is timed differently from the reference (detours, time reallocation): take
  // the reference point closest to where the vehicle will be, near the proportional estimate.
  const Eigen::Vector3d p = current_->spline.evaluate(std::clamp(t - current_->start_time_s, 0.0, d));
  double best = estimate, best_d2 = (reference_.position(estimate) - p).squaredNorm();
  for (double s = std::max(0.0, estimate - 2.0); s <= std::min(reference_.duration(), estimate + 2.0); s += 0.01) {
    const double d2 = (reference_.position(s) - p).squaredNorm();
    if (d2 < best_d2) best = s, best_d2 = d2;
  }
  return best;
}

double ReplanFsm::stopTimeLocked(double t, double deceleration) const {
  return takeoverStateLocked(t).velocity.norm() / deceleration + config_.emergency_margin_s + takeover_delay_s_;
}

double ReplanFsm::firstCollisionTime(const ExecTrajectory& traj, double t, const EsdfMap& map) const {
  const double begin = std::max(t, traj.start_time_s), end = traj.endTime();
  for (double s = begin;; s = std::min(end, s + config_.safety_sample_s)) {
    const DistanceQuery q = map.query(traj.spline.evaluate(s - traj.start_time_s));
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput ||
        q.distance < config_.safety_clearance_m)
      return s;
    if (s >= end) break;
  }
  return -1.0;
}

ExecTrajectory ReplanFsm::brakingTrajectory(double t, const EsdfMap& map, std::string* report,
                                           const FlatState* from) const {
  FlatState s0 = from ? *from : takeoverStateLocked(t);
  if (!current_ && !from) s0.velocity = odom_velocity_;
  const double speed = s0.velocity.norm();
  // Nearly at rest: a hold where it is, from the commanded velocity and acceleration (the end of a
  // stop still decelerating), so neither steps.
  const Eigen::Vector3d creep = s0.velocity;
  if (speed < 0.05) s0.velocity.setZero();
  // Along the current trajectory's path, which was checked when it was published: a stop on a curve
  // stays on the curve instead of leaving it along the tangent. Without one (or from another state),
  // along the velocity.
  // (The trajectory flown at t: a plan waiting for its takeover is not flown yet.)
  const ExecTrajectory* flown = from ? nullptr : flownAtLocked(t);
  const bool along_path = flown && t - flown->start_time_s < flown->spline.duration();
  std::optional<PathByLength> path;
  if (along_path) {
    path.emplace(flown->spline, t - flown->start_time_s, 0.01);
    if (speed >= 0.05) path->setDirection(s0.velocity);
  }
  auto brakeAt = [&](double a) {
    std::vector<Eigen::Vector3d> points;
    double interval = 0.1;
    Eigen::Vector3d start_acc = Eigen::Vector3d::Zero(), start_vel = s0.velocity;
    if (speed < 0.05) {
      points.assign(4, s0.position);
      start_vel = creep;
      start_acc = s0.acceleration;
    } else if (path) {
      // From the flown acceleration (the curve's included): no step in the commanded acceleration.
      points = stopPoints(*path, 0.0, speed, a, alongAcceleration(s0.velocity, s0.acceleration), &interval);
      points.front() = s0.position;
      start_acc = s0.acceleration;
    } else {
      const Eigen::Vector3d u = s0.velocity / speed;
      const double a0 = alongAcceleration(s0.velocity, s0.acceleration);
      const StopProfile stop(speed, a, a0);
      const int n = std::max(4, int(std::ceil(stop.duration() / 0.05)));
      interval = stop.duration() / n;
      for (int k = 0; k <= n; ++k) points.push_back(s0.position + u * stop.distance(k * interval));
      start_acc = a0 * u;  // along the line of the stop
    }
    ExecTrajectory brake;
    brake.start_time_s = t;
    brake.braking = true;
    if (!UniformBspline::fitToPoints(points, interval, start_vel, start_acc, Eigen::Vector3d::Zero(),
                                     Eigen::Vector3d::Zero(), 3, &brake.spline)) {
      // Only for a degenerate state; hold the position instead (a spline of equal points).
      brake.spline = UniformBspline::straightLine(s0.position, s0.position, 6, 3, 0.1);
    }
    brake.brake_start_s = t;
    return brake;
  };
  // At the planner's limit when that stops in time; harder (up to the vehicle's) when it does not.
  double a = config_.brake_acc_mps2;
  ExecTrajectory brake = brakeAt(a);
  double hit = firstCollisionTime(brake, t, map);
  // (Not from a re-anchored state: after an odometry jump the map is in the old frame.)
  while (hit >= 0.0 && speed >= 0.05 && a < config_.max_brake_acc_mps2 && !from) {
    a = std::min(config_.max_brake_acc_mps2, 1.25 * a);
    brake = brakeAt(a);
    hit = firstCollisionTime(brake, t, map);
  }
  if (report) {
    char decel[96];
    std::snprintf(decel, sizeof(decel), "braking at %.2f m/s^2 %s", speed < 0.05 ? 0.0 : a,
                  path ? "along the path " : "");
    *report = std::string(decel) + (hit < 0.0 ? "checked: collision-free"
                                              : "checked: comes within the safety clearance " +
                                                    std::to_string(hit - t) + " s after braking starts");
  }
  return brake;
}

ReferenceConfig ReplanFsm::referenceConfigLocked() const {
  ReferenceConfig r = config_.reference;
  r.max_vel_mps = std::min(r.max_vel_mps, cruiseSpeed(config_));
  return r;
}

KnownSpaceCommitment::Config ReplanFsm::commitmentConfig(const Config& c) {
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

bool ReplanFsm::commitToKnownSpace(const UniformBspline& plan, double t0, const EsdfMap& map, ExecTrajectory* traj,
                                   std::string* why) const {
  KnownSpaceCommitment::Committed c;
  if (!KnownSpaceCommitment(commitmentConfig(config_)).commit(plan, map, known_anchor_, &c, why)) return false;
  traj->spline = std::move(c.spline);
  traj->brake_start_s = t0 + c.brake_start_tau_s;
  traj->stops_before_unknown = c.stops_before_unknown;
  traj->has_heading_target = c.heading_target.has_value();
  if (c.heading_target) traj->heading_target = *c.heading_target;
  return true;
}

std::optional<ExecTrajectory> ReplanFsm::escapeTrajectoryLocked(double t, const EsdfMap& map,
                                                                std::string* report) const {
  const Eigen::Vector3d p0 = takeoverStateLocked(t).position;
  double d0 = 0.0;
  if (!(config_.max_escape_length_m > 0.0) || !map.interpolate(p0, &d0, nullptr)) {
    *report = "no escape: disabled, or the vehicle is outside the map";
    return std::nullopt;
  }
  const double target = config_.escape_clearance_m;
  std::vector<Eigen::Vector3d> walk;
  const bool reached = ascendDistance(map, p0, [&](const Eigen::Vector3d& p) {
    double d = 0.0;
    return map.interpolate(p, &d, nullptr) && d >= target;
  }, config_.max_escape_length_m, &walk);
  // A walk that stops short of the target (on a ridge between obstacles) still escapes when it
  // ended at least escape_min_clearance_m from obstacles.
  double d_end = -INFINITY;
  if (!walk.empty()) map.interpolate(walk.back(), &d_end, nullptr);
  if (walk.size() < 2 || (!reached && !(d_end >= config_.escape_min_clearance_m))) {
    *report = "no escape: no way up the distance field to " + std::to_string(config_.escape_min_clearance_m) +
              " m within " + std::to_string(config_.max_escape_length_m) + " m (from " + std::to_string(d0) + " m)";
    return std::nullopt;
  }
  std::optional<ExecTrajectory> escape = restToRestLocked(walk, t, map, d0, config_.escape_speed_mps, "escape", report);
  if (!escape || !report->empty()) return escape;
  char text[160];
  std::snprintf(text, sizeof(text), "escape: %.2f m up the distance field from %.2f m to %.2f m clearance in %.1f s",
                pathLength(walk), d0, d_end, escape->spline.duration());
  *report = text;
  return escape;
}

std::optional<ExecTrajectory> ReplanFsm::backoffTrajectoryLocked(double t, const EsdfMap& map, std::string* report,
                                                                 bool* to_anchor_out) const {
  const Eigen::Vector3d p0 = takeoverStateLocked(t).position;
  double d0 = 0.0;
  if (!map.interpolate(p0, &d0, nullptr)) {
    *report = "no back-off: the vehicle is outside the map";
    return std::nullopt;
  }
  // Back along the flown path (newest first) until backoff_length_m is flown and the point keeps
  // escape_clearance_m, or max_backoff_length_m.
  std::vector<Eigen::Vector3d> walk{p0};
  double length = 0.0, d_end = d0;
  for (auto it = flown_.rbegin(); it != flown_.rend(); ++it) {
    const double step = (*it - walk.back()).norm();
    if (step < 0.05) continue;
    if (length + step > config_.max_backoff_length_m) break;
    walk.push_back(*it);
    length += step;
    if (!map.interpolate(*it, &d_end, nullptr)) d_end = -INFINITY;
    if (length >= config_.backoff_length_m && d_end >= config_.escape_clearance_m) break;
  }
  bool to_anchor = false;
  if (length < std::min(0.3, config_.backoff_length_m) || walk.size() < 2) {
    // No flown path since the vehicle hovered without having flown there (a mission's start, or at
    // rest after a re-anchoring cleared the map): back to that hover, the known anchor, when it has
    // crept away from it within the anchor's zone. There the blind zone beside the camera counts as
    // known; from where it crept to, the space just ahead (seen by the camera, its clearance ball
    // not) is neither, and every plan was cut to a hold (fault_odom_blackout held 60 s).
    const double from_anchor = known_anchor_ ? (p0 - *known_anchor_).norm() : INFINITY;
    if (!(from_anchor >= 0.1 && from_anchor <= config_.known_start_radius_m + 0.05)) {
      *report = "no back-off: no flown path to go back along";
      return std::nullopt;
    }
    walk = {p0, *known_anchor_};
    length = from_anchor;
    if (!map.interpolate(*known_anchor_, &d_end, nullptr)) d_end = -INFINITY;
    to_anchor = true;
  }
  // The flown path zig-zags where the vehicle hovered and re-planned: shortcut it where the straight
  // way keeps the clearance the vehicle had (or the safety clearance), so the manoeuvre has no corners.
  const double keep = std::min(d0, config_.safety_clearance_m);
  auto straightIsClear = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const int n = std::max(1, int(std::ceil((b - a).norm() / 0.05)));
    for (int k = 0; k <= n; ++k) {
      double d = 0.0;
      if (!map.interpolate(a + (b - a) * (double(k) / n), &d, nullptr) || d < keep) return false;
    }
    return true;
  };
  std::vector<Eigen::Vector3d> smooth{walk.front()};
  for (size_t i = 0; i + 1 < walk.size();) {
    size_t j = walk.size() - 1;
    while (j > i + 1 && !straightIsClear(walk[i], walk[j])) --j;
    smooth.push_back(walk[j]);
    i = j;
  }
  walk = std::move(smooth);
  std::optional<ExecTrajectory> backoff = restToRestLocked(walk, t, map, d0, config_.backoff_speed_mps, "back-off", report);
  if (to_anchor_out) *to_anchor_out = to_anchor;
  if (!backoff || !report->empty()) return backoff;
  char text[160];
  std::snprintf(text, sizeof(text), "back-off: %.2f m back %s, from %.2f m to %.2f m clearance in %.1f s", length,
                to_anchor ? "to the hover it started from" : "along the flown path", d0, d_end, backoff->spline.duration());
  *report = text;
  return backoff;
}

std::optional<ExecTrajectory> ReplanFsm::restToRestLocked(const std::vector<Eigen::Vector3d>& walk, double t,
                                                          const EsdfMap& map, double d0, double speed_mps,
                                                          const char* what, std::string* report) const {
  report->clear();
  const Eigen::Vector3d p0 = walk.front();
  const FlatState s0 = takeoverStateLocked(t);  // walk.front() is its position
  std::vector<double> arc{0.0};
  for (size_t i = 1; i < walk.size(); ++i) arc.push_back(arc.back() + (walk[i] - walk[i - 1]).norm());
  const double length = arc.back();
  // Rest to rest along the walk with a smoothstep s(u) = L (3u^2 - 2u^3), whose peak speed is 1.5 L / T;
  // slowed down (at most 2 x 1.5 times: the bound is conservative, and a stretched walk must stay a
  // manoeuvre of seconds, cheap to fit) while the fitted curve's acceleration bound exceeds half the
  // braking deceleration (corners of the walk), so the vehicle tracks it closely. At most 200 points.
  ExecTrajectory escape;
  escape.start_time_s = t;
  escape.escape = true;
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  double T = std::max(0.5, 1.5 * length / speed_mps);
  for (int attempt = 0;; ++attempt) {
    const int n = std::clamp(int(std::ceil(T / 0.05)), 6, 200);
    std::vector<Eigen::Vector3d> points;
    size_t seg = 1;
    for (int k = 0; k <= n; ++k) {
      const double u = double(k) / n, s = length * u * u * (3.0 - 2.0 * u);
      while (seg + 1 < walk.size() && arc[seg] < s) ++seg;
      const double span = arc[seg] - arc[seg - 1];
      const double f = span > 0.0 ? std::clamp((s - arc[seg - 1]) / span, 0.0, 1.0) : 1.0;
      points.push_back(walk[seg - 1] + f * (walk[seg] - walk[seg - 1]));
    }
    // It starts in the state flown there (a creep below stopped_speed_mps is not a rest: no step).
    if (!UniformBspline::fitToPoints(points, T / n, s0.velocity, s0.acceleration, zero, zero, 3, &escape.spline)) {
      *report = std::string("no ") + what + ": the walk could not be fitted";
      return std::nullopt;
    }
    const double acc = escape.spline.maxAcceleration(), limit = 0.5 * config_.brake_acc_mps2;
    if (acc <= limit || attempt >= 2) break;
    T *= std::min(1.5, std::sqrt(acc / limit) * 1.05);
  }
  // Checked along the curve: never closer than it starts (nor than the safety clearance, when it
  // starts farther), never out of the map, in known space (beyond the vehicle's own radius).
  const double floor_m = std::min(d0, config_.safety_clearance_m) - 0.02;
  for (double tau = 0.0;; tau = std::min(escape.spline.duration(), tau + config_.safety_sample_s)) {
    double d = 0.0;
    const Eigen::Vector3d p = escape.spline.evaluate(tau);
    const bool known = !config_.commit_to_known_space || (p - p0).norm() <= config_.known_start_radius_m ||
                       (map.query(p).status == QueryStatus::kOk &&
                        map.occupancy().isKnownWithin(p, std::max(0.0, floor_m)));
    if (!known) {
      // Look before moving: hold here, turning the camera towards the way out (the trajectory
      // server turns to a held trajectory's heading target); the next try sees it.
      ExecTrajectory look;
      look.start_time_s = t;
      look.escape = true;
      look.spline = UniformBspline::straightLine(p0, p0, 6, 3, 0.1);
      look.brake_start_s = t;
      look.has_heading_target = true;
      look.heading_target = walk.back();
      *report = std::string(what) + ": the way crosses unknown space; holding and looking there first";
      return look;
    }
    if (!map.interpolate(p, &d, nullptr) || d < floor_m) {
      *report = std::string("no ") + what + ": the fitted manoeuvre comes closer to an obstacle than it starts";
      return std::nullopt;
    }
    if (tau >= escape.spline.duration()) break;
  }
  return escape;
}

void ReplanFsm::referenceNotRebuiltLocked(double t, const EsdfMap& map, FsmOutput* out) {
  if (last_goal_status_ != GoalStatus::kReferenceFailed) {
    // The map shows a goal of the mission in an obstacle (or out of the map window): it ends, saying why.
    giveUpLocked(t, map, last_goal_status_, ReplanStatus::kGoalInCollision,
                 std::string("the mission's goals are no longer valid (") + toString(last_goal_status_) + ")", out);
    return;
  }
  // The minimum-snap reference could not be built from the state it starts from (its limits, from a
  // fast or turning state): the goals are still valid. A moving vehicle stops and rebuilds it from
  // rest; at rest it is tried again at the next tick (the mission's time limit bounds the tries).
  last_goal_status_ = GoalStatus::kAccepted;
  const bool moving = current_ && !current_->manoeuvre() && t < current_->endTime();
  if (moving) {
    emergencyStopLocked(t, map, "the mission's reference could not be rebuilt from the moving state: stopping to "
                        "rebuild it from rest", out, nullptr, ReplanStatus::kInvalidInput);
    return;
  }
  ++consecutive_failures_;
  if (state_ != FsmState::kGenNewTraj && state_ != FsmState::kEmergencyStop)
    setState(FsmState::kGenNewTraj, out, "the mission's reference could not be rebuilt: trying again");
}

void ReplanFsm::startManoeuvreLocked(ExecTrajectory manoeuvre, bool backoff, FsmEvent* event, FsmOutput* out,
                                     const std::string& why) {
  if (backoff) {
    ++backoffs_;
    look_holds_ = 0;
    // The way back is used up: a later back-off goes on from where this one ends.
    const Eigen::Vector3d end = manoeuvre.spline.evaluate(manoeuvre.spline.duration());
    while (!flown_.empty() && (flown_.back() - end).norm() > 0.3) flown_.pop_back();
  }
  manoeuvre.id = next_id_++;
  replaceCurrentLocked(manoeuvre);
  consecutive_failures_ = 0;  // a new start: the tries after it are counted anew
  failures_at_stall_ = 0;
  failures_at_reroute_ = 0;
  route_stale_ = true;        // searched again from where it ends
  ++route_epoch_;
  collision_ahead_ = false;
  event->published = true;
  event->fallback = backoff ? "back_off" : "escape";
  out->trajectory = manoeuvre;
  setState(FsmState::kEmergencyStop, out, why);
}

void ReplanFsm::addStallZoneLocked(const GlobalRouter::Zone& zone) {
  stall_zones_.push_back(zone);
  if (stall_zones_.size() > kMaxStallZones) stall_zones_.erase(stall_zones_.begin());
}

bool ReplanFsm::handleStallLocked(double t, const EsdfMap& map, FsmOutput* out) {
  const bool flying = state_ == FsmState::kGenNewTraj || state_ == FsmState::kExecTraj ||
                      state_ == FsmState::kReplanTraj || state_ == FsmState::kEmergencyStop;
  if (!config_.global_route || !(config_.progress_timeout_s > 0.0) || !progress_.active() || goals_.empty() || !flying)
    return false;
  const FlatState here = takeoverStateLocked(t);
  progress_.update(t, here.position);
  progress_tick_s_ = t;
  if (progress_.lastGain() != stall_gain_s_) {  // progress: the remedies start over
    stall_gain_s_ = progress_.lastGain();
    stalls_ = 0;
  }
  const bool at_rest = (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kReroute;
  event.state = state_;
  event.status = ReplanStatus::kSuccess;
  event.position = here.position;
  std::string report;
  // A stop begun as a remedy has ended: back off from there.
  if (backoff_when_stopped_ && state_ == FsmState::kEmergencyStop && at_rest) {
    backoff_when_stopped_ = false;
    std::optional<ExecTrajectory> backoff = backoffTrajectoryLocked(t, map, &report);
    if (backoff) {
      event.message = "no progress: " + report;
      startManoeuvreLocked(*backoff, true, &event, out, report);
      out->event = event;
      return true;
    }
    // None: the stopped vehicle plans anew from where it is (EMERGENCY_STOP's own rule).
    if (!out->message.empty()) out->message += "; ";
    out->message += report;
    return false;
  }
  const double since = progress_.sinceGain(t);
  char text[200];
  std::snprintf(text, sizeof(text), "no progress towards the goal for %.0f s (%.1f m left, %.1f m when it last gained)",
                since, progress_.remaining(), progress_.best());
  if (since > mission_limit_s_) {
    char limit[220];
    std::snprintf(limit, sizeof(limit),
                  "no progress towards the goal for the mission's time limit of %.0f s (%.1f m left, %.1f m when it "
                  "last gained)", mission_limit_s_, progress_.remaining(), progress_.best());
    giveUpLocked(t, map, GoalStatus::kGivenUp, ReplanStatus::kSuccess, limit, out);
    return true;
  }
  const bool manoeuvring = current_ && current_->manoeuvre() && t < current_->endTime();
  const bool forced = std::exchange(force_stall_, false);
  if ((since < (stalls_ + 1) * config_.progress_timeout_s && !forced) || manoeuvring || goals_pending_ ||
      backoff_when_stopped_)
    return false;
  if (forced) {
    std::snprintf(text, sizeof(text), "%d plans failed at rest, no back-off left (%.1f m left)",
                  config_.max_plan_failures, progress_.remaining());
  }
  // A stall: the next remedy. Every one marks the place for the route searches to avoid.
  ++stalls_;
  // The zone lies ahead along the way, where the vehicle was heading (one around the vehicle alone
  // weighs on every way out of it alike).
  if (config_.stall_zone_radius_m > 0.0)
    addStallZoneLocked({progress_.ahead(config_.stall_zone_radius_m), config_.stall_zone_radius_m});
  route_stale_ = true;
  event.message = text;
  if (stalls_ % 2 == 0 && backoffs_ < config_.max_backoffs) {
    if (!at_rest) {
      // Stop first (the back-off starts from rest), then back off (above).
      emergencyStopLocked(t, map, std::string(text) + ": stopping to back off", out, nullptr, ReplanStatus::kSuccess);
      out->event->trigger = FsmEvent::Trigger::kReroute;
      backoff_when_stopped_ = true;
      return true;
    }
    std::optional<ExecTrajectory> backoff = backoffTrajectoryLocked(t, map, &report);
    if (backoff) {
      event.message += "; " + report;
      startManoeuvreLocked(*backoff, true, &event, out, report);
      out->event = event;
      return true;
    }
    event.message += "; " + report;
  }
  // Re-route from where the vehicle is (at the next tick), around the places it stalled at.
  if (state_ == FsmState::kExecTraj || state_ == FsmState::kReplanTraj) {
    pending_goals_ = remainingGoalsLocked();
    goals_pending_ = !pending_goals_.empty();
    rerouting_ = goals_pending_;
  }
  event.fallback = "reroute";
  event.message += "; re-routing around where it stalled";
  out->event = event;
  if (!out->message.empty()) out->message += "; ";
  out->message += event.message;
  return true;
}

void ReplanFsm::giveUpLocked(double t, const EsdfMap& map, GoalStatus status, ReplanStatus replan_status,
                             const std::string& why, FsmOutput* out) {
  const std::string reason = "mission given up: " + why;
  last_goal_status_ = status;
  goals_.clear();
  next_goal_ = 0;
  if (rerouting_) goals_pending_ = false;  // the re-route of this mission; new goals (setGoals) stay pending
  rerouting_ = false;
  rerouted_since_success_ = false;
  route_.clear();
  route_goals_.clear();
  markRouteLocked(map);
  consecutive_failures_ = 0;
  failures_at_stall_ = 0;
  progress_.clear();
  backoff_when_stopped_ = false;
  const bool moving = current_ && !current_->braking && t < current_->endTime();
  if (moving) {
    // A controlled stop along the current path (an escape or back-off under way is cut short too);
    // with no goals left the stop ends in WAIT_TARGET.
    emergencyStopLocked(t, map, reason, out, nullptr, replan_status);
    out->event->fallback = "give_up";
    return;
  }
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kRetry;
  event.state = state_;
  event.status = replan_status;
  event.fallback = "give_up";
  event.message = reason;
  event.position = takeoverStateLocked(t).position;
  out->event = event;
  setState(FsmState::kWaitTarget, out, reason);
}

void ReplanFsm::markRouteLocked(const EsdfMap& map) {
  route_samples_.clear();
  route_sample_blocked_.clear();
  route_sample_at_ = 0;
  const double step = map.geometry().resolution();
  for (size_t i = 1; i < route_.size(); ++i) {
    const Eigen::Vector3d a = route_[i - 1], b = route_[i];
    const int n = std::max(1, int(std::ceil((b - a).norm() / step)));
    for (int k = i == 1 ? 0 : 1; k <= n; ++k) route_samples_.push_back(a + (b - a) * (double(k) / n));
  }
  route_sample_blocked_.reserve(route_samples_.size());
  for (const Eigen::Vector3d& p : route_samples_) {
    const DistanceQuery q = map.query(p);
    const bool known = q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown;
    route_sample_blocked_.push_back(known && q.distance < config_.safety_clearance_m);
  }
}

namespace {
// The route check looks for a way past an obstacle on the route this far across it (the local
// search's reach: its sampling box extends 3.5 m to each side of the local segment) [m].
constexpr double kRouteBypassM = 3.0;
}  // namespace

bool ReplanFsm::routeBlockedLocked(double t, const EsdfMap& map, FsmOutput* out) {
  if (!config_.global_route || !(config_.route_check_length_m > 0.0) || route_samples_.empty() || goals_.empty() ||
      route_goals_ != remainingGoalsLocked() || t - route_checked_s_ < config_.route_check_interval_s)
    return false;
  route_checked_s_ = t;
  // Where along the route the vehicle is: the nearest sample within 20 m on from the last one found
  // (a route that doubles back around a wall is not short-cut to its later part).
  const double step = map.geometry().resolution();
  const Eigen::Vector3d here = takeoverStateLocked(t).position;
  const size_t window = size_t(20.0 / step);
  size_t at = route_sample_at_;
  double best = INFINITY;
  for (size_t i = route_sample_at_; i < route_samples_.size() && i <= route_sample_at_ + window; ++i) {
    const double d = (route_samples_[i] - here).squaredNorm();
    if (d < best) best = d, at = i;
  }
  route_sample_at_ = at;
  auto blockedAt = [&](const Eigen::Vector3d& p, double* distance) {
    const DistanceQuery q = map.query(p);
    *distance = q.distance;
    return (q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown) && q.distance < config_.safety_clearance_m;
  };
  // A way past the obstacle within the local search's reach: a point of the obstacle's face (the
  // plane through the blocked sample across the distance field's gradient in front of it, i.e. along
  // a wall however the route crosses it), within kRouteBypassM of the sample, inside the height band
  // and the map, and at the route's clearance from every known obstacle: beside a tree or a pillar,
  // or in a window near the route, all the local planner's. None: a wall across the way, which the
  // route must pass through an opening farther aside (or around its unseen part).
  const double band_lo = std::max(config_.route.min_z_m, map.geometry().windowMin().z() + step);
  const double band_hi = std::min(config_.route.max_z_m, map.geometry().windowMax().z() - step);
  auto bypassed = [&](size_t i) {
    const Eigen::Vector3d p = route_samples_[i];
    Eigen::Vector3d normal = i > 0 ? map.query(route_samples_[i - 1]).gradient : Eigen::Vector3d::Zero();
    if (!(normal.norm() > 0.1)) normal = route_samples_[std::min(i + 1, route_samples_.size() - 1)] - route_samples_[i > 0 ? i - 1 : 0];
    if (!(normal.norm() > 1e-6)) normal = Eigen::Vector3d::UnitX();
    normal.normalize();
    // Across the face: horizontal along it, and up it (vertical for a vertical face).
    Eigen::Vector3d along = normal.cross(Eigen::Vector3d::UnitZ());
    along = along.norm() > 0.1 ? along.normalized() : Eigen::Vector3d::UnitX();
    const Eigen::Vector3d up = along.cross(normal).normalized();
    const int n = int(std::round(kRouteBypassM / step));
    for (int a = -n; a <= n; ++a)
      for (int b = -n; b <= n; ++b) {
        const Eigen::Vector3d q = p + along * (a * step) + up * (b * step);
        if (q.z() < band_lo || q.z() > band_hi) continue;
        const DistanceQuery d = map.query(q);
        if ((d.status == QueryStatus::kOk || d.status == QueryStatus::kUnknown) && d.distance >= config_.route.clearance_m)
          return true;
      }
    return false;
  };
  // From 1 m ahead of the vehicle (the local planner's), up to the check length.
  const size_t first = at + size_t(1.0 / step), last = at + size_t(config_.route_check_length_m / step);
  bool in_bypassed = false;  // within an obstacle found bypassable: its next samples need no new look
  for (size_t i = first; i < route_samples_.size() && i <= last; ++i) {
    double distance = 0.0;
    if (route_sample_blocked_[i] || !blockedAt(route_samples_[i], &distance)) {
      in_bypassed = false;  // (as close when it was searched: not news)
      continue;
    }
    if (in_bypassed) continue;
    if (bypassed(i)) {
      in_bypassed = true;
      continue;
    }
    char text[200];
    std::snprintf(text, sizeof(text),
                  "the route is blocked %.1f m ahead at (%.2f, %.2f, %.2f) (%.2f m from a known obstacle): re-routing",
                  double(i - at) * step, route_samples_[i].x(), route_samples_[i].y(), route_samples_[i].z(),
                  distance);
    reroute_reason_ = text;
    route_stale_ = true;
    pending_goals_ = remainingGoalsLocked();
    goals_pending_ = !pending_goals_.empty();
    rerouting_ = goals_pending_;
    if (!out->message.empty()) out->message += "; ";
    out->message += text;
    return true;
  }
  return false;
}

void ReplanFsm::routeLocked(double t, const EsdfMap& map, std::unique_lock<std::mutex>* lock, FsmOutput* out,
                            const std::function<double()>& now, double* searched_until) {
  // Does this tick start (or rebuild) a reference, and through which goals?
  const bool at_rest = (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
  bool starts = false;
  switch (state_) {
    case FsmState::kInit: starts = goals_pending_ && have_odom_; break;
    case FsmState::kWaitTarget:
    case FsmState::kExecTraj:
    case FsmState::kReplanTraj: starts = goals_pending_; break;
    case FsmState::kGenNewTraj: starts = true; break;
    case FsmState::kEmergencyStop: starts = at_rest && (goals_pending_ || !goals_.empty()); break;
  }
  if (!starts) return;
  const std::vector<Eigen::Vector3d> goals = goals_pending_ ? pending_goals_ : remainingGoalsLocked();
  if (goals.empty() || (!route_stale_ && goals == route_goals_)) return;
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) return;  // refused by startGoalsLocked
  // New goals this tick's startGoalsLocked will refuse: no search, and the route of the mission
  // flown stays (one searched for them replaced it, or cleared it when the goal's clearance
  // failed the search, and the mission went on without).
  std::string refused;
  if (goals_pending_ && !rerouting_ && checkGoalsLocked(goals, map, &refused) != GoalStatus::kAccepted) return;
  const Eigen::Vector3d start = takeoverStateLocked(t + takeover_delay_s_).position;
  const uint64_t epoch = route_epoch_;
  const bool rerouting = rerouting_;

  // The places this mission stalled at weigh against a way through them (set here: the routers are
  // tick()'s, and replaced by a reconfiguration).
  router_->setAvoided(stall_zones_);
  start_router_->setAvoided(stall_zones_);
  // The search, with the mutex released: the safety thread and the inputs go on meanwhile.
  lock->unlock();
  Path route{start};
  SearchStatus status = SearchStatus::kSuccess;
  size_t failed_leg = 0;
  int expansions = 0;
  bool near_start = false;  // some leg has a route only with the start region relaxed
  for (size_t i = 0; i < goals.size() && status == SearchStatus::kSuccess; ++i) {
    GlobalRouter::Result leg = router_->route(map, route.back(), goals[i]);
    expansions += leg.expansions;
    if (leg.status == SearchStatus::kNoPath && i == 0) {
      // Not yet a proof: the vehicle may hover in a passage narrower than the route's clearance (a
      // dead-end slot it braked in) that the small relaxed start region does not leave.
      leg = start_router_->route(map, route.back(), goals[i]);
      expansions += leg.expansions;
      near_start = leg.status == SearchStatus::kSuccess;
    }
    status = leg.status;
    failed_leg = i;
    if (status == SearchStatus::kSuccess) route.insert(route.end(), leg.path.begin() + 1, leg.path.end());
  }
  *searched_until = now ? now() : t;  // the clock, read without the mutex
  lock->lock();

  if (route_epoch_ != epoch) {
    // New goals, a stop or an odometry jump meanwhile: the search answered another question.
    return;
  }
  route_stale_ = false;
  route_goals_ = goals;
  failures_at_reroute_ = consecutive_failures_;
  char text[240];
  if (status == SearchStatus::kSuccess) {
    route_ = std::move(route);
    markRouteLocked(map);
    out->new_route = true;
    std::snprintf(text, sizeof(text), "global route: %.1f m through %zu points (%d expansions)%s", pathLength(route_),
                  route_.size(), expansions,
                  near_start ? ", narrower than its clearance near the vehicle" : "");
  } else if (status == SearchStatus::kNoPath && config_.route.unknown_is_free) {
    // Both searches exhausted the map window: with unknown space free, no way to this goal exists.
    std::snprintf(text, sizeof(text),
                  "goal %zu (%.2f, %.2f, %.2f) is unreachable in the known map: no route keeps %.2f m from obstacles "
                  "(except within %.1f m of the vehicle) within the height band [%.2f, %.2f] m",
                  failed_leg, goals[failed_leg].x(), goals[failed_leg].y(), goals[failed_leg].z(), config_.route.clearance_m,
                  start_router_->config().start_radius_m, std::max(config_.route.min_z_m, map.geometry().windowMin().z()),
                  std::min(config_.route.max_z_m, map.geometry().windowMax().z()));
    if (!out->message.empty()) out->message += "; ";
    if (goals_pending_ && !rerouting) {
      // New goals: refused like a goal in an obstacle (a mission in progress goes on).
      goals_pending_ = false;
      new_mission_ = false;
      last_goal_status_ = GoalStatus::kUnreachable;
      out->message += std::string("goal refused: ") + toString(GoalStatus::kUnreachable) + ": " + text;
      return;
    }
    giveUpLocked(t, map, GoalStatus::kUnreachable, ReplanStatus::kNoPath, text, out);
    return;
  } else {
    // No proof either way (budget, start or goal inside the route's end clearance, or unknown space
    // not free to the route): straight references.
    route_.clear();
    markRouteLocked(map);
    out->new_route = true;
    std::snprintf(text, sizeof(text), "no global route (%s at goal %zu): references go straight through the goals",
                  toString(status), failed_leg);
  }
  if (!out->message.empty()) out->message += "; ";
  out->message += text;
}

bool ReplanFsm::startGoalsLocked(double t, const EsdfMap& map, FsmOutput* out) {
  goals_pending_ = false;
  const std::vector<Eigen::Vector3d> goals = pending_goals_;
  const bool rerouted = std::exchange(rerouting_, false);
  auto refuse = [&](GoalStatus status, const std::string& why) {
    last_goal_status_ = status;
    new_mission_ = false;
    if (!out->message.empty()) out->message += "; ";
    out->message += std::string("goal refused: ") + toString(status) + ": " + why;
    return false;
  };
  if (goals.empty()) return refuse(GoalStatus::kInvalidInput, "no goals");
  std::string why;
  const GoalStatus on_map = checkGoalsLocked(goals, map, &why);
  if (on_map != GoalStatus::kAccepted) return refuse(on_map, why);
  // The reference starts from the state at which the first trajectory on it will take over.
  FlatState start = takeoverStateLocked(t + takeover_delay_s_);
  if (state_ == FsmState::kInit || state_ == FsmState::kWaitTarget || !known_anchor_) known_anchor_ = start.position;
  start.jerk.setZero();  // the reference's jerk at the start is free of the spline's knots
  std::vector<Eigen::Vector3d> waypoints{start.position};
  // Through the global route when there is one for these goals (its first point is where the
  // vehicle was when it was searched; the reference starts from where it takes over).
  const bool routed = config_.global_route && route_.size() >= 2 && route_goals_ == goals;
  if (routed) {
    for (size_t i = 1; i < route_.size(); ++i)
      if ((route_[i] - waypoints.back()).norm() > 1e-3) waypoints.push_back(route_[i]);
  } else {
    for (const Eigen::Vector3d& g : goals)
      if ((g - waypoints.back()).norm() > 1e-3) waypoints.push_back(g);
  }
  if (waypoints.size() < 2) waypoints.push_back(goals.back() + Eigen::Vector3d(1e-3, 0, 0));
  // Moving across or away from the first leg (a re-route at speed): from the velocity along it only
  // (the plans start from the vehicle's state; the profile timing is not held to the reference's ramp).
  start = referenceStartState(start, waypoints[1] - waypoints[0]);
  PolynomialTrajectory ref;
  const TrajectoryStatus status =
      referenceTrajectory(waypoints, start, FlatState::atRest(waypoints.back()), referenceConfigLocked(), &ref);
  if (status != TrajectoryStatus::kSuccess)
    return refuse(GoalStatus::kReferenceFailed, std::string("minimum-snap reference: ") + toString(status));
  goals_ = goals;
  next_goal_ = 0;
  const bool new_mission = std::exchange(new_mission_, false);
  if (new_mission) {
    last_progress_s_ = t;
    mission_limit_s_ = config_.mission_timeout_s > 0.0 ? config_.mission_timeout_s : std::max(60.0, 4.0 * ref.duration());
    backoffs_ = 0;
    MissionProgress::Config progress;
    progress.min_gain_m = config_.progress_min_gain_m;
    progress_ = MissionProgress(progress);
    stalls_ = 0;
    force_stall_ = false;
    // The places stalled at stay weighed by later missions (a return leg through them), the oldest
    // dropped beyond kMaxStallZones.
    backoff_when_stopped_ = false;
  }
  // The distance left is measured along the way the reference takes; a rebuilt one re-bases it.
  progress_.reset(waypoints, t, start.position, !new_mission);
  stall_gain_s_ = progress_.lastGain();
  progress_tick_s_ = t;
  reference_ = std::move(ref);
  last_goal_status_ = GoalStatus::kAccepted;
  out->new_reference = true;
  setState(FsmState::kGenNewTraj, out,
           std::string(rerouted ? "re-routed" : "new") + " reference, " + std::to_string(goals.size()) + " goal(s)" +
               (routed ? ", along the global route" : ""));
  return true;
}

void ReplanFsm::plan(double t, const EsdfMap& map, FsmEvent::Trigger trigger, std::unique_lock<std::mutex>* lock,
                     FsmOutput* out, const std::function<double()>& now) {
  const bool generating = state_ == FsmState::kGenNewTraj;
  const double t_take = t + takeover_delay_s_;
  ReplanRequest request;
  request.start = takeoverStateLocked(t_take);
  request.reference_time_s = generating ? 0.0 : referenceTimeAtLocked(t_take);
  request.attempt = uint32_t(consecutive_failures_);  // a retry draws another roadmap
  // An intermediate goal not reached yet bounds the local goal where the reference passes it: the
  // plans go through it (within waypoint_reached_radius_m, when it counts as reached) instead of
  // cutting its corner (1.4 m off a waypoint at the end of a wall in fault_hidden_corner).
  if (next_goal_ + 1 < goals_.size() && !reference_.empty()) {
    const double t_pass = waypointPassTime(reference_, goals_[next_goal_], request.reference_time_s,
                                           config_.waypoint_reached_radius_m);
    if (std::isfinite(t_pass)) request.max_local_goal_time_s = t_pass;
  }
  const PolynomialTrajectory reference = reference_;
  request.reference = &reference;
  const int64_t current_id = current_ ? current_->id : -1;
  FsmEvent event;
  event.trigger = trigger;
  event.state = state_;
  event.position = request.start.position;
  if (!generating) setState(FsmState::kReplanTraj, out, toString(trigger));

  lock->unlock();
  ReplanResult result = replanner_->replan(map, request);
  const double finished = now ? now() : t;
  lock->lock();
  // The plan handed on at the end of this call, after the observer saw what the FSM made of it (its
  // start-velocity and known-space checks) outside the lock: the tick ends there.
  auto conclude = [&] {
    if (plan_observer_) {
      lock->unlock();
      plan_observer_(map, request, result);
      lock->lock();
    }
    out->plan = std::move(result);
  };

  // The known-space commitment of a successful plan (on the map it was planned on).
  ExecTrajectory traj;
  if (result.status == ReplanStatus::kSuccess) {
    std::string why;
    const double step = (result.trajectory.derivative().evaluate(0.0) - request.start.velocity).norm();
    if (step > config_.max_start_velocity_step_mps) {
      char text[128];
      std::snprintf(text, sizeof(text), "its start velocity is %.2f m/s off the commanded one (limit %.2f)", step,
                    config_.max_start_velocity_step_mps);
      result.status = ReplanStatus::kOptimizationFailed;
      result.message += (result.message.empty() ? "" : "; ") + std::string(text);
    } else if (!commitToKnownSpace(result.trajectory, t_take, map, &traj, &why)) {
      result.status = ReplanStatus::kOptimizationFailed;
      result.message += (result.message.empty() ? "" : "; ") + why;
    }
  }
  event.status = result.status;
  event.message = result.message;
  const std::string reroute_reason = std::exchange(reroute_reason_, std::string());
  if (trigger == FsmEvent::Trigger::kReroute && !reroute_reason.empty())
    event.message = reroute_reason + (event.message.empty() ? "" : "; " + event.message);
  event.stats = result.stats;
  const bool superseded = (current_ ? current_->id : -1) != current_id;
  // The takeover delay adapts to the planning time: a late plan lengthens it (up to the maximum),
  // on time plans bring it back towards the configured value.
  if (finished > t_take)
    takeover_delay_s_ = std::min(config_.max_takeover_delay_s, 1.5 * (finished - t));
  else
    takeover_delay_s_ = std::max(config_.takeover_delay_s, std::max(0.9 * takeover_delay_s_, 1.5 * (finished - t)));
  if (result.status == ReplanStatus::kSuccess && !superseded && finished <= t_take) {
    traj.id = next_id_++;
    traj.start_time_s = t_take;
    traj.reference_start_s = result.local_start_time_s;
    traj.reference_end_s = result.local_goal_time_s;
    if (traj.stops_before_unknown) {
      // It rejoins the reference only as far as it goes (proportionally, refined in referenceTimeAtLocked).
      const double planned = result.trajectory.duration();
      const double frac = planned > 0.0 ? std::clamp((traj.brake_start_s - t_take) / planned, 0.0, 1.0) : 0.0;
      traj.reference_end_s = traj.reference_start_s + frac * (traj.reference_end_s - traj.reference_start_s);
    }
    traj.ends_at_goal = !traj.stops_before_unknown && result.local_goal_time_s >= reference.duration() - 1e-6;
    // A plan cut to a hold where the vehicle is (unknown space right ahead), again and again at the
    // same place: turning to look has not shown the way (it may lie above or below the camera's
    // view). Back off along the flown path, where the camera sees more, and re-route from there.
    // (A hold, or a stop a few centimetres on: the cut plans of a vehicle that hovers at the edge.)
    const bool look_hold = traj.stops_before_unknown && request.start.velocity.norm() < config_.stopped_speed_mps &&
                           (traj.spline.evaluate(traj.spline.duration()) - traj.spline.evaluate(0.0)).norm() < 0.3;
    const bool same_place = look_holds_ > 0 && (request.start.position - look_hold_position_).norm() < 0.3;
    look_holds_ = look_hold ? (same_place ? look_holds_ + 1 : 1) : 0;
    if (look_hold && !same_place) {
      look_hold_position_ = request.start.position;
      look_hold_since_s_ = t;
    }
    std::optional<ExecTrajectory> backoff;
    std::string backoff_report;
    bool to_anchor = false;
    // (Held for look_hold_min_s too: the plans of a hold come every tick, and the camera turning
    // round towards the way on needs its time; 5 holds in 0.25 s backed a vehicle off that had just
    // reached a goal and turned to the next one behind it.)
    if (config_.global_route && look_holds_ >= config_.max_look_holds && t - look_hold_since_s_ >= config_.look_hold_min_s &&
        backoffs_ < config_.max_backoffs) {
      // From the takeover time, as the plan it replaces (the hold published last tick may start
      // between now and then: taking over at t would leave it out).
      backoff = backoffTrajectoryLocked(t_take, map, &backoff_report, &to_anchor);
      if (backoff && backoff->has_heading_target) backoff.reset();  // a look again: no use
    }
    // Holding there is no progress: it does not restart the mission's time limit, and ends the
    // mission when that passes.
    if (look_hold && !backoff && config_.global_route &&
        t - last_progress_s_ > mission_limit_s_) {
      char text[160];
      std::snprintf(text, sizeof(text), "held at the edge of the known space, no way on for the mission's time limit of %.0f s",
                    mission_limit_s_);
      giveUpLocked(t, map, GoalStatus::kGivenUp, ReplanStatus::kSuccess, text, out);
      event.fallback = "give_up";
      event.message += (event.message.empty() ? "" : "; ") + out->event->message;
      out->event = event;
      conclude();
      return;
    }
    if (backoff) {
      // Holding there did not show the way on: a stall. The route rebuilt after the back-off weighs
      // against the place (another opening, another side), as the progress remedy's routes do: the
      // zone lies ahead along the way (where the progress is tracked), else around the hold. (Not
      // after a back-off to the anchor: the camera's blind zone held it there, not the way.)
      const bool tracked = config_.progress_timeout_s > 0.0 && progress_.active();
      if (config_.stall_zone_radius_m > 0.0 && !to_anchor)
        addStallZoneLocked({tracked ? progress_.ahead(config_.stall_zone_radius_m) : look_hold_position_,
                            config_.stall_zone_radius_m});
      route_stale_ = route_stale_ || !to_anchor;
      event.message += (event.message.empty() ? "" : "; ") + std::string("held at the edge of the known space ") +
                       std::to_string(config_.max_look_holds) + " times; " + backoff_report;
      startManoeuvreLocked(*backoff, true, &event, out, backoff_report);
      out->event = event;
      conclude();
      return;
    }
    replaceCurrentLocked(traj);
    collision_ahead_ = false;
    consecutive_failures_ = 0;
    failures_at_stall_ = 0;
    force_stall_ = false;
    rerouted_since_success_ = false;
    failures_at_reroute_ = 0;
    if (!look_hold) last_progress_s_ = t;
    if (traj.stops_before_unknown) {  // in the event log: where the vehicle waits on its map
      char text[96];
      std::snprintf(text, sizeof(text), "stops before unknown space, braking from +%.2f s", traj.brake_start_s - t_take);
      event.message = text;
    }
    event.published = true;
    out->trajectory = traj;
    setState(FsmState::kExecTraj, out, "");
  } else {
    ++consecutive_failures_;
    std::string give_up_why;
    // What the vehicle does now; a discarded plan keeps its label unless it ends the mission.
    const bool late = result.status == ReplanStatus::kSuccess;
    if (late) event.fallback = superseded ? "discarded_superseded" : "discarded_late";
    if (superseded) {
      // A braking trajectory took over while planning: the emergency stop owns the state now.
    } else if (generating) {
      const bool moving = current_ && !current_->manoeuvre() && t < current_->endTime();
      char text[160];
      if (!config_.global_route && consecutive_failures_ >= config_.max_plan_failures) {
        event.fallback = "give_up";
        give_up_why = "no trajectory after " + std::to_string(consecutive_failures_) + " tries";
      } else if (config_.global_route && t - last_progress_s_ > mission_limit_s_) {
        event.fallback = "give_up";
        std::snprintf(text, sizeof(text), "no trajectory for the mission's time limit of %.0f s (%d tries in a row failed)",
                      mission_limit_s_, consecutive_failures_);
        give_up_why = text;
      } else if (!late) {
        event.fallback = moving ? "keep_current" : "hover_retry";
      }
    } else if (!late) {
      event.fallback = "keep_current";
    }
    // At rest too close to an obstacle for the replanner to start: a slow escape first, then (as
    // after braking) a new reference from where it ends.
    const bool at_rest = !current_ || t >= current_->endTime();
    const bool giving_up = event.fallback == "give_up";
    std::string escape_report;
    std::optional<ExecTrajectory> escape;
    if (!superseded && result.status == ReplanStatus::kStartInCollision && at_rest && !giving_up)
      escape = escapeTrajectoryLocked(t, map, &escape_report);
    // Plans keep failing from rest (or it cannot start and has no way up the distance field): back
    // off along the flown path, and re-route from there.
    bool backoff = false;
    if (!escape && config_.global_route && !superseded && generating && at_rest && !giving_up &&
        backoffs_ < config_.max_backoffs &&
        (result.status == ReplanStatus::kStartInCollision || consecutive_failures_ >= config_.max_plan_failures)) {
      std::string report;
      escape = backoffTrajectoryLocked(t, map, &report);
      backoff = escape.has_value();
      escape_report += (escape_report.empty() ? "" : "; ") + report;
    }
    if (!escape && !escape_report.empty()) event.message += "; " + escape_report;
    // Still failing at rest with no back-off left: the stall remedy (a zone ahead, a re-route) now,
    // not when the progress clock runs out.
    if (!escape && config_.global_route && !superseded && generating && at_rest && !giving_up &&
        consecutive_failures_ - failures_at_stall_ >= config_.max_plan_failures) {
      force_stall_ = true;
      failures_at_stall_ = consecutive_failures_;
    }
    if (event.fallback == "hover_retry") rest_retry_after_s_ = finished + config_.rest_retry_interval_s;
    if (event.fallback == "keep_current") moving_retry_after_s_ = finished + config_.moving_retry_interval_s;
    // The way looks blocked (no guide path, no free local goal) or plans keep failing: re-route.
    const bool blocked = result.status == ReplanStatus::kNoPath || result.status == ReplanStatus::kGoalInCollision;
    if (config_.global_route && !superseded && !giving_up && !escape &&
        ((blocked && !rerouted_since_success_) ||
         consecutive_failures_ - failures_at_reroute_ >= config_.reroute_after_failures)) {
      route_stale_ = true;
      rerouted_since_success_ = true;
      failures_at_reroute_ = consecutive_failures_;
      if (!generating && !goals_pending_) {
        // A moving vehicle: a new reference from the takeover state, next tick (unless new goals
        // arrived while planning: they are flown instead).
        pending_goals_ = remainingGoalsLocked();
        goals_pending_ = !pending_goals_.empty();
        rerouting_ = goals_pending_;
      }
    }
    if (escape) {
      event.message += "; " + escape_report;
      startManoeuvreLocked(*escape, backoff, &event, out, escape_report);
    } else if (giving_up) {
      giveUpLocked(t, map, GoalStatus::kGivenUp, result.status, give_up_why, out);
      event.published = out->trajectory.has_value();  // the stop of a moving vehicle
      event.message += "; " + out->event->message;
    } else if (!superseded && !generating) {
      setState(FsmState::kExecTraj, out, "");
      collision_ahead_ = collision_ahead_ || trigger == FsmEvent::Trigger::kCollisionAhead;
    }
  }
  out->event = event;
  conclude();
}

FsmOutput ReplanFsm::tick(double t, const EsdfMap& map, const std::function<double()>& now) {
  std::unique_lock<std::mutex> lock(mutex_);
  FsmOutput out;
  if (!std::isfinite(t)) return out;
  map_geometry_ = map.geometry();
  observeClockLocked(t, &out);
  // Here only, not in checkSafety(): the replanner and the routers are used by tick() alone,
  // outside the lock, so only tick() may replace them.
  applyPendingConfigLocked(&out);
  if (have_odom_ && followServerLocked(t, map, &out)) return out;
  // Nothing is planned on stale inputs (checkSafety() brakes a moving vehicle); goals wait.
  std::string stale;
  if (state_ != FsmState::kInit && !inputsFreshLocked(t, &stale)) {
    // Nothing is planned: no stall (the progress clock pauses).
    if (progress_.active() && std::isfinite(progress_tick_s_) && t > progress_tick_s_) progress_.shift(t - progress_tick_s_);
    progress_tick_s_ = t;
    if (goals_pending_ && state_ == FsmState::kWaitTarget) {
      goals_pending_ = false;
      last_goal_status_ = GoalStatus::kInputsStale;
    }
    if (!inputs_reported_) {
      inputs_reported_ = true;
      if (!out.message.empty()) out.message += "; ";
      out.message += "inputs stale (" + stale + "): not planning";
    }
    return out;
  }
  // After a time jump the replan waits for a trajectory server setpoint sampled after it (when a
  // server reports): the FSM re-synchronises its timing to it first (followServerLocked), since the
  // two shifted by their own estimates of the time between calls.
  if (time_jumped_ && server_ && std::abs(t - server_->stamp_s) <= config_.server_timeout_s &&
      server_->stamp_s < time_jump_clock_s_)
    return out;
  const bool jumped = std::exchange(time_jumped_, false);
  if (inputs_reported_ && state_ != FsmState::kInit) {
    inputs_reported_ = false;
    if (!out.message.empty()) out.message += "; ";
    out.message += "inputs fresh again";
  }
  // The flown path, for back-offs: commanded positions (checked trajectories) 0.25 m apart; not
  // the manoeuvres (a back-off would walk back along the previous one).
  if (current_ && !current_->manoeuvre()) {
    const Eigen::Vector3d p = takeoverStateLocked(t).position;
    if (flown_.empty() || (p - flown_.back()).norm() >= 0.25) flown_.push_back(p);
    if (flown_.size() > 200) flown_.erase(flown_.begin(), flown_.begin() + 100);
  }
  if (handleStallLocked(t, map, &out)) return out;
  if (config_.global_route) {
    const FsmState before = state_;
    double searched_until = NAN;
    routeLocked(t, map, &lock, &out, now, &searched_until);
    if (out.event || state_ != before) return out;  // given up, or a braking took over meanwhile
    // A long search: plan at the next tick, from then (a plan from t would start late).
    if (searched_until - t > 0.5 * takeover_delay_s_) return out;
  }
  switch (state_) {
    case FsmState::kInit:
      if (have_odom_) setState(FsmState::kWaitTarget, &out, "odometry received");
      if (goals_pending_ && startGoalsLocked(t, map, &out)) plan(t, map, FsmEvent::Trigger::kNewGoal, &lock, &out, now);
      break;
    case FsmState::kWaitTarget:
      if (goals_pending_ && startGoalsLocked(t, map, &out)) plan(t, map, FsmEvent::Trigger::kNewGoal, &lock, &out, now);
      break;
    case FsmState::kGenNewTraj: {
      // A retry rebuilds the reference from where the vehicle will be, so it starts from its state.
      const bool fresh = goals_pending_;
      if (!fresh && consecutive_failures_ > 0 && t < rest_retry_after_s_) break;  // paced retries at rest
      if (!fresh) pending_goals_ = remainingGoalsLocked();
      goals_pending_ = true;
      if (startGoalsLocked(t, map, &out))
        plan(t, map, fresh ? FsmEvent::Trigger::kNewGoal : FsmEvent::Trigger::kRetry, &lock, &out, now);
      else if (!fresh)
        referenceNotRebuiltLocked(t, map, &out);
      break;
    }
    case FsmState::kExecTraj:
    case FsmState::kReplanTraj: {
      if (goals_pending_) {
        const FsmEvent::Trigger trigger = rerouting_ ? FsmEvent::Trigger::kReroute : FsmEvent::Trigger::kNewGoal;
        if (startGoalsLocked(t, map, &out)) plan(t, map, trigger, &lock, &out, now);
        break;
      }
      if (!current_) {
        setState(FsmState::kWaitTarget, &out, "no trajectory");
        break;
      }
      const bool ended = t >= current_->endTime();
      if (current_->ends_at_goal && ended) {
        if ((odom_position_ - goals_.back()).norm() <= config_.goal_tolerance_m) {
          out.goal_reached = true;
          goals_.clear();  // done: a later stop (e.g. an odometry jump at the hover) flies nowhere
          next_goal_ = 0;
          progress_.clear();
          setState(FsmState::kWaitTarget, &out, "goal reached");
        }
        break;
      }
      // A trajectory cut before unknown space is replanned before its stop begins, so a plan on the
      // grown map takes over while the vehicle still cruises; one that ends moving, early enough
      // before it runs out that a failed plan still leaves retries before checkSafety() must brake.
      const bool running_out = !current_->ends_at_goal &&
                               (ended || current_->endTime() - t <= stopTimeLocked(t, config_.brake_acc_mps2) + 0.5 * config_.replan_interval_s ||
                                (current_->stops_before_unknown &&
                                 current_->brake_start_s - t <= takeover_delay_s_ + 0.5 * config_.replan_interval_s));
      const bool periodic = !current_->ends_at_goal && t - current_->start_time_s >= config_.replan_interval_s;
      // The route ahead newly blocked in the map: re-routed at the next tick (a collision ahead or a
      // time jump is planned for first).
      if (!jumped && !collision_ahead_ && !current_->manoeuvre() && routeBlockedLocked(t, map, &out)) break;
      if (jumped) {
        plan(t, map, FsmEvent::Trigger::kTimeJump, &lock, &out, now);
      } else if (collision_ahead_) {
        plan(t, map, consecutive_failures_ > 0 ? FsmEvent::Trigger::kRetry : FsmEvent::Trigger::kCollisionAhead,
             &lock, &out, now);
      } else if (running_out || periodic) {
        // Retries of a failed periodic replan are paced while the trajectory flown stays safe for a
        // while (moving_retry_interval_s); when it runs out soon, at every tick.
        if (consecutive_failures_ > 0 && !running_out && t < moving_retry_after_s_) break;
        plan(t, map, consecutive_failures_ > 0 ? FsmEvent::Trigger::kRetry : FsmEvent::Trigger::kPeriodic, &lock,
             &out, now);
      }
      break;
    }
    case FsmState::kEmergencyStop: {
      const bool stopped = (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
      if (!stopped) break;
      // At rest after an odometry jump: the hover is the anchor (the camera cannot see beside and
      // behind it, and the map it flew through was in the old frame).
      if (std::exchange(anchor_at_rest_, false)) known_anchor_ = takeoverStateLocked(t).position;
      // Stopped: a new reference from here through the mission's goals (or the newer ones).
      const bool fresh = goals_pending_;
      if (!fresh) {
        pending_goals_ = remainingGoalsLocked();
        goals_pending_ = !pending_goals_.empty();
      }
      if (!goals_pending_) {
        setState(FsmState::kWaitTarget, &out, "stopped, no mission");
        break;
      }
      bool started = startGoalsLocked(t, map, &out);
      if (!started && fresh && last_goal_status_ != GoalStatus::kReferenceFailed && !remainingGoalsLocked().empty()) {
        // Newer goals refused (out of the map, in an obstacle: said in the message and the goal
        // status) are no reason to drop the mission: it goes on from here, as it would in flight.
        const GoalStatus refused = last_goal_status_;
        pending_goals_ = remainingGoalsLocked();
        goals_pending_ = true;
        started = startGoalsLocked(t, map, &out);
        if (started) last_goal_status_ = refused;
      }
      if (started) {
        // A new reference from rest is a new strategy: it gets its own max_plan_failures tries (the
        // failures of the replans that led here do not count against it).
        consecutive_failures_ = 0;
        failures_at_stall_ = 0;
        failures_at_reroute_ = 0;
        plan(t, map, FsmEvent::Trigger::kRetry, &lock, &out, now);
      } else {
        referenceNotRebuiltLocked(t, map, &out);
      }
      break;
    }
  }
  return out;
}

void ReplanFsm::emergencyStopLocked(double t, const EsdfMap& map, const std::string& reason, FsmOutput* out,
                                    const FlatState* from, ReplanStatus status) {
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kEmergency;
  event.state = state_;
  event.status = status;
  event.fallback = "stop";
  std::string report;
  ExecTrajectory brake = brakingTrajectory(t, map, &report, from);
  if (from) known_anchor_ = from->position;  // a hold where the vehicle is measured (or the server holds)
  brake.id = next_id_++;
  event.position = brake.spline.evaluate(0.0);
  event.message = reason + "; " + report;
  event.published = true;
  replaceCurrentLocked(brake);
  collision_ahead_ = false;
  route_stale_ = true;  // once stopped, the reference is rebuilt along a new route
  ++route_epoch_;
  setState(FsmState::kEmergencyStop, out, event.message);
  out->trajectory = brake;
  out->event = event;
}

FsmOutput ReplanFsm::checkSafety(double t, const EsdfMap& map) {
  std::lock_guard<std::mutex> lock(mutex_);
  FsmOutput out;
  if (!std::isfinite(t)) return out;
  observeClockLocked(t, &out);
  if (have_odom_ && followServerLocked(t, map, &out)) return out;
  if (!current_ || state_ == FsmState::kInit) return out;
  const bool active = t < current_->endTime();
  const double commanded_speed = active ? takeoverStateLocked(t).velocity.norm() : 0.0;
  // Stale inputs: a moving vehicle brakes to a hover (a braking trajectory already does).
  std::string stale;
  if (!inputsFreshLocked(t, &stale)) {
    if (!current_->braking && commanded_speed > config_.stopped_speed_mps)
      emergencyStopLocked(t, map, "inputs stale (" + stale + ")", &out, nullptr, ReplanStatus::kInvalidInput);
    return out;
  }
  // Odometry far from where the vehicle was commanded to be at its stamp (a VIO jump, or a vehicle
  // that went its own way while the odometry was away, e.g. a flight controller's failsafe hold):
  // hold from the measured state, moving on with the measured velocity to a stop; replanned from
  // there. (With the commanded velocity instead, a vehicle that came back from a failsafe hold
  // moving the other way left the stop at once and was re-anchored a second time, a setpoint jump.)
  const bool covered = odom_time_s_ >= current_->start_time_s || (previous_ && odom_time_s_ >= previous_->start_time_s);
  const double tracking_error = covered ? (odom_position_ - takeoverStateLocked(odom_time_s_).position).norm() : 0.0;
  if (tracking_error > config_.max_tracking_error_m) {
    FlatState from = takeoverStateLocked(t);
    from.velocity = odom_velocity_;
    from.position = odom_position_ + from.velocity * std::max(0.0, t - odom_time_s_);
    from.acceleration.setZero();
    from.jerk.setZero();
    char text[160];
    std::snprintf(text, sizeof(text), "odometry %.2f m from the commanded position (limit %.2f m): holding at the "
                  "measured position", tracking_error, config_.max_tracking_error_m);
    emergencyStopLocked(t, map, text, &out, &from, ReplanStatus::kInvalidInput);
    current_->reanchor = out.trajectory->reanchor = true;  // the step to the measured position is deliberate
    out.odometry_jumped = true;
    anchor_at_rest_ = true;
    flown_.clear();  // in the old frame
    stall_zones_.clear();
    route_stale_ = true;
    ++route_epoch_;
    return out;
  }
  // Braking and escapes were checked when made and are not replanned (they end at rest).
  if (current_->manoeuvre()) return out;
  if (t > current_->endTime() && state_ == FsmState::kWaitTarget) return out;
  // Time to stop from the current speed, plus the margin: a collision (or the end of a trajectory
  // that ends moving, past which nothing is planned) closer than that cannot wait for a replan.
  // Before a collision the vehicle may fly on, replanning at every tick, while a stop at the back-up
  // deceleration every committed plan keeps (commit_brake_acc_mps2) still ends before it: a
  // collision seen at the end of a plan cut before unknown space (a tree behind the edge of what
  // was seen, a voxel that turned occupied) is a replan's business, not an emergency stop's.
  const double collision_decel =
      config_.commit_to_known_space ? std::max(config_.brake_acc_mps2, config_.commit_brake_acc_mps2) : config_.brake_acc_mps2;
  const double hit = firstCollisionTime(*current_, t, map);
  const double end_speed =
      current_->spline.derivative().evaluate(std::max(0.0, current_->spline.duration() - 1e-6)).norm();
  const bool runs_out = !current_->ends_at_goal && end_speed > config_.stopped_speed_mps &&
                        current_->endTime() - t <= stopTimeLocked(t, config_.brake_acc_mps2);
  if (hit >= 0.0) collision_ahead_ = true;
  if (!runs_out && (hit < 0.0 || hit - t > stopTimeLocked(t, collision_decel))) return out;

  emergencyStopLocked(t, map,
                      hit >= 0.0 ? "collision in " + std::to_string(hit - t) + " s"
                                 : "the trajectory ends moving in " + std::to_string(current_->endTime() - t) +
                                       " s with no replan",
                      &out, nullptr, ReplanStatus::kOptimizationFailed);
  return out;
}

}  // namespace topo_planner
