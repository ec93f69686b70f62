// The simulated quadrotor: topics and parameters are documented in uav_sim/ros/quadrotor_sim.h.
#include <ros/ros.h>

#include "topo_planner/uav_sim/ros/quadrotor_sim.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "quadrotor_sim");
  ros::NodeHandle nh, pnh("~");
  topo_planner::QuadrotorSim::Config config;
  if (!topo_planner::readQuadrotorSimParams(pnh, &config)) return 1;
  std::string error;
  auto sim = topo_planner::QuadrotorSim::create(nh, pnh, config, &error);
  if (!sim) {
    ROS_ERROR("quadrotor_sim: cannot start: %s", error.c_str());
    return 1;
  }
  ros::spin();  // the true map; the loop and the rotor commands have their own threads
  sim.reset();  // joins the loop
  return 0;
}
