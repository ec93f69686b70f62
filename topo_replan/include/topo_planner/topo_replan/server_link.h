#pragma once
// The replanning FSM's link to the trajectory server: whether the server follows the trajectory the
// FSM commands, judged from the server's published setpoint.
//
// The server should follow the current trajectory once its start (plus the message latency,
// grace_s) has passed, the one it replaced until then. It does not when it stops on its own
// (watchdog, a trajectory that ended moving), follows a trajectory the FSM does not command (another
// planner session's, or one it no longer commands), or holds while the commanded trajectory moves
// or away from the commanded position. While it follows, its setpoint keeps the FSM's timing in step
// (after a clock step each side saw at another moment): the link finds the time offset that puts
// the commanded trajectory on the server's setpoint. The FSM acts on the verdict (replan_fsm.h: no
// heartbeat while diverged, re-anchoring on the server's hold).
//
// Not thread-safe: the FSM calls it under its mutex.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "topo_planner/topo_replan/exec_trajectory.h"
#include "topo_planner/topo_replan/input_monitor.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace topo_planner {

/// The setpoint the trajectory server commands (its published position command).
struct ServerSetpoint {
  enum class Mode { kBeforeFirst, kTrajectory, kStopping, kHold };
  double stamp_s = 0.0;  ///< [s, caller's clock]
  double arrival_s = NAN;  ///< when it arrived [s, caller's clock]; NaN: at stamp_s
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Mode mode = Mode::kTrajectory;  ///< kStopping: a stop of its own (watchdog, or a trajectory that ended moving)
  bool own_session = false;       ///< the trajectory it follows (or followed) is of this planner session
  int64_t trajectory_id = -1;     ///< ... and has this id
};

class ServerLink {
 public:
  struct Config {
    double timeout_s = 0.25;             ///< the setpoint counts while this fresh (its stamp vs the clock) [s]
    double grace_s = 0.15;               ///< the server is on a trajectory that started this long ago [s]
    double position_tolerance_m = 0.1;   ///< a hold farther than this from the commanded position is not it [m]
    double stopped_speed_mps = 0.2;      ///< below this a setpoint or the commanded state is at rest [m/s]
    double max_resync_s = 1.0;           ///< the largest timing offset searched when re-synchronising [s]
  };

  /// What the latest setpoint says at a time.
  struct Verdict {
    enum class Kind {
      kFollows,   ///< it follows (or nothing fresh or new to judge)
      kDiverged,  ///< it does not follow and does not hold: wait for its hold, send no heartbeat
      kHolds,     ///< it holds on its own: the commanded state is that hold now
    };
    Kind kind = Kind::kFollows;
    std::string why;          ///< kDiverged, kHolds: how it does not follow
    bool first_report = false;  ///< kDiverged: the first of this episode (say it once)
    /// kFollows: the commanded trajectories' start times move back by this to match the server
    /// (0: in step) [s].
    double resync_s = 0.0;
    Eigen::Vector3d hold = Eigen::Vector3d::Zero();  ///< kHolds: where
  };

  explicit ServerLink(const Config& config) : config_(config) {}
  void setConfig(const Config& config) { config_ = config; }

  /// Non-finite values, setpoints stamped before the last one and setpoints stamped more than
  /// timeout_s ahead of their arrival (another time base, or a forged stamp: taken, it would hide
  /// every later one as out of order) are refused (false).
  bool set(const ServerSetpoint& setpoint);
  const std::optional<ServerSetpoint>& latest() const { return latest_; }
  /// The latest setpoint is within timeout_s of t.
  bool freshAt(double t) const;
  /// Before the FSM's first trajectory: where the server holds at t (at rest before its first
  /// trajectory, or holding: a restarted planner finds it where its stop ended), when it said so
  /// within timeout_s + 1 s of t.
  std::optional<Eigen::Vector3d> holdAt(double t) const;

  /// Judges the latest setpoint at clock t against the commanded trajectories (`current`, and the
  /// one it replaced, flown until current's start; null when none); `commanded_at` gives the
  /// commanded state at a time. A setpoint stamped before the last re-anchoring is not judged.
  Verdict judge(double t, const ExecTrajectory* current, const ExecTrajectory* previous,
                const std::function<FlatState(double)>& commanded_at);
  /// The FSM took the server's hold as its commanded state at t (after a kHolds verdict).
  void anchored(double t) { anchor_s_ = t; }
  /// A time jump: the stamps of the old clock move with it.
  void shift(const InputMonitor::TimeJump& jump);
  int resyncs() const { return resyncs_; }

 private:
  Config config_;
  std::optional<ServerSetpoint> latest_;
  bool reported_ = false;   // the divergence was said (once per episode)
  double anchor_s_ = -1e300;  // the last re-anchoring on the server's hold [s]
  int resyncs_ = 0;
};

}  // namespace topo_planner
