// The simulation's true world: topics and parameters are documented in uav_sim/ros/map_generator_server.h.
#include <ros/ros.h>

#include "topo_planner/uav_sim/ros/map_generator_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "map_generator");
  ros::NodeHandle nh("~");
  topo_planner::MapGeneratorServer::Config config;
  if (!topo_planner::readMapGeneratorParams(nh, &config)) return 1;
  std::string error;
  const auto server = topo_planner::MapGeneratorServer::create(nh, config, &error);
  if (!server) {
    ROS_ERROR("map_generator: cannot start: %s", error.c_str());
    return 1;
  }
  ros::spin();  // keeps the latched cloud available
  return 0;
}
