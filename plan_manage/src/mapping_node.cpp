// Occupancy + ESDF mapping node: topics and parameters are documented in plan_manage/mapping_server.h.
#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include "topo_planner/plan_manage/mapping_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "mapping_node");
  ros::NodeHandle nh("~");
  topo_planner::MappingServer::Config config;
  if (!topo_planner::readMappingParams(nh, &config)) return 1;
  std::string error;
  const auto server = topo_planner::MappingServer::create(nh, config, &error);
  if (!server) {
    ROS_ERROR("mapping: cannot start: %s", error.c_str());
    return 1;
  }
  // /diagnostics: "<node>: mapping" (plan_manage/health.h), at ~diagnostic_period (1 s by default).
  diagnostic_updater::Updater updater;
  updater.setHardwareID("topo_planner");
  updater.add("mapping", [&](diagnostic_updater::DiagnosticStatusWrapper& status) {
    topo_planner::healthToStatus(server->health(ros::Time::now().toSec()), &status);
  });
  const ros::Timer diagnostics_timer = nh.createTimer(ros::Duration(0.1), [&](const ros::TimerEvent&) { updater.update(); });
  // Two threads: fusion and publishing overlap (MappingServer's locking rule makes that safe).
  ros::AsyncSpinner spinner(2);
  spinner.start();
  ros::waitForShutdown();
  return 0;
}
