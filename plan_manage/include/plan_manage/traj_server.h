#pragma once
// TrajServer: turns the planner's B-splines into tracking setpoints at rate_hz (the core is
// topo_replan/setpoint_generator.h: take-over at each trajectory's start time, hold at the end, yaw
// along the direction of travel with a limited rate). The node `traj_server_node` runs one.
//
// Topics (private; remap them in the launch file)
//   Subscribed  ~bspline         topo_planner/Bspline
//               ~odometry        nav_msgs/Odometry (only the first one: the initial yaw)
//   Published   ~position_cmd    topo_planner/PositionCommand (for the geometric controller)
//               ~setpoint_pose   geometry_msgs/PoseStamped  (position + yaw, for a MAVROS-style bridge)
//               ~setpoint_twist  geometry_msgs/TwistStamped (velocity + yaw rate, world frame)
// Nothing is published before the first trajectory starts (the controller holds its position).
//
// Parameters: frame_id ("world"), rate_hz (100), max_yaw_rate_radps (1.5), yaw_lookahead_s (1.0),
// yaw_min_displacement_m (0.3). Invalid values stop the node with a ROS_ERROR.

#include <nav_msgs/Odometry.h>
#include <ros/ros.h>

#include <mutex>
#include <string>

#include "topo_planner/Bspline.h"
#include "topo_replan/setpoint_generator.h"

namespace topo_planner {

class TrajServer {
 public:
  struct Config {
    SetpointGenerator::Config generator;
    std::string frame_id = "world";  ///< frame of the setpoints
    double rate_hz = 100.0;          ///< setpoint rate [Hz]
  };

  TrajServer(const ros::NodeHandle& nh, const Config& config);

 private:
  void bsplineCallback(const BsplineConstPtr& msg);
  void odomCallback(const nav_msgs::OdometryConstPtr& msg);
  void timerCallback(const ros::TimerEvent&);

  ros::NodeHandle nh_;
  Config config_;
  std::mutex mutex_;  // guards generator_ and have_yaw_
  SetpointGenerator generator_;
  bool have_yaw_ = false;
  ros::Subscriber bspline_sub_, odom_sub_;
  ros::Publisher cmd_pub_, pose_pub_, twist_pub_;
  ros::Timer timer_;
};

bool readTrajServerParams(const ros::NodeHandle& nh, TrajServer::Config* config);

}  // namespace topo_planner
