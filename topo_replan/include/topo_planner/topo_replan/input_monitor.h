#pragma once
// Input liveness and the clock, for the replanning FSM (flight safety: every input has a freshness
// rule). Odometry is fresh when it arrived within odom_timeout_s and its stamp is within
// odom_max_age_s of the clock; depth when the last fused frame's stamp is within depth_timeout_s.
// Odometry stamped before the last one, or ahead of its arrival by more than odom_max_age_s, is
// refused; so is a depth frame stamped ahead of its arrival.
//
// The clock: a step forwards by more than time_jump_threshold_s, or backwards by more than
// kMaxClockDisorderS (or the threshold if smaller), between two observations is a time jump. The
// monitor shifts its own stamps by it and returns the jump, so the owner shifts everything else it
// stamped on the old clock (see TimeJump).
//
// Not thread-safe: the FSM calls it under its mutex.

#include <cmath>
#include <optional>
#include <string>

namespace topo_planner {

/// Freshness of the inputs at a time, for the heartbeat, the diagnostics and the log.
struct InputHealth {
  bool ok = false;            ///< every input is fresh
  std::string why;            ///< what is stale, when not ok
  double depth_age_s = -1.0;  ///< clock - stamp of the last fused depth frame [s]; -1 = never
  double odom_age_s = -1.0;   ///< clock - stamp of the last odometry [s]; -1 = never
};

class InputMonitor {
 public:
  /// The longest step back of the clock between two calls taken for their order (the callers read
  /// the clock before they take the lock), not for a time jump [s].
  static constexpr double kMaxClockDisorderS = 0.15;

  struct Config {
    double depth_timeout_s = 0.5;        ///< depth older than this is stale; 0: depth is not required [s]
    double odom_timeout_s = 0.25;        ///< odometry that has not arrived for this long is stale [s]
    double odom_max_age_s = 0.5;         ///< odometry stamped longer ago than this is stale [s]
    double time_jump_threshold_s = 1.0;  ///< a clock step forwards larger than this is a time jump [s]
  };

  /// A step of the clock taken for a time jump.
  struct TimeJump {
    double step_s = 0.0;       ///< the clock's step between the two calls [s]
    double shift_s = 0.0;      ///< what stored times move by: the step less a usual interval [s]
    double old_clock_s = 0.0;  ///< the clock before ...
    double new_clock_s = 0.0;  ///< ... and after
    /// Moves a stamp of an input by the shift when it is nearer the old clock than the new one (an
    /// input that arrived before this process's clock stepped is in the new time base already).
    void shiftStamp(double* stamp_s) const {
      if (std::abs(*stamp_s - old_clock_s) < std::abs(*stamp_s - new_clock_s)) *stamp_s += shift_s;
    }
  };

  explicit InputMonitor(const Config& config) : config_(config) {}
  void setConfig(const Config& config) { config_ = config; }

  /// Every entry point's clock bookkeeping (a non-finite clock is ignored): the time jump, when it
  /// is one, with this monitor's stamps already shifted.
  std::optional<TimeJump> observeClock(double now);
  /// Whether the clock has been observed, and its latest reading.
  bool haveClock() const { return have_clock_; }
  double clock() const { return last_clock_s_; }
  int timeJumps() const { return time_jumps_; }

  /// Odometry stamped t, arrived at arrival_s (finite; observe the clock at arrival_s first): taken
  /// (true), or refused with the reason (stamped ahead of its arrival, or before the last one).
  bool acceptOdometry(double t, double arrival_s, std::string* why);
  bool haveOdometry() const { return have_odom_; }
  double odometryStamp() const { return odom_time_s_; }

  /// The mapping fused a frame stamped stamp_s at arrival_s (both finite). The same stamp again is a
  /// no-op (the caller may poll the last frame); so is one older than the newest, or stamped more
  /// than odom_max_age_s ahead of its arrival.
  void depthFused(double stamp_s, double arrival_s);

  /// Every input fresh at `now`; otherwise false with what is stale.
  bool fresh(double now, std::string* why) const;
  InputHealth health(double now) const;

 private:
  Config config_;
  bool have_odom_ = false;
  double odom_time_s_ = 0.0;
  double odom_arrival_s_ = 0.0;
  bool have_raw_depth_ = false;  // the last stamp passed to depthFused, as passed
  double raw_depth_stamp_s_ = 0.0;
  bool have_depth_ = false;
  double depth_stamp_s_ = 0.0;
  double depth_arrival_s_ = 0.0;
  bool have_clock_ = false;
  double last_clock_s_ = 0.0;
  double typical_step_s_ = 0.0;  // running mean of the clock's steps between calls [s]
  int time_jumps_ = 0;
};

}  // namespace topo_planner
