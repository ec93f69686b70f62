// Trajectory server node: B-splines and planner heartbeats in, 100 Hz setpoints out, with the watchdog
// and time-jump handling (plan_manage/traj_server.h).
#include <ros/ros.h>

#include "topo_planner/plan_manage/traj_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "traj_server_node");
  ros::NodeHandle nh("~");
  topo_planner::TrajServer::Config config;
  if (!topo_planner::readTrajServerParams(nh, &config)) return 1;
  topo_planner::TrajServer server(nh, config);
  ros::spin();
  return 0;
}
