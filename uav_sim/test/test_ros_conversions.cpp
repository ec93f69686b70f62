// The simulator's message conversions (no roscore needed): odometry twist in the body frame per
// nav_msgs, cloud round trips, and refusal of malformed input.
#include <gtest/gtest.h>
#include <sensor_msgs/PointField.h>

#include <cmath>

#include "topo_planner/uav_sim/ros/conversions.h"
#include "topo_planner/uav_sim/ros/truth_map.h"

namespace topo_planner {
namespace {

TEST(RosConversions, OdometryTwistIsInTheBodyFrame) {
  Quadrotor::State s;
  s.position = Eigen::Vector3d(1.0, 2.0, 3.0);
  s.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));  // facing +y
  s.velocity = Eigen::Vector3d(1.0, 0.0, 0.0);  // world +x: the body's right side, -y in FLU
  s.angular_velocity = Eigen::Vector3d(0.1, 0.2, 0.3);
  nav_msgs::Odometry msg;
  stateToOdometry(s, ros::Time(5.0), "world", "base_link", &msg);
  EXPECT_EQ(msg.header.frame_id, "world");
  EXPECT_EQ(msg.child_frame_id, "base_link");
  EXPECT_NEAR(msg.twist.twist.linear.x, 0.0, 1e-12);
  EXPECT_NEAR(msg.twist.twist.linear.y, -1.0, 1e-12);
  EXPECT_NEAR(msg.twist.twist.angular.z, 0.3, 1e-12);

  Quadrotor::State back;
  std::string why;
  ASSERT_TRUE(odometryToState(msg, false, &back, &why)) << why;
  EXPECT_LT((back.position - s.position).norm(), 1e-12);
  EXPECT_LT((back.velocity - s.velocity).norm(), 1e-12);
  EXPECT_LT((back.angular_velocity - s.angular_velocity).norm(), 1e-12);
  EXPECT_NEAR(yawOf(back.orientation), M_PI / 2, 1e-12);

  // A VIO publishing world-frame twist: taken as is.
  nav_msgs::Odometry world = msg;
  world.twist.twist.linear.x = 1.0;
  world.twist.twist.linear.y = 0.0;
  ASSERT_TRUE(odometryToState(world, true, &back, &why));
  EXPECT_LT((back.velocity - s.velocity).norm(), 1e-12);

  nav_msgs::Odometry bad = msg;
  bad.pose.pose.position.z = NAN;
  EXPECT_FALSE(odometryToState(bad, false, &back, &why));
  bad = msg;
  bad.pose.pose.orientation.w = 0.0;
  bad.pose.pose.orientation.z = 0.0;  // zero quaternion
  EXPECT_FALSE(odometryToState(bad, false, &back, &why));
  bad = msg;
  bad.twist.twist.angular.x = INFINITY;
  EXPECT_FALSE(odometryToState(bad, false, &back, &why));
}

TEST(RosConversions, CloudRoundTripAndMalformedClouds) {
  const std::vector<Eigen::Vector3d> points{{0.05, 0.15, 0.25}, {-1.05, 2.05, 0.95}};
  sensor_msgs::PointCloud2 cloud;
  pointsToCloud(points, "world", ros::Time(1.0), &cloud);
  std::vector<Eigen::Vector3d> back;
  std::string why;
  ASSERT_TRUE(cloudToPoints(cloud, &back, &why)) << why;
  ASSERT_EQ(back.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) EXPECT_LT((back[i] - points[i]).norm(), 1e-6);

  sensor_msgs::PointCloud2 empty;
  pointsToCloud({}, "world", ros::Time(1.0), &empty);
  EXPECT_TRUE(cloudToPoints(empty, &back, &why));
  EXPECT_TRUE(back.empty());

  sensor_msgs::PointCloud2 truncated = cloud;
  truncated.data.resize(truncated.data.size() - 1);
  EXPECT_FALSE(cloudToPoints(truncated, &back, &why));
  sensor_msgs::PointCloud2 no_z = cloud;
  no_z.fields.pop_back();
  EXPECT_FALSE(cloudToPoints(no_z, &back, &why));
  sensor_msgs::PointCloud2 doubles = cloud;
  doubles.fields[0].datatype = sensor_msgs::PointField::FLOAT64;
  EXPECT_FALSE(cloudToPoints(doubles, &back, &why));

  // The true map of the cloud, around the scenario's start and goals.
  SimScenario scenario;
  scenario.start_m = Eigen::Vector3d(-3.0, 0.0, 1.0);
  scenario.goals_m = {{3.0, 0.0, 1.0}};
  std::shared_ptr<const TruthMap> map;
  ASSERT_TRUE(truthMapFromCloud(cloud, truthMapConfig(scenario), &map, &why)) << why;
  EXPECT_EQ(map->numOccupied(), 2u);
  EXPECT_TRUE(map->sphereInCollision(Eigen::Vector3d(0.05, 0.15, 0.35), 0.15));
  EXPECT_FALSE(map->sphereInCollision(Eigen::Vector3d(-3.0, 0.0, 1.0), 0.15));
  EXPECT_FALSE(truthMapFromCloud(truncated, truthMapConfig(scenario), &map, &why));
}

TEST(RosConversions, PositionCommandsWithNaNAreRefused) {
  topo_planner::PositionCommand msg;
  msg.position.x = 1.0;
  msg.velocity.y = 2.0;
  msg.yaw = 0.5;
  TrackingReference ref;
  ASSERT_TRUE(trackingReferenceFromMsg(msg, &ref));
  EXPECT_EQ(ref.position.x(), 1.0);
  EXPECT_EQ(ref.velocity.y(), 2.0);
  EXPECT_EQ(ref.yaw, 0.5);
  for (double* field : {&msg.jerk.z, &msg.yaw_rate, &msg.acceleration.x}) {
    const double saved = *field;
    *field = NAN;
    const topo_planner::PositionCommand bad = msg;
    *field = saved;
    TrackingReference untouched = ref;
    EXPECT_FALSE(trackingReferenceFromMsg(bad, &untouched));
    EXPECT_EQ(untouched.position, ref.position);
  }
}

}  // namespace
}  // namespace topo_planner
