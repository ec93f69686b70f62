#pragma once
// The ROS-free core of the flight monitor (plan_manage/flight_monitor.h): the bookkeeping of a
// flight through a goal sequence, its report, and the files written at its end.
//
// It measures what the paper's real-world and simulated experiments report for a flight (Zhou et
// al. ICRA 2020, Sec. VI-C/D): whether every goal was reached without collision, the clearance
// kept from the obstacles, the speeds flown, and how often and how fast the local replanner ran.
//
// Clearance is the distance from the body centre to the nearest occupied voxel (the solid cube) of
// the simulator's true map (uav_sim/truth_map.h: ESDF broad phase, exact narrow phase); the wrapper
// measures it and feeds it in with every odometry sample.

#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_manage/flight_oracle.h"
#include "topo_planner/plan_manage/speed_account.h"

namespace topo_planner {

/// One entry per occupied x-y voxel column of `map`: the column centre (x, y) and the top of its
/// highest occupied voxel (z) [m], sorted by x then y. For the top-view plot of the true map.
std::vector<Eigen::Vector3d> occupiedColumns(const OccupancyMap& map);

/// How a flight ended.
enum class FlightStatus {
  kInProgress,   ///< not started or still flying
  kSuccess,      ///< every goal reached, no collision
  kCollision,    ///< every goal reached, but the vehicle touched the true map
  kGoalTimeout,  ///< a goal was not reached within goal_timeout_s
  kNoStart,      ///< the map, the odometry or the planner never became ready
  kInterrupted,  ///< the monitor was shut down before the end
};
const char* toString(FlightStatus status);

/// One odometry sample, world frame.
struct OdometrySample {
  double t_s = 0.0;                                       ///< [s]
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();   ///< body centre [m]
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();  ///< world frame [m/s]
  double clearance_m = 0.0;  ///< body centre to the nearest obstacle, NaN if unknown [m]
};

/// One planning call of the planner (a ReplanEvent).
struct ReplanRecord {
  double t_s = 0.0;                                      ///< [s]
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  ///< start of the planned trajectory [m]
  std::string trigger, status, fallback;
  std::string message;     ///< the planner's account of the call (why it failed)
  double total_ms = 0.0;   ///< check + search + optimisation [ms]
  bool published = false;  ///< a trajectory came out
  /// The FSM's stall remedy (fallback "reroute": no progress for fsm/progress_timeout_s), not a
  /// planning call: counted in stalls, not among the replans or their failures.
  bool stall = false;
  int64_t trajectory_id = -1;
  int goal_index = -1;     ///< goal active when it arrived (set by the recorder)
};

/// A downsampled odometry row of the flight trace.
struct TraceRow {
  double t_s = 0.0;  ///< since the flight started [s]
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();
  double clearance_m = 0.0;
  int goal_index = -1;
  double commanded_speed_mps = std::numeric_limits<double>::quiet_NaN();  ///< latest setpoint's speed [m/s]
  double commanded_decel_mps2 = std::numeric_limits<double>::quiet_NaN();  ///< its acceleration against its velocity [m/s^2]
};

/// What happened while the vehicle flew towards one goal.
struct GoalRecord {
  int index = 0;
  Eigen::Vector3d goal_m = Eigen::Vector3d::Zero();
  bool sent = false;
  bool reached = false;
  bool timed_out = false;
  double sent_t_s = 0.0;     ///< when it became the active goal [s]
  double reached_t_s = 0.0;  ///< when it was reached (valid if reached) [s]
  double path_length_m = 0.0;
  double max_speed_mps = 0.0;
  double min_clearance_m = std::numeric_limits<double>::quiet_NaN();  ///< NaN before the first sample [m]
  double distance_m = std::numeric_limits<double>::quiet_NaN();  ///< body to goal at the latest sample [m]
  double oracle_time_s = std::numeric_limits<double>::quiet_NaN();  ///< the oracle's time for this leg (FlightOracle) [s]
  int replans = 0;               ///< planning calls that published a trajectory
  int replan_failures = 0;       ///< planning calls that did not
  int stalls = 0;                ///< stall re-routes of the FSM while it was active
  int sim_collisions = 0;        ///< simulator contacts counted while it was active
  int clearance_contacts = 0;    ///< own-check contacts that began while it was active
  int collisions() const { return sim_collisions > clearance_contacts ? sim_collisions : clearance_contacts; }
  double elapsedS(double now_s) const { return (reached ? reached_t_s : now_s) - sent_t_s; }
};

/// One setpoint of the trajectory server (a PositionCommand), world frame.
struct SetpointSample {
  double t_s = 0.0;                                           ///< [s]
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();       ///< [m]
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();     ///< [m/s]
  Eigen::Vector3d acceleration_mps2 = Eigen::Vector3d::Zero();  ///< [m/s^2]
  SpeedAccount::Mode mode = SpeedAccount::Mode::kTrajectory;  ///< what the server does (the speed account)
  uint64_t planner_session = 0;                               ///< the trajectory it follows ...
  int64_t trajectory_id = -1;                                 ///< ... (or followed)
};

/// A step of the commanded position larger than the motion between two setpoints allows.
struct SetpointStep {
  double t_s = 0.0;                                   ///< time of the later setpoint [s]
  Eigen::Vector3d from_m = Eigen::Vector3d::Zero();   ///< the earlier setpoint [m]
  Eigen::Vector3d to_m = Eigen::Vector3d::Zero();     ///< the later one [m]
  double allowed_m = 0.0;                             ///< |v| dt + the jump margin [m]
  bool reanchoring = false;  ///< it equals an injected odometry jump: a re-anchoring, not a jump
};

/// Watches the setpoint stream for what "setpoints never jump" (house style, flight safety) forbids
/// and for the commanded accelerations:
///  - a jump is a step in commanded position between consecutive setpoints greater than
///    max(|v_prev|, |v|) dt + jump_margin_m (v the commanded velocities, dt the time between them);
///  - a step that equals an injected odometry jump offset (within reanchor_tolerance_m plus the
///    motion allowance) and comes within reanchor_window_s after it counts once as a re-anchoring
///    (the planner holding at the measured state after a VIO jump), not as a jump; so does a step
///    onto the measured position (the latest odometry, within the same tolerance) within
///    reanchor_window_s after odometry returned from a blackout (while it was away the commanded
///    state ran on and the vehicle did not follow: holding at the measured state is the safe move);
///  - the deceleration is the commanded acceleration against the commanded velocity (above
///    min_speed_mps), the acceleration its norm; each also from the finite difference of the
///    commanded velocity over at least finite_difference_s (a velocity step shows there, not in the
///    acceleration field), the worse of the two counting; not across a re-anchoring, which sets the
///    command to the measured state, velocity included (the vehicle does not change speed there;
///    the command meets it).
/// A setpoint older than the previous one (a ROS time step the caller could not remove) is a new
/// start: no step allowance beyond the margin, no finite difference across it. One caller.
class SetpointWatch {
 public:
  struct Config {
    double jump_margin_m = 0.05;         ///< a step above |v| dt + this is a jump [m]
    double reanchor_tolerance_m = 0.25;  ///< a step this close (+ |v| dt) to an odometry jump re-anchors [m]
    double reanchor_window_s = 2.0;      ///< ... if it comes within this after the odometry jump [s]
    double finite_difference_s = 0.05;   ///< velocity differences over at least this ... [s]
    double max_finite_difference_s = 0.5;  ///< ... and at most this give an acceleration [s]
    double min_speed_mps = 0.1;          ///< decelerations count above this commanded speed [m/s]
    size_t max_steps_kept = 20;          ///< jumps and re-anchorings kept for the report

    bool validate(std::string* why) const;
  };
  struct Stats {
    int setpoints = 0;
    int jumps = 0;
    int reanchorings = 0;
    double max_decel_mps2 = 0.0;  ///< worst commanded deceleration [m/s^2]
    double max_decel_t_s = std::numeric_limits<double>::quiet_NaN();  ///< when [s]
    bool max_decel_from_difference = false;  ///< it came from the velocity difference, not the field
    double max_acc_mps2 = 0.0;    ///< worst commanded acceleration (norm) [m/s^2]
    double max_excess_m = 0.0;    ///< largest step beyond its allowance among the jumps [m]
    std::vector<SetpointStep> steps;  ///< the first max_steps_kept jumps and re-anchorings
  };

  SetpointWatch();
  explicit SetpointWatch(const Config& config);
  void addSetpoint(const SetpointSample& s);
  /// An injected odometry jump: from t_s the odometry is offset by delta_m more than before.
  void addOdometryJump(double t_s, const Eigen::Vector3d& delta_m);
  /// Odometry came back at t_s after a blackout.
  void addOdometryReturn(double t_s);
  /// The latest measured (odometry) position [m].
  void setMeasuredPosition(const Eigen::Vector3d& p_m);
  const Stats& stats() const { return stats_; }
  /// Commanded speed of the latest setpoint (NaN before the first) [m/s].
  double lastSpeed() const;
  /// Its acceleration against its velocity (0 below min_speed_mps; NaN before the first) [m/s^2].
  double lastDecel() const;

 private:
  struct PendingJump {
    double t_s;
    Eigen::Vector3d delta_m;
  };
  Config config_;
  Stats stats_;
  bool have_previous_ = false;
  SetpointSample previous_;
  std::deque<SetpointSample> history_;  // recent setpoints, oldest first (finite differences)
  std::vector<PendingJump> pending_;
  std::vector<double> returns_;  // odometry returns still within the window [s]
  bool have_measured_ = false;
  Eigen::Vector3d measured_m_ = Eigen::Vector3d::Zero();
};

/// Turns the stamps of a steady stream (the simulator's ground truth, 200 Hz) into a flight time
/// that does not jump with ROS time: a stamp that goes back by more than max_back_s, or forward by
/// more than max_gap_s, is a ROS time step, absorbed into a correction so that the flight time
/// goes on by the stream's previous interval. Other times (stamps of other topics, now()) get the
/// current correction. One caller.
class TimeStepFilter {
 public:
  explicit TimeStepFilter(double max_gap_s = 0.5, double max_back_s = 1e-3);
  /// A stamp of the stream; returns its corrected time.
  double addStreamStamp(double raw_s);
  /// raw_s + the current correction.
  double correct(double raw_s) const { return raw_s + correction_s_; }
  double correction() const { return correction_s_; }
  int steps() const { return steps_; }  ///< time steps absorbed

 private:
  double max_gap_s_, max_back_s_;
  bool have_last_ = false;
  double last_raw_s_ = 0.0;
  double last_interval_s_ = 0.0;
  double correction_s_ = 0.0;
  int steps_ = 0;
};

/// When the flight monitor sends the active goal again (besides its resend_period_s rule): after
/// the planner restarted (a heartbeat with a planner_session other than the last one) and after an
/// injected fault cleared, settle_s after the latest such trigger and once the planner says its
/// inputs are fresh (or has never sent a heartbeat), so that a restarted or recovered planner gets
/// the mission's remaining goal and the mission can complete. One caller.
class GoalResendPolicy {
 public:
  explicit GoalResendPolicy(double settle_s = 1.0) : settle_s_(settle_s) {}
  /// A heartbeat. Returns true when it shows a restart (a new session after an earlier one).
  bool onHeartbeat(uint64_t planner_session, bool inputs_ok, double t_s);
  /// A fault cleared (a blackout ended, an odometry jump or a clock step happened) at t_s.
  void onFaultCleared(double t_s);
  /// True once per trigger when the resend is due at t_s.
  bool due(double t_s);
  int restarts() const { return restarts_; }

 private:
  double settle_s_;
  bool have_session_ = false;
  uint64_t session_ = 0;
  bool inputs_ok_ = true;
  bool pending_ = false;
  double due_t_s_ = 0.0;
  int restarts_ = 0;
};

/// An injected fault's change as the monitor saw it (the simulator's fault event).
struct FaultRecord {
  double t_s = 0.0;   ///< [s]
  std::string kind;   ///< depth_blackout, odom_blackout, odom_jump, clock_step
  std::string phase;  ///< start, end, step
  std::string text;   ///< the whole event line
  double commanded_speed_mps = std::numeric_limits<double>::quiet_NaN();  ///< latest setpoint's speed then [m/s]
  double true_speed_mps = std::numeric_limits<double>::quiet_NaN();       ///< the vehicle's true speed then [m/s]
  int goal_index = -1;  ///< goal active then
};

/// The figures of a flight (the FlightResult message, plus a few details).
struct FlightSummary {
  FlightStatus status = FlightStatus::kInProgress;
  bool success = false;  ///< every goal reached, no collision
  std::string message;
  int goals_total = 0;
  int goals_reached = 0;
  int collisions = 0;          ///< max(sim_collisions, clearance_contacts): the two see the same contacts
  int sim_collisions = 0;      ///< contacts the simulator reported during the flight
  int clearance_contacts = 0;  ///< contacts of the monitor's own clearance check
  double min_clearance_m = std::numeric_limits<double>::quiet_NaN();  ///< NaN without samples [m]
  Eigen::Vector3d min_clearance_position_m = Eigen::Vector3d::Zero();
  /// Time average of the speed over the flight, and the largest: of the ground truth when there is
  /// one (odometry noise adds speed and path that were not flown), else of the odometry.
  double mean_speed_mps = 0.0;
  double max_speed_mps = 0.0;
  bool measured_on_truth = false;  ///< speed and path length come from the ground truth
  int replans = 0;
  int replan_failures = 0;
  int stalls = 0;                 ///< stall re-routes (ReplanRecord::stall), not planning calls
  double replan_ms_median = 0.0;  ///< over every planning call of the flight (0 without calls) [ms]
  double replan_ms_p95 = 0.0;
  double replan_ms_max = 0.0;
  double duration_s = 0.0;      ///< first goal sent to last goal reached (or the end) [s]
  double path_length_m = 0.0;   ///< flown (ground truth when there is one) [m]
  // The speed account (SpeedAccount) over the flight, and the oracle (FlightOracle).
  SpeedAccount::Totals speed;  ///< time fast and time slow per cause
  double fast_share = 0.0;     ///< share of the counted time at or above the account's fast_fraction x max_vel
  /// The oracle's time for the goals reached, the flight's time for them, and their ratio (NaN
  /// without an oracle or a goal reached) [s].
  double oracle_time_s = std::numeric_limits<double>::quiet_NaN();
  double reached_time_s = std::numeric_limits<double>::quiet_NaN();
  double time_ratio = std::numeric_limits<double>::quiet_NaN();
  // The setpoints (SetpointWatch) and the faults.
  int setpoints = 0;            ///< setpoints seen while flying
  int setpoint_jumps = 0;       ///< steps over |v| dt + the margin, re-anchorings excepted
  int reanchorings = 0;         ///< steps equal to an injected odometry jump
  double max_decel_mps2 = 0.0;  ///< worst commanded deceleration [m/s^2]
  double max_acc_mps2 = 0.0;    ///< worst commanded acceleration (norm) [m/s^2]
  int faults_injected = 0;      ///< fault starts, odometry jumps and clock steps seen while flying
  int planner_restarts = 0;     ///< new planner sessions seen while flying
  int goal_resends = 0;         ///< goals sent again (restart, fault cleared, no planning call)
  int time_steps = 0;           ///< ROS time steps absorbed by the monitor's clock
};

/// Follows a flight through a goal sequence, fed with odometry, planner events and collision
/// counts; decides when a goal is reached or has timed out, and keeps the statistics.
///
/// A goal is reached when the body is within goal_tolerance_m of it and slower than
/// goal_max_speed_mps: the planner brings the vehicle to rest at every goal (each is a new mission
/// ending at rest), so arriving means being close and nearly stopped; a fast pass through the
/// tolerance sphere (an overshoot, or a trajectory that grazes the goal on the way elsewhere) is
/// not an arrival. With pass_through the goals are the waypoints of one mission: the intermediate
/// ones count when passed within waypoint_tolerance_m at any speed, the last as above. The next goal becomes active at once. The flight ends when the last goal is
/// reached or when one times out (the remaining goals then count as not reached).
///
/// Collisions are counted twice, independently: the simulator's own contact counter, and the
/// monitor's check of the clearance at every sample (a contact begins below collision_radius_m
/// and ends above it plus contact_release_m). Both see the same contacts, so the flight's count is
/// the larger of the two. Not thread-safe: one caller.
class FlightRecorder {
 public:
  struct Config {
    double goal_tolerance_m = 0.5;       ///< body within this distance of the goal [m]
    double goal_max_speed_mps = 1.0;     ///< ... and slower than this; 0 = no speed condition [m/s]
    /// The goals are the waypoints of one mission, flown through without stopping: every goal but
    /// the last counts as reached when the body comes within waypoint_tolerance_m, at any speed.
    bool pass_through = false;
    double waypoint_tolerance_m = 1.0;   ///< see pass_through (the planner's own waypoint radius) [m]
    double goal_timeout_s = 90.0;        ///< time allowed per goal [s]
    /// Own contact check: a clearance below this is a contact (the body sphere's radius; keep it
    /// equal to the simulator's) [m].
    double collision_radius_m = 0.15;
    double contact_release_m = 0.05;     ///< a contact ends above collision_radius_m + this [m]
    double trace_period_s = 0.05;        ///< odometry rows kept every this long (20 Hz) [s]
    double max_sample_gap_s = 1.0;       ///< larger odometry gaps are not integrated (speed, path) [s]
    SetpointWatch::Config setpoints;     ///< setpoint jumps and accelerations
    SpeedAccount::Config speed;          ///< the speed account (the flight's limits)

    bool validate(std::string* why) const;
  };

  /// What one call did.
  struct Update {
    int goal_reached = -1;    ///< index of the goal reached by this call, or -1
    int goal_timed_out = -1;  ///< index of the goal that timed out, or -1
    int next_goal = -1;       ///< index of the goal that became active, or -1
    bool finished = false;    ///< the flight ended with this call
  };

  FlightRecorder(const Config& config, const std::vector<Eigen::Vector3d>& goals);

  const Config& config() const { return config_; }
  /// Starts the flight at t_s: goal 0 becomes active. With no goals the flight ends at once
  /// (kSuccess, nothing to do). Ignored once started.
  Update start(double t_s);
  /// An odometry sample (world frame). Samples before start() or after the end only update the
  /// simulator's collision baseline; non-finite ones are ignored.
  Update addOdometry(const OdometrySample& sample);
  /// Checks the active goal's time limit at t_s (for when odometry stops).
  Update checkTimeout(double t_s);
  /// A planning call; counted towards the active goal while the flight runs, ignored otherwise.
  void addReplan(ReplanRecord record);
  /// The simulator's collision counter (contacts since it started). Values seen before start()
  /// are the baseline; the flight's sim_collisions is the largest value since minus that.
  void addSimCollisionCount(double t_s, uint32_t count_since_sim_start);
  /// Ends the flight from outside (kNoStart, kInterrupted) at t_s; ignored once it has ended.
  void finish(double t_s, FlightStatus status, const std::string& message);
  /// The vehicle's true state (the simulator's ground truth), for the clearance and the contact
  /// check when the odometry samples carry none (NaN clearance): odometry may be offset by an
  /// injected jump or stop in a blackout, the true body does neither. Only while flying.
  void addTruth(const OdometrySample& truth);
  /// A setpoint of the trajectory server (SetpointWatch, the speed account); only while flying.
  void addSetpoint(const SetpointSample& setpoint);
  /// A trajectory the planner published (the speed account reads its kind and brake point).
  void addTrajectory(const SpeedAccount::Trajectory& trajectory) { speed_account_.addTrajectory(trajectory); }
  /// The oracle's times per goal (FlightOracle::Result::time_s, one per goal); ignored when not ok.
  void setOracle(const FlightOracle::Result& oracle);
  const SpeedAccount& speedAccount() const { return speed_account_; }
  /// An injected odometry jump by delta_m at t_s (a setpoint step equal to it re-anchors).
  void addOdometryJump(double t_s, const Eigen::Vector3d& delta_m);
  /// Odometry came back after a blackout at t_s (a setpoint step onto the measured position re-anchors).
  void addOdometryReturn(double t_s);
  /// An injected fault's change (kind, phase: the first two words of the simulator's event line).
  void addFault(double t_s, const std::string& kind, const std::string& phase, const std::string& text);
  /// Counters kept by the caller, for the summary.
  void setCounters(int planner_restarts, int goal_resends, int time_steps);
  const SetpointWatch& setpoints() const { return setpoint_watch_; }
  const std::vector<FaultRecord>& faults() const { return faults_; }

  bool started() const { return started_; }
  bool finished() const { return status_ != FlightStatus::kInProgress; }
  FlightStatus status() const { return status_; }
  int activeGoal() const { return active_; }
  double startTime() const { return start_t_s_; }
  double lastTime() const { return last_t_s_; }
  const std::vector<GoalRecord>& goals() const { return goals_; }
  const std::vector<TraceRow>& trace() const { return trace_; }
  const std::vector<ReplanRecord>& replans() const { return replans_; }
  FlightSummary summary() const;

 private:
  void advanceFrom(int reached, double t_s, Update* update);
  void addClearance(const Eigen::Vector3d& position_m, double clearance_m, GoalRecord* goal);
  void endFlight(double t_s, FlightStatus status, const std::string& message);
  bool flying() const { return started_ && status_ == FlightStatus::kInProgress; }

  Config config_;
  std::vector<GoalRecord> goals_;
  bool started_ = false;
  FlightStatus status_ = FlightStatus::kInProgress;
  std::string message_;
  int active_ = -1;
  double start_t_s_ = 0.0;
  double end_t_s_ = 0.0;
  double last_t_s_ = 0.0;

  bool have_previous_ = false;
  OdometrySample previous_;
  double speed_integral_m_ = 0.0;  // integral of the speed over time [m]
  double integrated_s_ = 0.0;      // time covered by it [s]
  double path_length_m_ = 0.0;
  double max_speed_mps_ = 0.0;
  // The same of the ground truth: once a true state arrived, the odometry adds nothing to them.
  bool truth_seen_ = false;
  bool have_previous_truth_ = false;
  OdometrySample previous_truth_;
  SpeedAccount speed_account_;
  double min_clearance_m_ = std::numeric_limits<double>::quiet_NaN();
  Eigen::Vector3d min_clearance_position_m_ = Eigen::Vector3d::Zero();
  double next_trace_t_s_ = 0.0;  // time slot of the next trace row
  bool in_contact_ = false;
  int clearance_contacts_ = 0;
  bool have_sim_count_ = false;
  uint32_t sim_count_base_ = 0;
  uint32_t sim_count_max_ = 0;

  std::vector<TraceRow> trace_;
  std::vector<ReplanRecord> replans_;

  SetpointWatch setpoint_watch_;
  double truth_speed_mps_ = std::numeric_limits<double>::quiet_NaN();
  double truth_clearance_m_ = std::numeric_limits<double>::quiet_NaN();
  std::vector<FaultRecord> faults_;
  int planner_restarts_ = 0, goal_resends_ = 0, time_steps_ = 0;
};

/// A reference trajectory of the planner (its sampled positions), as received.
struct ReferenceRecord {
  int id = 0;
  double t_s = 0.0;  ///< since the flight started (negative before it) [s]
  std::vector<Eigen::Vector3d> points_m;
};

/// One line for the log when a goal ends, e.g. "goal 2/3 reached at t=41.2 s in 20.1 s: ...".
std::string formatGoalLine(const GoalRecord& goal, int goals_total, double flight_start_s, double now_s);
/// The speed account's slow causes with their shares, e.g. "timing 61%, limits 22%, held 17%".
std::string accountLine(const SpeedAccount::Totals& totals);
/// The multi-line flight report.
std::string formatReport(const FlightSummary& summary, const std::string& name);

// Files of a flight (output_dir/<name>...). Each returns false and says why if it cannot write.
// Times are seconds since the flight started.

/// <name>.csv: t,x,y,z,vx,vy,vz,speed,clearance_m,goal_index,cmd_speed,cmd_decel
bool writeTraceCsv(const std::string& path, const std::vector<TraceRow>& rows, std::string* error);
/// <name>_events.csv: t,x,y,z,trigger,status,fallback,total_ms,trajectory_id,goal_index
bool writeReplanCsv(const std::string& path, const std::vector<ReplanRecord>& replans, double start_t_s,
                    std::string* error);
/// <name>_map.csv: x,y,z_max (TruthMap::occupiedColumns)
bool writeMapCsv(const std::string& path, const std::vector<Eigen::Vector3d>& columns, std::string* error);
/// <name>_reference.csv: id,t,x,y,z (one row per point)
bool writeReferenceCsv(const std::string& path, const std::vector<ReferenceRecord>& references, std::string* error);

/// <name>_report.json: every FlightSummary field, the goals, the start, per-goal records and
/// `scenario` (string key -> JSON value text, written verbatim: callers pass numbers, true/false,
/// or quoted strings made with jsonString()).
struct FlightReportInfo {
  std::string name;
  Eigen::Vector3d start_m = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  double map_resolution_m = 0.1;
  size_t map_occupied_voxels = 0;
  double collision_radius_m = 0.15;  ///< of the own contact check (FlightRecorder::Config)
  std::map<std::string, std::string> scenario;
};
/// With `recorder`, also the faults seen and the setpoint jumps and re-anchorings kept ("faults",
/// "setpoint_steps").
bool writeReportJson(const std::string& path, const FlightSummary& summary, const std::vector<GoalRecord>& goals,
                     double start_t_s, const FlightReportInfo& info, std::string* error,
                     const FlightRecorder* recorder = nullptr);
/// The text of that file (the monitor also publishes it on ~report).
std::string reportJson(const FlightSummary& summary, const std::vector<GoalRecord>& goals, double start_t_s,
                       const FlightReportInfo& info, const FlightRecorder* recorder = nullptr);

/// A JSON string literal (quoted, escaped) of s.
std::string jsonString(const std::string& s);
/// A JSON number of x (shortest round-trip form), or null for NaN/inf.
std::string jsonNumber(double x);

}  // namespace topo_planner
