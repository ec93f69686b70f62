// Replanning node (FSM + mapping in one process): topics and parameters in plan_manage/planner_server.h.
#include <ros/ros.h>

#include "topo_planner/plan_manage/planner_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "planner_node");
  ros::NodeHandle nh("~");
  topo_planner::PlannerServer::Config config;
  if (!topo_planner::readPlannerParams(nh, &config)) return 1;
  std::string error;
  const auto server = topo_planner::PlannerServer::create(nh, config, &error);
  if (!server) {
    ROS_ERROR("planner: cannot start: %s", error.c_str());
    return 1;
  }
  ros::spin();  // odometry and goals; mapping, planning and safety run on their own spinners
  return 0;
}
