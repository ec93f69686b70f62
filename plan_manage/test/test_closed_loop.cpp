// Rostest of the closed loop (closed_loop.test): the flight monitor flies the planner through the
// scenario's goals in the simulator; this node waits for its latched FlightResult and checks that
// every goal was reached without a collision. The wall-clock wait is a guard against a hung
// simulation (a result that never comes), not a performance budget.

#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <topo_planner/FlightResult.h>
#include <topo_planner/PlannerConfig.h>

#include <map>
#include <string>

namespace {

TEST(ClosedLoop, ReachesEveryGoalWithoutCollision) {
  ros::NodeHandle nh, pnh("~");
  double wall_timeout_s = 270.0;
  int goals_expected = 3;
  pnh.param("wall_timeout_s", wall_timeout_s, wall_timeout_s);
  pnh.param("goals_expected", goals_expected, goals_expected);

  topo_planner::FlightResultConstPtr result;
  ros::Subscriber sub = nh.subscribe<topo_planner::FlightResult>(
      "/flight_monitor/result", 1, [&](const topo_planner::FlightResultConstPtr& msg) { result = msg; });
  // The planner's /diagnostics while it flies (plan_manage/health.h): the worst level of each task
  // and its last values.
  std::map<std::string, diagnostic_msgs::DiagnosticStatus> last;
  std::map<std::string, int> worst;
  ros::Subscriber diag_sub = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 20, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& msg) {
        for (const auto& st : msg->status) {
          const std::string task = st.name.substr(st.name.rfind(' ') + 1);
          if (st.hardware_id != "topo_planner" || (task != "planner" && task != "mapping")) continue;
          last[task] = st;
          worst[task] = std::max(worst.count(task) ? worst[task] : 0, int(st.level));
        }
      });
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(wall_timeout_s);
  while (!result && ros::ok() && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_TRUE(result != nullptr) << "no /flight_monitor/result within " << wall_timeout_s << " s of wall time";

  ROS_INFO("closed loop: %s: %u/%u goals, %u collisions, min clearance %.2f m, speed mean %.2f max %.2f m/s, "
           "%u replans (%u failed), replanning median %.1f ms p95 %.1f ms, %.1f s, %.1f m",
           result->success ? "success" : "FAILURE", result->goals_reached, result->goals_total, result->collisions,
           result->min_clearance_m, result->mean_speed_mps, result->max_speed_mps, result->replans,
           result->replan_failures, result->replan_ms_median, result->replan_ms_p95, result->duration_s,
           result->path_length_m);
  EXPECT_TRUE(result->success) << result->message;
  EXPECT_EQ(result->goals_total, uint32_t(goals_expected));
  EXPECT_EQ(result->goals_reached, uint32_t(goals_expected)) << result->message;
  EXPECT_EQ(result->collisions, 0u) << result->message;
  EXPECT_GT(result->min_clearance_m, 0.0);
  EXPECT_GT(result->replans, 0u);

  // Both tasks reported; a flight without faults never had stale inputs (ERROR) after its start.
  ros::spinOnce();
  ASSERT_TRUE(last.count("planner") && last.count("mapping")) << "no planner or mapping status on /diagnostics";
  EXPECT_LT(worst["planner"], int(diagnostic_msgs::DiagnosticStatus::ERROR)) << last["planner"].message;
  std::string calls;
  for (const auto& kv : last["planner"].values)
    if (kv.key == "planning calls total") calls = kv.value;
  EXPECT_GT(std::stoi(calls.empty() ? "0" : calls), 0);

  // The flight limits at run time (dynamic_reconfigure ~limits): the loaded values first; a valid
  // change is taken, one the parameter checks refuse (braking above max_brake_acc_mps2) is reverted.
  diag_sub.shutdown();
  ros::AsyncSpinner spinner(1);  // the client's updates arrive while it waits
  spinner.start();
  dynamic_reconfigure::Client<topo_planner::PlannerConfig> limits("/planner/limits");
  topo_planner::PlannerConfig current;
  ASSERT_TRUE(limits.getCurrentConfiguration(current, ros::Duration(10.0))) << "no /planner/limits";
  double max_vel = 0.0;
  ASSERT_TRUE(ros::param::get("/planner/max_vel_mps", max_vel));
  EXPECT_DOUBLE_EQ(current.max_vel_mps, max_vel);
  topo_planner::PlannerConfig change = current;
  change.max_vel_mps = 1.5;
  change.safety_clearance_m = 0.25;
  ASSERT_TRUE(limits.setConfiguration(change));
  EXPECT_DOUBLE_EQ(change.max_vel_mps, 1.5);
  EXPECT_DOUBLE_EQ(change.safety_clearance_m, 0.25);
  topo_planner::PlannerConfig refused = change;
  refused.brake_acc_mps2 = 19.0;
  ASSERT_TRUE(limits.setConfiguration(refused));
  EXPECT_DOUBLE_EQ(refused.brake_acc_mps2, current.brake_acc_mps2);  // reverted
  EXPECT_DOUBLE_EQ(refused.max_vel_mps, 1.5);                        // the accepted change stays
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_closed_loop");
  return RUN_ALL_TESTS();
}
