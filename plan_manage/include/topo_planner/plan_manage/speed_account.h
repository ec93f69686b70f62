#pragma once
// Where a flight's speed goes: every instant the vehicle flies slower than fast_fraction x max_vel
// is attributed to one cause, from what was commanded then and why.
//
// Causes, in the order they are tested (the first that applies wins):
//   held        the trajectory server holds (before the first trajectory, after a stop), the command
//               is at rest, or a slow manoeuvre (escape, back-off) is flown: held or stalled
//   braking     an emergency braking trajectory, or the server's own stop (watchdog, end stop)
//   commitment  past the brake point of a plan cut before unknown space (the known-space commitment:
//               its committed stop, and the rest at its end), or within takeover_window_s of a plan
//               that took over from such a stop (it starts from the speed the stop left)
//   takeover    within takeover_window_s of a plan's take-over, the plan it replaced would command
//               more than takeover_loss_mps faster now (and was not braking yet): the new plan slowed
//   tracking    the command is fast, the vehicle is not (the controller lags)
//   limits      the command accelerates, brakes (for a turn or the goal) or turns with more than
//               limit_fraction x max_acc: flying at the dynamic limits
//   timing      none of the above: the plan itself is slow (the reference's or the optimiser's time
//               allocation)
// The account integrates time between the vehicle's (true) speed samples, each interval classified
// by the state at its start. Trajectories are known by (session, id); a setpoint whose trajectory is
// unknown is classified from the command alone. No ROS, no threads: one caller.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <deque>
#include <string>

#include "topo_planner/bspline_opt/uniform_bspline.h"

namespace topo_planner {

enum class SlowCause { kHeld, kBraking, kCommitment, kTakeover, kTracking, kLimits, kTiming };
constexpr int kNumSlowCauses = 7;
const char* toString(SlowCause cause);

class SpeedAccount {
 public:
  struct Config {
    double max_vel_mps = 3.0;          ///< the flight's speed limit [m/s]
    double max_acc_mps2 = 2.5;         ///< its acceleration limit [m/s^2]
    double fast_fraction = 0.8;        ///< an instant is fast at or above this x max_vel
    double limit_fraction = 0.6;       ///< commanded tangential or normal acceleration above this x max_acc: at the limits
    double held_speed_mps = 0.1;       ///< a command slower than this ...
    double held_acc_mps2 = 0.5;        ///< ... with less acceleration than this is at rest [m/s^2]
    double takeover_window_s = 1.0;    ///< a plan's first this long is compared with the plan it replaced [s]
    double takeover_loss_mps = 0.1;    ///< slower than that one by more than this: the take-over's [m/s]
    double max_gap_s = 0.5;            ///< longer gaps between speed samples are not counted [s]
    size_t max_trajectories = 64;      ///< trajectories kept (the newest)

    bool validate(std::string* why) const;
  };
  enum class TrajectoryKind { kPlan, kBraking, kManoeuvre };
  struct Trajectory {
    uint64_t session = 0;
    int64_t id = -1;
    double start_s = 0.0;        ///< take-over time [s]
    /// The plan is flown as planned until here, then stops before unknown space (the known-space
    /// commitment); at or past its end when it was not cut [s].
    double brake_start_s = 0.0;
    TrajectoryKind kind = TrajectoryKind::kPlan;
    UniformBspline spline;
  };
  enum class Mode { kHold, kTrajectory, kStopping };
  struct Setpoint {
    Mode mode = Mode::kHold;
    uint64_t session = 0;
    int64_t trajectory_id = -1;
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();      ///< [m/s]
    Eigen::Vector3d acceleration = Eigen::Vector3d::Zero();  ///< [m/s^2]
  };
  struct Totals {
    double total_s = 0.0;  ///< time counted [s]
    double fast_s = 0.0;   ///< at or above fast_fraction x max_vel [s]
    std::array<double, kNumSlowCauses> slow_s{};  ///< below it, per cause [s]
    double slow() const;
    /// A cause's share of the slow time (0 without any).
    double share(SlowCause cause) const;
  };

  SpeedAccount();
  explicit SpeedAccount(const Config& config);
  const Config& config() const { return config_; }

  /// A published trajectory (replaces one with the same session and id).
  void addTrajectory(const Trajectory& trajectory);
  /// The trajectory server's latest setpoint (in force until the next).
  void setSetpoint(const Setpoint& setpoint);
  /// The vehicle's true speed at t: the interval since the previous sample is attributed.
  void addSpeed(double t_s, double speed_mps);
  /// The cause of an instant at t with the vehicle at speed_mps under the current setpoint (nullopt
  /// semantics through `fast`: true when the instant is not slow at all).
  SlowCause classify(double t_s, double speed_mps, bool* fast) const;
  const Totals& totals() const { return totals_; }

 private:
  const Trajectory* find(uint64_t session, int64_t id) const;
  /// The plan flown before `t` (the one with the latest start before traj's, same session).
  const Trajectory* replaced(const Trajectory& traj) const;

  Config config_;
  std::deque<Trajectory> trajectories_;
  bool have_setpoint_ = false;
  Setpoint setpoint_;
  bool have_sample_ = false;
  double last_t_s_ = 0.0;
  double last_speed_mps_ = 0.0;
  Totals totals_;
};

}  // namespace topo_planner
