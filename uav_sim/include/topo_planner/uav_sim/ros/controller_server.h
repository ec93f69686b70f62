#pragma once
// ControllerServer: the geometric tracking controller (uav_sim/geometric_controller.h, Lee et al.
// CDC 2010) between the trajectory server and the simulated quadrotor. It runs once per odometry
// message and answers it with a RotorCommand stamped with that odometry's stamp (the simulator's
// lockstep waits for exactly that answer, see uav_sim/ros/quadrotor_sim.h). The node
// `geometric_controller_node` runs one.
//
// Topics (relative names, resolved in the node's namespace)
//   Subscribed  odom                     nav_msgs/Odometry            the vehicle state
//               planning/position_cmd    topo_planner/PositionCommand the tracking reference
//   Published   controller/rotor_command topo_planner/RotorCommand    rotor speeds, thrust, moments
//
// Reference. Until the first command: hover where the first odometry put the vehicle (position and
// heading). After command_timeout_s without a command: hover where the vehicle is at that moment,
// with the last commanded heading (logged once), until commands resume. A command with NaN/inf is
// refused (throttled warning) and the last valid one stays. The command's age is measured in ROS
// time, but across a ROS time step (odometry stamps going back, or further apart than
// max_odom_interval_s) the age it had at the previous odometry is carried over, so a clock step
// does not fake a timeout (a real flight controller times commands on its own clock). Odometry with NaN/inf or a non-unit
// quaternion is refused (throttled warning) and not answered.
//
// Parameters (private; defaults are the Config defaults below; config/controller.yaml documents them)
//   position_gain [10 10 12] 1/s^2, velocity_gain [6 6 7] 1/s, attitude_gain [250 250 60] 1/s^2,
//   rate_gain [30 30 12] 1/s, max_tilt_rad 0.7, min_thrust_ratio 0.2, max_thrust_ratio 2.2,
//   command_timeout_s 0.5, max_odom_interval_s 0.25, odom_twist_in_world false, vehicle/* (config/vehicle.yaml: the
//   controller's model of the airframe).

#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <topo_planner/PositionCommand.h>

#include <memory>
#include <string>

#include "topo_planner/uav_sim/geometric_controller.h"
#include "topo_planner/uav_sim/quadrotor.h"

namespace topo_planner {

class ControllerServer {
 public:
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

  struct Config {
    GeometricController::Config gains;  ///< gains and limits
    Quadrotor::Config vehicle;          ///< the controller's model of the airframe (mass, inertia, rotors)
    double command_timeout_s = 0.5;     ///< without a command this long, hover in place [s]
    double max_odom_interval_s = 0.25;  ///< odometry further apart (or going back) is a time step or a gap [s]
    bool odom_twist_in_world = false;   ///< odometry twist in the world frame (some VIOs) instead of the body frame

    bool validate(std::string* why) const;
  };

  static std::unique_ptr<ControllerServer> create(const ros::NodeHandle& nh, const Config& config, std::string* error);

 private:
  ControllerServer(const ros::NodeHandle& nh, const Config& config);
  void odomCallback(const nav_msgs::OdometryConstPtr& msg);
  void commandCallback(const topo_planner::PositionCommandConstPtr& msg);

  ros::NodeHandle nh_;
  Config config_;
  GeometricController controller_;
  // Single-threaded spinner: the callbacks never overlap.
  bool have_reference_ = false;  // a hover reference or a command
  bool have_command_ = false;    // a command (not just the start hover)
  bool holding_ = false;         // the timeout hover is active
  TrackingReference reference_;
  ros::Time command_time_;  // arrival of the latest valid command
  ros::Time last_odom_stamp_;  // stamp of the previous odometry
  std::string world_frame_;    // the odometry's frame: position commands in another one are refused
  /// Odometry and commands stamped further than this from the clock (or not stamped) are no state or
  /// command of this clock; a ROS time step of a few seconds, whose stamps may arrive before the
  /// clock's, is not refused [s].
  static constexpr double kMaxStampOffsetS = 10.0;
  uint64_t commands_ = 0;
  ros::Subscriber odom_sub_, command_sub_;
  ros::Publisher rotor_pub_;
};

/// Reads the parameters into *config; false with a ROS_ERROR when any is invalid.
bool readControllerParams(const ros::NodeHandle& pnh, ControllerServer::Config* config);

}  // namespace topo_planner
