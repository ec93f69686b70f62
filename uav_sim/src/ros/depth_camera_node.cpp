// The simulated depth camera: topics and parameters are documented in uav_sim/ros/depth_camera_server.h.
#include <ros/ros.h>

#include "topo_planner/uav_sim/ros/depth_camera_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "depth_camera");
  ros::NodeHandle nh, pnh("~");
  topo_planner::DepthCameraServer::Config config;
  if (!topo_planner::readDepthCameraParams(pnh, &config)) return 1;
  std::string error;
  auto server = topo_planner::DepthCameraServer::create(nh, config, &error);
  if (!server) {
    ROS_ERROR("depth_camera: cannot start: %s", error.c_str());
    return 1;
  }
  ros::spin();  // odometry; rendering has its own thread
  server.reset();
  return 0;
}
