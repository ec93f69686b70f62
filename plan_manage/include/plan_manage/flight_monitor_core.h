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
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "plan_env/occupancy_map.h"

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
  double total_ms = 0.0;   ///< check + search + optimisation [ms]
  bool published = false;  ///< a trajectory came out
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
  int replans = 0;               ///< planning calls that published a trajectory
  int replan_failures = 0;       ///< planning calls that did not
  int sim_collisions = 0;        ///< simulator contacts counted while it was active
  int clearance_contacts = 0;    ///< own-check contacts that began while it was active
  int collisions() const { return sim_collisions > clearance_contacts ? sim_collisions : clearance_contacts; }
  double elapsedS(double now_s) const { return (reached ? reached_t_s : now_s) - sent_t_s; }
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
  double mean_speed_mps = 0.0;  ///< time average of the speed over the flight
  double max_speed_mps = 0.0;
  int replans = 0;
  int replan_failures = 0;
  double replan_ms_median = 0.0;  ///< over every planning call of the flight (0 without calls) [ms]
  double replan_ms_p95 = 0.0;
  double replan_ms_max = 0.0;
  double duration_s = 0.0;      ///< first goal sent to last goal reached (or the end) [s]
  double path_length_m = 0.0;
};

/// Follows a flight through a goal sequence, fed with odometry, planner events and collision
/// counts; decides when a goal is reached or has timed out, and keeps the statistics.
///
/// A goal is reached when the body is within goal_tolerance_m of it and slower than
/// goal_max_speed_mps: the planner brings the vehicle to rest at every goal (each is a new mission
/// ending at rest), so arriving means being close and nearly stopped; a fast pass through the
/// tolerance sphere (an overshoot, or a trajectory that grazes the goal on the way elsewhere) is
/// not an arrival. The next goal becomes active at once. The flight ends when the last goal is
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
    double goal_timeout_s = 90.0;        ///< time allowed per goal [s]
    /// Own contact check: a clearance below this is a contact (the body sphere's radius; keep it
    /// equal to the simulator's) [m].
    double collision_radius_m = 0.15;
    double contact_release_m = 0.05;     ///< a contact ends above collision_radius_m + this [m]
    double trace_period_s = 0.05;        ///< odometry rows kept every this long (20 Hz) [s]
    double max_sample_gap_s = 1.0;       ///< larger odometry gaps are not integrated (speed, path) [s]

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
};

/// A reference trajectory of the planner (its sampled positions), as received.
struct ReferenceRecord {
  int id = 0;
  double t_s = 0.0;  ///< since the flight started (negative before it) [s]
  std::vector<Eigen::Vector3d> points_m;
};

/// One line for the log when a goal ends, e.g. "goal 2/3 reached at t=41.2 s in 20.1 s: ...".
std::string formatGoalLine(const GoalRecord& goal, int goals_total, double flight_start_s, double now_s);
/// The multi-line flight report.
std::string formatReport(const FlightSummary& summary, const std::string& name);

// Files of a flight (output_dir/<name>...). Each returns false and says why if it cannot write.
// Times are seconds since the flight started.

/// <name>.csv: t,x,y,z,vx,vy,vz,speed,clearance_m,goal_index
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
bool writeReportJson(const std::string& path, const FlightSummary& summary, const std::vector<GoalRecord>& goals,
                     double start_t_s, const FlightReportInfo& info, std::string* error);

/// A JSON string literal (quoted, escaped) of s.
std::string jsonString(const std::string& s);
/// A JSON number of x (shortest round-trip form), or null for NaN/inf.
std::string jsonNumber(double x);

}  // namespace topo_planner
