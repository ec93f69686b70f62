#include "topo_planner/topo_replan/input_monitor.h"

#include <algorithm>
#include <cstdio>

namespace topo_planner {

std::optional<InputMonitor::TimeJump> InputMonitor::observeClock(double now) {
  if (!std::isfinite(now)) return std::nullopt;
  if (!have_clock_) {
    have_clock_ = true;
    last_clock_s_ = now;
    return std::nullopt;
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
    return std::nullopt;
  }
  // The clock also went on by about one usual interval between the two calls.
  TimeJump jump;
  jump.step_s = step;
  jump.shift_s = step - typical_step_s_;
  jump.old_clock_s = last_clock_s_;
  jump.new_clock_s = now;
  // Inputs are not taken for stale (or fresh) by the step alone.
  jump.shiftStamp(&odom_time_s_);
  odom_arrival_s_ += jump.shift_s;  // arrivals are read from this clock
  jump.shiftStamp(&depth_stamp_s_);
  jump.shiftStamp(&depth_arrival_s_);
  last_clock_s_ = now;
  ++time_jumps_;
  return jump;
}

bool InputMonitor::acceptOdometry(double t, double arrival_s, std::string* why) {
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
  return true;
}

void InputMonitor::depthFused(double stamp_s, double arrival_s) {
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

bool InputMonitor::fresh(double now, std::string* why) const {
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

InputHealth InputMonitor::health(double now) const {
  InputHealth h;
  h.ok = fresh(now, &h.why);
  h.depth_age_s = have_depth_ ? now - depth_stamp_s_ : -1.0;
  h.odom_age_s = have_odom_ ? now - odom_time_s_ : -1.0;
  return h;
}

}  // namespace topo_planner
