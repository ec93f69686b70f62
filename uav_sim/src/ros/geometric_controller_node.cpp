// The geometric tracking controller: topics and parameters are documented in uav_sim/ros/controller_server.h.
#include <ros/ros.h>

#include "topo_planner/uav_sim/ros/controller_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "geometric_controller");
  ros::NodeHandle nh, pnh("~");
  topo_planner::ControllerServer::Config config;
  if (!topo_planner::readControllerParams(pnh, &config)) return 1;
  std::string error;
  const auto server = topo_planner::ControllerServer::create(nh, config, &error);
  if (!server) {
    ROS_ERROR("geometric_controller: cannot start: %s", error.c_str());
    return 1;
  }
  ros::spin();  // one thread: odometry and commands never overlap
  return 0;
}
