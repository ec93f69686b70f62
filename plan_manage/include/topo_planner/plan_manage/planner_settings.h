#pragma once
// The planner node's own settings (beside the FSM's, ReplanFsm::Config, and the mapping's,
// MappingServer::Config): frames, timer periods, the visualisation step, the mission given as a
// parameter. ROS-free, so that their range checks are tested and fuzzed without a roscore
// (plan_manage/test/test_planner_settings.cpp, test/fuzz/params_fuzz.cpp); readPlannerParams reads
// them and refuses to start when validate() fails.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace topo_planner {

struct PlannerSettings {
  std::string frame_id = "world";     ///< world frame of odometry, goals and outputs
  bool odom_twist_in_world = false;   ///< the odometry twist is in the world frame (some VIOs)
  double goal_height_m = 1.0;         ///< height of rviz 2D Nav Goals [m]
  double plan_period_s = 0.05;        ///< FSM tick period [s]
  double safety_period_s = 0.05;      ///< safety check period [s]
  std::vector<Eigen::Vector3d> goals; ///< a mission flown once odometry arrives (param goals_m)
  double vis_sample_s = 0.05;         ///< time step of the trajectory markers [s]
  /// Forget the map when the odometry jumps (the FSM holds, then replans in the space seen anew).
  bool clear_map_on_odom_jump = true;
  double reference_speed_ratio = 0.75;  ///< the reference's limits / the optimiser's (reference/speed_ratio)
  /// Diagnostics: every failed replanning problem (map and request) is saved in this directory for
  /// replay_plan (plan_problem_io.h), up to max_failed_plan_dumps of them; empty: off (debug/...).
  std::string dump_failed_plans_dir;
  int max_failed_plan_dumps = 200;
  static constexpr int kMaxFailedPlanDumps = 100000;

  /// Smallest vis_sample_s: the markers sample a trajectory at T / vis_sample_s points (capped), a
  /// tiny step only overflows that count.
  static constexpr double kMinVisSampleS = 0.001;
  /// Timer periods: ros::Duration rounds below 1 ns to 0 (a timer that never waits; 1 ms is
  /// already 50 times the default rate), and holds 32-bit seconds (a period of a minute is no planner).
  static constexpr double kMinPeriodS = 0.001;
  static constexpr double kMaxPeriodS = 60.0;

  /// False with the reasons in *why (all of them, "; "-separated) when a field is out of range.
  bool validate(std::string* why) const;
};

}  // namespace topo_planner
