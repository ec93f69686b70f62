#include "topo_planner/topo_replan/setpoint_generator.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {
namespace {

// A trajectory ending slower than this ends at rest (held at once); faster, it ends moving (end stop).
constexpr double kRestSpeedMps = 1e-3;
// The stop's path: arc-length samples at most this far apart in trajectory time [s].
constexpr double kPathStepS = 0.005;
// The path ends where its speed falls below this (the tangent is no longer defined) [m/s].
constexpr double kPathMinSpeedMps = 1e-3;

bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }

}  // namespace

const char* toString(Setpoint::Mode mode) {
  switch (mode) {
    case Setpoint::Mode::kHoldBeforeFirst:
      return "HOLD_BEFORE_FIRST";
    case Setpoint::Mode::kTrajectory:
      return "TRAJECTORY";
    case Setpoint::Mode::kEndStop:
      return "END_STOP";
    case Setpoint::Mode::kWatchdogStop:
      return "WATCHDOG_STOP";
    case Setpoint::Mode::kHold:
      return "HOLD";
  }
  return "UNKNOWN";
}

bool SetpointGenerator::Config::validate(std::string* why) const {
  auto bad = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (!finitePositive(max_yaw_rate_radps)) return bad("max_yaw_rate_radps must be positive");
  if (!finitePositive(lookahead_s)) return bad("lookahead_s must be positive");
  if (!(min_displacement_m >= 0.0) || !std::isfinite(min_displacement_m)) return bad("min_displacement_m must be >= 0");
  if (max_queued < 1) return bad("max_queued must be >= 1");
  if (!finitePositive(nominal_period_s)) return bad("nominal_period_s must be positive");
  if (!finitePositive(heartbeat_timeout_s) || heartbeat_timeout_s <= nominal_period_s)
    return bad("heartbeat_timeout_s must be longer than the sampling period");
  if (!(moving_speed_mps >= 0.0) || !std::isfinite(moving_speed_mps)) return bad("moving_speed_mps must be >= 0");
  if (!finitePositive(stop_acc_mps2)) return bad("stop_acc_mps2 must be positive");
  if (!finitePositive(stop_jerk_mps3)) return bad("stop_jerk_mps3 must be positive");
  if (!std::isfinite(max_time_step_s) || max_time_step_s <= 2.0 * nominal_period_s)
    return bad("max_time_step_s must be longer than two sampling periods");
  if (!(max_takeover_gap_m > 0.0) || !std::isfinite(max_takeover_gap_m)) return bad("max_takeover_gap_m must be positive");
  if (!(max_takeover_velocity_gap_mps > 0.0) || !std::isfinite(max_takeover_velocity_gap_mps))
    return bad("max_takeover_velocity_gap_mps must be positive");
  return true;
}

bool SetpointGenerator::add(uint64_t session, int64_t id, double start_time_s, const UniformBspline& spline,
                            const std::optional<Eigen::Vector3d>& heading_target, bool reanchor) {
  const bool valid = std::isfinite(start_time_s) && spline.isValid() && spline.degree() >= 3 &&
                     (!heading_target || heading_target->allFinite());
  const bool new_session = have_last_ && session != last_session_;
  if (!valid || (have_last_ && !new_session && id <= last_id_)) {
    ++stats_.refused;
    return false;
  }
  Entry e;
  e.session = session;
  e.id = id;
  e.start = start_time_s;
  e.pos = spline;
  e.vel = spline.derivative();
  e.acc = e.vel.derivative();
  e.jerk = e.acc.derivative();
  e.heading_target = heading_target;
  e.reanchor = reanchor;
  if (new_session) {
    // The old planner's queued trajectories will not be followed up by it: drop them.
    ++stats_.session_changes;
    queue_.clear();
  }
  while (!queue_.empty() && queue_.back().start >= start_time_s) queue_.pop_back();
  if (int(queue_.size()) >= config_.max_queued) queue_.pop_front();
  queue_.push_back(std::move(e));
  have_last_ = true;
  last_session_ = session;
  last_id_ = id;
  input_pending_ = true;
  ++stats_.accepted;
  return true;
}

void SetpointGenerator::noteHeartbeat(double t) {
  if (!std::isfinite(t)) return;
  if (!sampled_ || std::abs(t - last_t_) <= config_.max_time_step_s) {
    last_input_t_ = std::max(last_input_t_, t);
  } else {
    // Another time base than the last sample's: a time jump that sample() has not seen yet. The
    // heartbeat is fresh now, i.e. at the last sample (shifted with the other times at the jump).
    last_input_t_ = std::max(last_input_t_, last_t_);
  }
}

void SetpointGenerator::setYaw(double yaw) {
  if (std::isfinite(yaw)) yaw_ = std::remainder(yaw, 2.0 * M_PI);
}

void SetpointGenerator::setVehiclePose(const Eigen::Vector3d& position, double yaw) {
  if (active_ || !position.allFinite()) return;
  vehicle_position_ = position;
  have_pose_ = true;
  setYaw(yaw);
}

FlatState SetpointGenerator::trajectoryState(const Entry& e, double tau) const {
  tau = std::clamp(tau, 0.0, e.pos.duration());
  FlatState s;
  s.position = e.pos.evaluate(tau);
  s.velocity = e.vel.evaluate(tau);
  s.acceleration = e.acc.evaluate(tau);
  s.jerk = e.jerk.evaluate(tau);
  return s;
}

void SetpointGenerator::shiftTimes(double shift) {
  current_.start += shift;
  for (Entry& e : queue_) e.start += shift;
  stop_.t0 += shift;
  hold_since_ += shift;
  last_input_t_ += shift;
}

void SetpointGenerator::startStop(double t0, const Entry& path, double tau0, const FlatState& state,
                                  Setpoint::Mode mode) {
  mode_ = mode;
  Stop s;
  s.t0 = t0;
  s.tau0 = tau0;
  s.start_pos = state.position;
  const double v0 = state.velocity.norm();
  Eigen::Vector3d dir = Eigen::Vector3d::UnitX();
  if (v0 > 1e-9)
    dir = state.velocity / v0;
  else if (state.acceleration.norm() > 1e-9)
    dir = state.acceleration.normalized();
  const double a0 = state.acceleration.dot(dir);
  stats_.last_stop_speed_mps = v0;

  // The jerk-limited speed profile (v0 >= 0, tangential acceleration a0, deceleration A, jerk J):
  // ramp a0 -> -ap, hold -ap, ramp -ap -> 0; the three speed changes add up to -v0.
  const double J = config_.stop_jerk_mps3;
  const double A = std::max(config_.stop_acc_mps2, -a0);  // never soften a harder braking
  s.v0 = v0;
  s.a0 = a0;
  const double t2 = (v0 + a0 * a0 / (2.0 * J) - A * A / J) / A;
  if (t2 >= 0.0) {  // trapezoid: reaches the full deceleration
    s.ap = A, s.j1 = -J, s.t1 = (a0 + A) / J, s.t2 = t2, s.j3 = J, s.t3 = A / J;
  } else {
    const double ap = std::sqrt(J * v0 + 0.5 * a0 * a0);
    if (ap >= -a0) {  // triangle: ramps down to -ap and straight back to 0
      s.ap = ap, s.j1 = -J, s.t1 = (a0 + ap) / J, s.t2 = 0.0, s.j3 = J, s.t3 = ap / J;
    } else {
      // Already decelerating too hard for the remaining speed: ramping back to 0 at J would
      // reverse; ramp back faster, so the speed reaches 0 with the acceleration.
      s.ap = -a0, s.j1 = 0.0, s.t1 = 0.0, s.t2 = 0.0;
      s.j3 = v0 > 1e-12 ? a0 * a0 / (2.0 * v0) : 0.0;
      s.t3 = v0 > 1e-12 ? 2.0 * v0 / s.ap : 0.0;
    }
  }
  s.length_m = evaluateProfile(s, s.duration()).s;

  const double duration = path.pos.isValid() ? path.pos.duration() : 0.0;
  if (mode == Setpoint::Mode::kWatchdogStop && path.pos.isValid() &&
      path.vel.evaluate(duration).norm() <= kRestSpeedMps && duration - tau0 <= s.duration()) {
    // The trajectory comes to rest no later than the stop would: it is a stop already, checked by
    // the planner (perhaps braking harder than stop_acc_mps2); follow it.
    s.follow_trajectory = true;
    s.j1 = s.j3 = s.ap = s.t2 = s.t3 = 0.0;
    s.t1 = std::max(0.0, duration - tau0);
    s.path = path;
    stop_ = std::move(s);
    return;
  }

  s.end_dir = dir;
  s.end_pos = state.position;
  if (path.pos.isValid() && tau0 < duration) {
    // Arc length along the path from tau0 (Simpson's rule on the speed), up to the stopping
    // distance, the trajectory's end, or where the path's speed vanishes.
    s.path = path;
    s.s_m.push_back(0.0);
    s.tau_s.push_back(tau0);
    const int steps = std::max(1, int(std::ceil((duration - tau0) / std::min(kPathStepS, path.pos.knotSpan() / 4.0))));
    const double h = (duration - tau0) / steps;
    double arc = 0.0;
    Eigen::Vector3d p_prev = state.position;
    for (int k = 1; k <= steps && arc < s.length_m; ++k) {
      const double ta = tau0 + (k - 1) * h, tb = tau0 + k * h;
      const double vb = path.vel.evaluate(tb).norm();
      arc += h / 6.0 * (path.vel.evaluate(ta).norm() + 4.0 * path.vel.evaluate(0.5 * (ta + tb)).norm() + vb);
      const Eigen::Vector3d pb = path.pos.evaluate(tb);
      if ((pb - p_prev).norm() > 1e-9) s.end_dir = (pb - p_prev).normalized();
      p_prev = pb;
      s.s_m.push_back(arc);
      s.tau_s.push_back(tb);
      if (vb < kPathMinSpeedMps) break;
    }
    s.end_pos = path.pos.evaluate(s.tau_s.back());
    const Eigen::Vector3d v_end = path.vel.evaluate(s.tau_s.back());
    if (v_end.norm() >= kPathMinSpeedMps) s.end_dir = v_end.normalized();
  }
  stop_ = std::move(s);
}

SetpointGenerator::Profile1d SetpointGenerator::evaluateProfile(const Stop& s, double t) {
  Profile1d p;
  t = std::clamp(t, 0.0, s.duration());
  // Phase 1.
  const double t1 = std::min(t, s.t1);
  p.s = s.v0 * t1 + s.a0 * t1 * t1 / 2.0 + s.j1 * t1 * t1 * t1 / 6.0;
  p.v = s.v0 + s.a0 * t1 + s.j1 * t1 * t1 / 2.0;
  p.a = s.a0 + s.j1 * t1;
  p.j = s.j1;
  if (t > s.t1) {  // phase 2
    p.a = -s.ap;
    p.j = 0.0;
    const double t2 = std::min(t - s.t1, s.t2);
    p.s += p.v * t2 + p.a * t2 * t2 / 2.0;
    p.v += p.a * t2;
    if (t > s.t1 + s.t2) {  // phase 3
      const double t3 = std::min(t - s.t1 - s.t2, s.t3);
      p.s += p.v * t3 + p.a * t3 * t3 / 2.0 + s.j3 * t3 * t3 * t3 / 6.0;
      p.v += p.a * t3 + s.j3 * t3 * t3 / 2.0;
      p.a += s.j3 * t3;
      p.j = s.j3;
    }
  }
  if (t >= s.duration()) p.v = p.a = p.j = 0.0;
  p.v = std::max(0.0, p.v);
  return p;
}

FlatState SetpointGenerator::stopState(double t) const { return stopStateOf(stop_, t); }

FlatState SetpointGenerator::stopStateOf(const Stop& s, double t) const {
  if (s.follow_trajectory) return trajectoryState(s.path, s.tau0 + std::clamp(t - s.t0, 0.0, s.t1));
  const Profile1d prof = evaluateProfile(s, t - s.t0);
  FlatState out;
  Eigen::Vector3d tangent = s.end_dir, normal_acc = Eigen::Vector3d::Zero();  // normal acceleration / speed^2
  if (!s.s_m.empty() && prof.s <= s.s_m.back()) {
    // On the path: the trajectory time at this arc length (linear between the samples).
    const size_t k = std::min(size_t(std::upper_bound(s.s_m.begin(), s.s_m.end(), prof.s) - s.s_m.begin()),
                              s.s_m.size() - 1);
    const size_t j = k == 0 ? 0 : k - 1;
    const double ds = s.s_m[k] - s.s_m[j];
    const double w = ds > 1e-12 ? (prof.s - s.s_m[j]) / ds : 1.0;
    const double tau = s.tau_s[j] + w * (s.tau_s[k] - s.tau_s[j]);
    out.position = s.path.pos.evaluate(tau);
    const Eigen::Vector3d pv = s.path.vel.evaluate(tau), pa = s.path.acc.evaluate(tau);
    const double speed = pv.norm();
    if (speed >= kPathMinSpeedMps) {
      tangent = pv / speed;
      normal_acc = (pa - pa.dot(tangent) * tangent) / (speed * speed);
    }
  } else {
    // Past the path's end (or no path): straight on along its last direction.
    const double s_end = s.s_m.empty() ? 0.0 : s.s_m.back();
    out.position = s.end_pos + (prof.s - s_end) * s.end_dir;
  }
  out.velocity = prof.v * tangent;
  out.acceleration = prof.a * tangent + prof.v * prof.v * normal_acc;
  out.jerk = prof.j * tangent;  // the tangential part (feed-forward only)
  return out;
}

double SetpointGenerator::updateYaw(double dt, const Eigen::Vector3d& position, const Eigen::Vector3d& ahead,
                                    double* rate) {
  double target = yaw_;
  if (ahead.head<2>().norm() >= config_.min_displacement_m) {
    target = std::atan2(ahead.y(), ahead.x());
  } else if (active_ && current_.heading_target) {
    const Eigen::Vector3d to_target = *current_.heading_target - position;
    if (to_target.head<2>().norm() > config_.min_displacement_m) target = std::atan2(to_target.y(), to_target.x());
  }
  const double error = std::remainder(target - yaw_, 2.0 * M_PI);
  const double step = std::clamp(error, -config_.max_yaw_rate_radps * dt, config_.max_yaw_rate_radps * dt);
  yaw_ = std::remainder(yaw_ + step, 2.0 * M_PI);
  *rate = dt > 0.0 ? step / dt : 0.0;
  return yaw_;
}

bool SetpointGenerator::commandedAt(double t, FlatState* state) const {
  if (!active_) {
    // Before the first trajectory only a streamed hold is a commanded state.
    if (!config_.hold_before_first_trajectory || !have_pose_ || !sampled_) return false;
    *state = FlatState::atRest(vehicle_position_);
    return true;
  }
  if (t < current_.start && before_.valid) {
    // Before the current trajectory took over: what it replaced.
    if (before_.mode == Setpoint::Mode::kHold) {
      *state = FlatState::atRest(before_.hold_position);
    } else if (before_.mode == Setpoint::Mode::kTrajectory) {
      const double d = before_.trajectory.pos.duration();
      *state = trajectoryState(before_.trajectory, std::clamp(t - before_.trajectory.start, 0.0, d));
    } else {
      *state = stopStateOf(before_.stop, std::clamp(t, before_.stop.t0, before_.stop.t0 + before_.stop.duration()));
    }
    return true;
  }
  if (mode_ == Setpoint::Mode::kHold && t >= hold_since_) {
    *state = FlatState::atRest(hold_position_);
    return true;
  }
  const bool stop = mode_ == Setpoint::Mode::kEndStop || mode_ == Setpoint::Mode::kWatchdogStop ||
                    (mode_ == Setpoint::Mode::kHold && hold_after_stop_);
  if (stop && t >= stop_.t0) {
    *state = stopState(std::min(t, stop_.t0 + stop_.duration()));
    return true;
  }
  const double duration = current_.pos.duration();
  *state = trajectoryState(current_, std::clamp(t - current_.start, 0.0, duration));
  if (t - current_.start >= duration && state->velocity.norm() <= kRestSpeedMps) *state = FlatState::atRest(state->position);
  return true;
}

bool SetpointGenerator::sample(double t, Setpoint* out) {
  if (!std::isfinite(t)) return false;
  // Time jumps: shift every stored time so that this sample is one nominal period after the last.
  double dt = 0.0;
  if (sampled_) {
    const double step = t - last_t_;
    if (step < 0.0 || step > config_.max_time_step_s) {
      const double shift = step - config_.nominal_period_s;
      shiftTimes(shift);
      ++(step < 0.0 ? stats_.backward_time_jumps : stats_.forward_time_jumps);
      stats_.last_time_jump_s = shift;
      dt = config_.nominal_period_s;
    } else {
      dt = step;
    }
  }
  const double previous_t = t - dt;  // the last sample, in this time base (t itself at the first)
  sampled_ = true;
  last_t_ = t;
  if (input_pending_) {
    last_input_t_ = std::max(last_input_t_, t);
    input_pending_ = false;
  }

  // The newest queued trajectory whose start has come takes over (also from a stop or a hold), if it
  // starts from the state commanded at its start time (what the planner plans from: its takeover
  // state; judged at the start time, so a late arrival, e.g. an emergency brake, is not refused).
  bool refused_now = false;
  while (!queue_.empty() && queue_.front().start <= t) {
    Entry next = std::move(queue_.front());
    queue_.pop_front();
    FlatState before, then;
    if (!next.reanchor && commandedAt(next.start, &before)) {
      const FlatState s = trajectoryState(next, 0.0);
      double gap = (s.position - before.position).norm();
      // Arriving after setpoints past its start went out (late, not a stall of the sampling), it
      // has moved away from them meanwhile (from a hold, by half its acceleration times the delay
      // squared): that step, at the last sample, is what the vehicle would see.
      if (previous_t > next.start && commandedAt(previous_t, &then)) {
        const double late = std::min(previous_t - next.start, next.pos.duration());
        gap = std::max(gap, (trajectoryState(next, late).position - then.position).norm());
      }
      const double velocity_gap = (s.velocity - before.velocity).norm();
      if (!(gap <= config_.max_takeover_gap_m) || !(velocity_gap <= config_.max_takeover_velocity_gap_mps)) {
        ++stats_.discontinuous_refused;
        stats_.last_takeover_gap_m = gap;
        stats_.last_takeover_velocity_gap_mps = velocity_gap;
        stats_.last_refused_id = next.id;
        refused_now = true;
        continue;
      }
    }
    if (active_) {
      before_.valid = true;
      before_.mode = mode_;
      if (mode_ == Setpoint::Mode::kTrajectory) before_.trajectory = current_;
      if (mode_ == Setpoint::Mode::kEndStop || mode_ == Setpoint::Mode::kWatchdogStop ||
          (mode_ == Setpoint::Mode::kHold && hold_after_stop_ && next.start < hold_since_)) {
        before_.mode = Setpoint::Mode::kWatchdogStop;  // (any stop)
        before_.stop = stop_;
      }
      before_.hold_position = hold_position_;
    }
    current_ = std::move(next);
    active_ = true;
    mode_ = Setpoint::Mode::kTrajectory;
  }
  if (refused_now && active_ && mode_ == Setpoint::Mode::kTrajectory) {
    // The planner replaced this trajectory (it may be the one it stopped for): stop along its path now
    // instead of flying it on unchecked; the planner plans from the hold.
    const double tau = std::clamp(t - current_.start, 0.0, current_.pos.duration());
    const FlatState state = trajectoryState(current_, tau);
    if (state.velocity.norm() > config_.moving_speed_mps) {
      ++stats_.refusal_stops;
      queue_.clear();
      startStop(t, current_, tau, state, Setpoint::Mode::kWatchdogStop);
    }
  }
  Setpoint sp;
  if (!active_) {
    if (!config_.hold_before_first_trajectory || !have_pose_) return false;
    sp.mode = Setpoint::Mode::kHoldBeforeFirst;
    sp.state = FlatState::atRest(vehicle_position_);
    sp.yaw = yaw_;
    sp.yaw_rate = 0.0;
    sp.trajectory_id = -1;
    *out = sp;
    return true;
  }

  const double duration = current_.pos.duration();
  const double tau = t - current_.start;
  if (mode_ == Setpoint::Mode::kTrajectory) {
    if (tau > duration) {
      const FlatState end = trajectoryState(current_, duration);
      if (end.velocity.norm() > kRestSpeedMps) {
        // Ends moving: stop straight on from its end (no path beyond it), from its end time.
        ++stats_.end_stops;
        startStop(current_.start + duration, Entry{}, 0.0, end, Setpoint::Mode::kEndStop);
      } else {
        mode_ = Setpoint::Mode::kHold;
        hold_position_ = end.position;
        hold_since_ = current_.start + duration;
        hold_after_stop_ = false;
      }
    } else {
      const FlatState state = trajectoryState(current_, tau);
      const double age = t - last_input_t_;
      if (age > config_.heartbeat_timeout_s && state.velocity.norm() > config_.moving_speed_mps) {
        ++stats_.watchdog_stops;
        stats_.last_input_age_s = age;
        stats_.dropped_on_watchdog += int64_t(queue_.size());
        queue_.clear();
        startStop(t, current_, tau, state, Setpoint::Mode::kWatchdogStop);
      } else {
        sp.state = state;
      }
    }
  }
  const bool stopping = mode_ == Setpoint::Mode::kEndStop || mode_ == Setpoint::Mode::kWatchdogStop;
  if (stopping && t - stop_.t0 >= stop_.duration()) {
    mode_ = Setpoint::Mode::kHold;
    hold_position_ = stopState(stop_.t0 + stop_.duration()).position;
    hold_since_ = stop_.t0 + stop_.duration();
    hold_after_stop_ = true;
  }
  Eigen::Vector3d ahead = Eigen::Vector3d::Zero();
  if (mode_ == Setpoint::Mode::kTrajectory) {
    ahead = current_.pos.evaluate(std::min(duration, std::max(0.0, tau) + config_.lookahead_s)) - sp.state.position;
  } else if (mode_ == Setpoint::Mode::kHold) {
    sp.state = FlatState::atRest(hold_position_);
  } else {
    sp.state = stopState(t);
    ahead = stopState(std::min(t + config_.lookahead_s, stop_.t0 + stop_.duration())).position - sp.state.position;
  }
  sp.mode = mode_;
  sp.trajectory_id = current_.id;
  sp.planner_session = current_.session;
  sp.yaw = updateYaw(dt, sp.state.position, ahead, &sp.yaw_rate);
  *out = sp;
  return true;
}

}  // namespace topo_planner
