#pragma once
// FaultSchedule: the faults the simulator injects into the vehicle's inputs, at set simulated times,
// for the fault-injection tests and benchmark (failure behaviour, issue 11). What a real drone's
// inputs do when something fails (PX4's failsafe table lists the same inputs):
//   - depth blackout   [start, end): the depth camera publishes no image (a USB camera that drops
//                      out, a driver that hangs);
//   - odometry blackout [start, end): no odometry and no tf (a VIO that stalls or loses tracking);
//                      the physics goes on, and the controller, fed by the same odometry, goes
//                      silent too, so the simulator's command-timeout failsafe takes over;
//   - odometry jump    from t on, a constant offset is added to the published position and tf
//                      (a VIO relocalisation or loop closure); jumps add up;
//   - clock step       from t on, /clock and every stamp jump by step_s (+/-) while the physics
//                      goes on (a companion computer without RTC syncing NTP, a looping bag);
//                      steps add up.
//
// Times are simulated seconds since the simulation started: the physics clock, which starts at 0
// when the simulator's clock starts (clock_start_s) and is not moved by clock steps. Before any
// clock step, ROS time = clock_start_s + t.
//
// A plain value: no ROS, no clock of its own. The simulator asks it what holds at its physics time.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace topo_planner {

struct FaultSchedule {
  struct Window {
    double start_s = 0.0;  ///< first simulated time of the fault [s]
    double end_s = 0.0;    ///< the fault has cleared from this time on [s]
  };
  struct OdomJump {
    double t_s = 0.0;                                    ///< from this simulated time on [s]
    Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();  ///< added to the published position [m]
  };
  struct ClockStep {
    double t_s = 0.0;     ///< at this simulated time [s]
    double step_s = 0.0;  ///< /clock and every stamp jump by this (+ forward, - backward) [s]
  };
  enum class Kind { kDepthBlackout, kOdomBlackout, kOdomJump, kClockStep };
  /// "depth_blackout", "odom_blackout", "odom_jump", "clock_step".
  static const char* toString(Kind kind);

  /// A change of the injected faults at one time.
  struct Event {
    enum class Phase { kStart, kEnd, kStep };  ///< a window starts or ends; a jump or a step happens
    double t_s = 0.0;
    Kind kind = Kind::kDepthBlackout;
    Phase phase = Phase::kStart;
    Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();  ///< odometry jump: this jump's offset [m]
    double step_s = 0.0;                                 ///< clock step: this step [s]
    double end_s = 0.0;                                  ///< window start: when it ends [s]
  };
  static const char* toString(Event::Phase phase);  ///< "start", "end", "step"

  std::vector<Window> depth_blackouts;
  std::vector<Window> odom_blackouts;
  std::vector<OdomJump> odom_jumps;
  std::vector<ClockStep> clock_steps;

  bool empty() const;
  /// Finite, non-negative times, windows with start < end, steps that keep the ROS time positive
  /// (clock_start_s + t + the steps so far > 0 at every step). The reason in *why otherwise.
  bool validate(double clock_start_s, std::string* why) const;

  bool depthBlackout(double t_s) const;        ///< inside a depth blackout window at t_s
  bool odomBlackout(double t_s) const;         ///< inside an odometry blackout window at t_s
  Eigen::Vector3d odomOffset(double t_s) const;  ///< sum of the jumps at or before t_s [m]
  double clockOffset(double t_s) const;          ///< sum of the steps at or before t_s [s]
  /// The events with times in (t0_s, t1_s], by time (then: ends before starts).
  std::vector<Event> eventsIn(double t0_s, double t1_s) const;
  /// The time by which every fault has started and every window has ended [s] (0 when empty).
  double lastEventTime() const;

  /// From the flat parameter lists: windows [start1, end1, start2, end2, ...], jumps
  /// [t1, dx1, dy1, dz1, ...], steps [t1, step1, ...]. False with the reason for a list of the
  /// wrong length (values are checked by validate()).
  static bool fromLists(const std::vector<double>& depth_blackouts_s, const std::vector<double>& odom_blackouts_s,
                        const std::vector<double>& odom_jumps, const std::vector<double>& clock_steps,
                        FaultSchedule* schedule, std::string* why);
  /// One line, e.g. "depth blackout [5.0, 8.0) s; odometry jump at 12.0 s by (1.00, 0.00, 0.00) m", or "none".
  std::string describe() const;
};

/// One line for a log or the event topic: "<kind> <phase> t=<t> s ...", e.g.
/// "odom_jump step t=12.000 s offset=(1.000, 0.000, 0.000) m". The first two words are the kind and
/// the phase (what the flight monitor reads).
std::string describe(const FaultSchedule::Event& event);

}  // namespace topo_planner
