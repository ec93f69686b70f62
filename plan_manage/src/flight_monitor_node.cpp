// Flight monitor node: topics and parameters are documented in plan_manage/flight_monitor.h.
#include <ros/ros.h>

#include "topo_planner/plan_manage/flight_monitor.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "flight_monitor");
  ros::NodeHandle nh, pnh("~");
  topo_planner::FlightMonitor::Config config;
  if (!topo_planner::readFlightMonitorParams(pnh, &config)) return 1;
  std::string error;
  const auto monitor = topo_planner::FlightMonitor::create(nh, pnh, config, &error);
  if (!monitor) {
    ROS_ERROR("flight_monitor: cannot start: %s", error.c_str());
    return 1;
  }
  ros::spin();
  // Shut down from outside (Ctrl-C, roslaunch ending): report what was flown so far.
  monitor->finishInterrupted();
  return 0;
}
