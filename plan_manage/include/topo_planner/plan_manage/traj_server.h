#pragma once
// TrajServer: turns the planner's B-splines into tracking setpoints at rate_hz. The logic is the
// ROS-free core topo_replan/setpoint_generator.h (take-over at each trajectory's start time,
// ordering across planner restarts, the watchdog and end stops, time jumps, the yaw policy with
// the heading target); this class feeds it messages and ROS time and publishes what it returns.
// The node `traj_server_node` runs one.
//
// Failure behaviour (issue 11):
//   - planner silent (no ~heartbeat and no ~bspline for heartbeat_timeout_s) while moving: smooth
//     stop along the current trajectory's path, then hold (ROS_WARN); a new trajectory takes over;
//   - a trajectory that ends moving: the same smooth stop straight on, then hold (ROS_WARN);
//   - a restarted planner (new planner_session): its trajectories are accepted though ids restart;
//   - ROS time stepping backwards, or forwards by more than max_time_step_s: the trajectories are
//     shifted so the setpoint goes on where it was (ROS_WARN); later trajectories use the new time.
//
// Topics (private; remap them in the launch file)
//   Subscribed  ~bspline         topo_planner/Bspline
//               ~heartbeat       topo_planner/PlannerHeartbeat (the planner's liveness, 20 Hz)
//               ~odometry        nav_msgs/Odometry (until the first trajectory starts: the initial
//                                yaw, and the hold pose when hold_before_first_trajectory)
//   Published   ~position_cmd    topo_planner/PositionCommand (for the geometric controller)
//               ~setpoint_pose   geometry_msgs/PoseStamped  (position + yaw, for a MAVROS-style bridge)
//               ~setpoint_twist  geometry_msgs/TwistStamped (velocity + yaw rate, world frame)
//               ~quadrotor_cmd   quadrotor_msgs/PositionCommand, when built with quadrotor_msgs
//               ~mavros_setpoint mavros_msgs/PositionTarget, when built with mavros_msgs
//                                (plan_manage/setpoint_messages.h: fields, frames, flags)
// Nothing is published before the first trajectory starts (the controller holds its position),
// unless hold_before_first_trajectory: then a hold at the latest odometry pose (position, zero
// velocity, its yaw; trajectory_id -1) is streamed at rate_hz, as PX4 OFFBOARD needs.
//
// Parameters (config/traj_server.yaml): frame_id ("world"), rate_hz (100 Hz),
// max_yaw_rate_radps (1.5 rad/s), yaw_lookahead_s (1.0 s), yaw_min_displacement_m (0.3 m),
// heartbeat_timeout_s (0.5 s), stop_acc_mps2 (2.5 m/s^2), stop_jerk_mps3 (10 m/s^3),
// max_time_step_s (0.25 s), hold_before_first_trajectory (false). The generator's nominal period is
// 1 / rate_hz. Invalid values stop the node with a ROS_ERROR.

#include <nav_msgs/Odometry.h>
#include <ros/ros.h>

#include <mutex>
#include <string>

#include "topo_planner/Bspline.h"
#include "topo_planner/PlannerHeartbeat.h"
#include "topo_planner/topo_replan/setpoint_generator.h"

namespace topo_planner {

class TrajServer {
 public:
  struct Config {
    SetpointGenerator::Config generator;  ///< nominal_period_s is set from rate_hz
    std::string frame_id = "world";       ///< frame of the setpoints (and of accepted odometry)
    double rate_hz = 100.0;               ///< setpoint rate [Hz]
  };

  TrajServer(const ros::NodeHandle& nh, const Config& config);

 private:
  void bsplineCallback(const BsplineConstPtr& msg);
  void heartbeatCallback(const PlannerHeartbeatConstPtr& msg);
  void odomCallback(const nav_msgs::OdometryConstPtr& msg);
  void timerCallback(const ros::TimerEvent&);
  /// ROS_WARN for the events of one sample (the counters that changed).
  void logEvents(const SetpointGenerator::Stats& before, const SetpointGenerator::Stats& after,
                 const Setpoint& sp) const;

  ros::NodeHandle nh_;
  Config config_;
  std::mutex mutex_;  // guards generator_, heartbeat_session_, have_heartbeat_
  SetpointGenerator generator_;
  uint64_t heartbeat_session_ = 0;
  bool have_heartbeat_ = false;
  ros::Subscriber bspline_sub_, heartbeat_sub_, odom_sub_;
  ros::Publisher cmd_pub_, pose_pub_, twist_pub_;
  ros::Publisher quadrotor_pub_, mavros_pub_;  // advertised when built with those message packages
  ros::Timer timer_;
};

/// Reads and validates the parameters (the defaults are Config's).
bool readTrajServerParams(const ros::NodeHandle& nh, TrajServer::Config* config);

}  // namespace topo_planner
