#pragma once
// PlannerServer: the ROS wrapper of the replanning FSM (topo_replan/replan_fsm.h), with the mapping
// (MappingServer) in the same process so the planner reads the ESDF without copying it. The node
// `planner_node` runs one; it is what runs on a real drone (with the trajectory server).
//
// Threads (each on its own callback queue and spinner thread, so none blocks another):
//   mapping   the MappingServer's depth/pose/cloud callbacks and publishers (2 threads)
//   planning  the FSM tick every plan_period_s: goals, horizon checks, replanning (holds the map's
//             read lock while it plans, so a fusion waits at most one planning call)
//   safety    the collision check of the executing trajectory every safety_period_s and the
//             emergency stop
//   main      odometry and goals
//
// Inputs are watched by the FSM (topo_replan/replan_fsm.h, "Input liveness"): odometry (stamp and
// arrival; odometry in another frame than frame_id, or stamped before the last one, is ignored with a
// throttled warning) and the mapping's last fused depth frame, passed to the FSM before every tick
// and safety check. Stale inputs refuse goals, stop planning and brake a moving vehicle to a hover.
//
// Topics (private; remap them in the launch file)
//   Subscribed  ~odometry        nav_msgs/Odometry (body pose; twist in the child frame unless
//                                odom_twist_in_world)
//               ~goal            geometry_msgs/PoseStamped (rviz 2D Nav Goal; placed at goal_height_m)
//               ~waypoints       nav_msgs/Path (3-D goals, flown in order)
//               ~position_cmd    topo_planner/PositionCommand, the trajectory server's setpoint: when
//                                the server stops or holds on its own (watchdog, a refused
//                                trajectory), the FSM plans from its hold (ReplanFsm, "The trajectory
//                                server")
//               ~mapping/...     the mapping topics (plan_manage/mapping_server.h)
//   Published   ~bspline         topo_planner/Bspline, every trajectory the FSM returns (with this
//                                process's random planner_session, so a restarted planner is accepted)
//               ~heartbeat       topo_planner/PlannerHeartbeat at every safety check: session, state,
//                                input freshness (the trajectory server stops the vehicle without it)
//               ~replan_event    topo_planner/ReplanEvent, every planning call
//               ~reference_path  nav_msgs/Path (latched), the global reference
//               ~global_route    nav_msgs/Path (latched), the mission's global route (empty: none)
//               ~vis/trajectory, ~vis/candidates, ~vis/guide_paths   visualization_msgs/MarkerArray
//               ~vis/roadmap (guards, connectors, edges of the last search)  visualization_msgs/MarkerArray
//               /diagnostics diagnostic_msgs/DiagnosticArray, "<node>: planner" and "<node>: mapping"
//                            at ~diagnostic_period (1 s by default): plan_manage/health.h
//
// Parameters: see readPlannerParams() and config/planner.yaml.
//
// Reconfigure (dynamic_reconfigure server ~limits, cfg/Planner.cfg): max_vel_mps, max_acc_mps2 (the
// reference follows at reference/speed_ratio), brake_acc_mps2, safety_clearance_m, search_clearance_m
// (the guide search, the A* fallback and, unless route/clearance_m set it apart, the global route)
// and optimizer_clearance_m. It starts with the loaded values; a change is validated like the
// parameters (ReplanFsm::reconfigure) and applied at the next tick: every plan after it keeps the
// new values, the trajectory in flight is kept. A refused change is reverted, with a warning.

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <geometry_msgs/PoseStamped.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_manage/health.h"
#include "topo_planner/plan_manage/mapping_server.h"
#include "topo_planner/plan_manage/planner_params.h"
#include "topo_planner/plan_manage/planner_settings.h"
#include "topo_planner/PlannerConfig.h"
#include "topo_planner/PositionCommand.h"
#include "topo_planner/topo_replan/replan_fsm.h"

namespace topo_planner {

class PlannerServer {
 public:
  struct Config {
    PlannerSettings node;  ///< the node's own settings (frames, periods, visualisation, goals_m)
    ReplanFsm::Config fsm;
    MappingServer::Config mapping;
  };

  static std::unique_ptr<PlannerServer> create(const ros::NodeHandle& nh, const Config& config, std::string* error);
  ~PlannerServer();

 private:
  PlannerServer(const ros::NodeHandle& nh, const Config& config);

  void odomCallback(const nav_msgs::OdometryConstPtr& msg);
  void positionCmdCallback(const PositionCommandConstPtr& msg);
  void goalCallback(const geometry_msgs::PoseStampedConstPtr& msg);
  void waypointsCallback(const nav_msgs::PathConstPtr& msg);
  void submitGoals(const std::vector<Eigen::Vector3d>& goals, const char* source);
  void planTimer(const ros::TimerEvent&);
  void safetyTimer(const ros::TimerEvent&);
  /// Publishes what a tick or a safety check returned.
  void handle(const FsmOutput& out);
  void publishReference();
  void publishRoute();
  void publishPlanMarkers(const ReplanResult& plan, const ExecTrajectory* chosen);
  /// Passes the mapping's last fused depth frame to the FSM.
  void feedDepth();
  void publishHeartbeat(double now);
  void reconfigureCallback(PlannerConfig& limits, uint32_t level);
  static PlannerConfig limitsOf(const ReplanFsm::Config& fsm);

  ros::NodeHandle nh_;
  Config config_;
  std::unique_ptr<ReplanFsm> fsm_;
  ros::CallbackQueue mapping_queue_, planning_queue_, safety_queue_;
  std::unique_ptr<MappingServer> mapping_;
  std::unique_ptr<ros::AsyncSpinner> mapping_spinner_, planning_spinner_, safety_spinner_;

  ros::Subscriber odom_sub_, goal_sub_, waypoints_sub_, position_cmd_sub_;
  uint64_t session_ = 0;  // random per process: trajectory ordering survives a restart
  int failed_plan_dumps_ = 0;  // problems saved by debug/dump_failed_plans_dir (planning thread only)
  ros::Publisher heartbeat_pub_;
  ros::Publisher tick_done_pub_;  // ~tick_done: each planning tick finished, stamped with its time
  int time_jumps_logged_ = 0;  // safety thread only
  ros::Publisher route_pub_;
  ros::Publisher bspline_pub_, event_pub_, reference_pub_, traj_vis_pub_, candidates_vis_pub_, guides_vis_pub_,
      roadmap_vis_pub_;
  ros::Timer plan_timer_, safety_timer_;
  PlannerHealth health_;                                  // thread-safe
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;  // updated by the safety thread
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<PlannerConfig>> reconfigure_;
  ReplanFsm::Config requested_;  // the FSM settings last requested (reconfigure callback only)
  std::atomic<bool> initial_goals_sent_{false};  // goals_m accepted (retried every tick until then)
};

/// The vehicle's limits (the optimiser's) and the reference's, reference_ratio of them, so that
/// detours need no time stretching (readPlannerParams and the reconfigure server).


/// Reads the planner's parameters (and the mapping's, under ~mapping) with the struct defaults,
/// validates them, and returns false after a ROS_ERROR saying what is wrong.
bool readPlannerParams(const ros::NodeHandle& nh, PlannerServer::Config* config);

}  // namespace topo_planner
