#include "topo_planner/uav_sim/ros/conversions.h"

#include <sensor_msgs/PointField.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace topo_planner {

namespace {
bool hostIsBigEndian() {
  const uint16_t probe = 1;
  uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}
}  // namespace

bool cloudToPoints(const sensor_msgs::PointCloud2& msg, std::vector<Eigen::Vector3d>* points, std::string* why) {
  points->clear();
  uint32_t offset[3];
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const auto it = std::find_if(msg.fields.begin(), msg.fields.end(),
                                 [&](const sensor_msgs::PointField& f) { return f.name == names[a]; });
    if (it == msg.fields.end() || it->datatype != sensor_msgs::PointField::FLOAT32 ||
        uint64_t(it->offset) + 4 > msg.point_step) {
      if (why) *why = "the cloud needs FLOAT32 x, y and z fields";
      return false;
    }
    offset[a] = it->offset;
  }
  if (bool(msg.is_bigendian) != hostIsBigEndian()) {
    if (why) *why = "the cloud's byte order differs from the host's";
    return false;
  }
  const uint64_t n = uint64_t(msg.width) * msg.height;
  if (n == 0) return true;
  const uint64_t row_bytes = uint64_t(msg.width) * msg.point_step;
  if (msg.row_step < row_bytes || uint64_t(msg.row_step) * (msg.height - 1) + row_bytes > msg.data.size()) {
    if (why) *why = "the cloud's data is shorter than its header says";
    return false;
  }
  points->reserve(n);
  for (uint64_t r = 0; r < msg.height; ++r)
    for (uint64_t c = 0; c < msg.width; ++c) {
      const uint8_t* pt = msg.data.data() + r * msg.row_step + c * msg.point_step;
      float xyz[3];
      for (int a = 0; a < 3; ++a) std::memcpy(&xyz[a], pt + offset[a], 4);
      points->emplace_back(xyz[0], xyz[1], xyz[2]);
    }
  return true;
}

void pointsToCloud(const std::vector<Eigen::Vector3d>& points, const std::string& frame_id, const ros::Time& stamp,
                   sensor_msgs::PointCloud2* msg) {
  msg->header.frame_id = frame_id;
  msg->header.stamp = stamp;
  sensor_msgs::PointCloud2Modifier modifier(*msg);
  modifier.setPointCloud2Fields(3, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32,
                                "z", 1, sensor_msgs::PointField::FLOAT32);
  modifier.resize(points.size());
  msg->height = 1;
  msg->width = uint32_t(points.size());
  msg->is_bigendian = hostIsBigEndian();
  msg->is_dense = true;
  if (points.empty()) return;  // the iterators index data[0]
  sensor_msgs::PointCloud2Iterator<float> x(*msg, "x"), y(*msg, "y"), z(*msg, "z");
  for (const Eigen::Vector3d& p : points) {
    *x = float(p.x());
    *y = float(p.y());
    *z = float(p.z());
    ++x, ++y, ++z;
  }
}

bool odometryToState(const nav_msgs::Odometry& msg, bool twist_in_world, Quadrotor::State* state, std::string* why) {
  const auto& p = msg.pose.pose.position;
  const auto& o = msg.pose.pose.orientation;
  const auto& v = msg.twist.twist.linear;
  const auto& w = msg.twist.twist.angular;
  Quadrotor::State s;
  s.position = Eigen::Vector3d(p.x, p.y, p.z);
  Eigen::Quaterniond q(o.w, o.x, o.y, o.z);
  const Eigen::Vector3d velocity(v.x, v.y, v.z), rates(w.x, w.y, w.z);
  if (!s.position.allFinite() || !q.coeffs().allFinite() || !velocity.allFinite() || !rates.allFinite()) {
    if (why) *why = "odometry with NaN/inf values";
    return false;
  }
  const double n = q.norm();
  if (std::abs(n - 1.0) > 1e-2) {
    if (why) *why = "odometry orientation is not a unit quaternion";
    return false;
  }
  q.coeffs() /= n;
  s.orientation = q;
  const Eigen::Matrix3d R = q.toRotationMatrix();
  s.velocity = twist_in_world ? velocity : Eigen::Vector3d(R * velocity);
  s.angular_velocity = twist_in_world ? Eigen::Vector3d(R.transpose() * rates) : rates;
  *state = s;
  return true;
}

void stateToOdometry(const Quadrotor::State& state, const ros::Time& stamp, const std::string& frame_id,
                     const std::string& child_frame_id, nav_msgs::Odometry* msg) {
  msg->header.stamp = stamp;
  msg->header.frame_id = frame_id;
  msg->child_frame_id = child_frame_id;
  auto& pose = msg->pose.pose;
  pose.position.x = state.position.x();
  pose.position.y = state.position.y();
  pose.position.z = state.position.z();
  pose.orientation.w = state.orientation.w();
  pose.orientation.x = state.orientation.x();
  pose.orientation.y = state.orientation.y();
  pose.orientation.z = state.orientation.z();
  const Eigen::Vector3d v_body = state.orientation.conjugate() * state.velocity;
  auto& twist = msg->twist.twist;
  twist.linear.x = v_body.x();
  twist.linear.y = v_body.y();
  twist.linear.z = v_body.z();
  twist.angular.x = state.angular_velocity.x();
  twist.angular.y = state.angular_velocity.y();
  twist.angular.z = state.angular_velocity.z();
}

bool trackingReferenceFromMsg(const topo_planner::PositionCommand& msg, TrackingReference* ref) {
  TrackingReference r;
  r.position = Eigen::Vector3d(msg.position.x, msg.position.y, msg.position.z);
  r.velocity = Eigen::Vector3d(msg.velocity.x, msg.velocity.y, msg.velocity.z);
  r.acceleration = Eigen::Vector3d(msg.acceleration.x, msg.acceleration.y, msg.acceleration.z);
  r.jerk = Eigen::Vector3d(msg.jerk.x, msg.jerk.y, msg.jerk.z);
  r.yaw = msg.yaw;
  r.yaw_rate = msg.yaw_rate;
  if (!r.position.allFinite() || !r.velocity.allFinite() || !r.acceleration.allFinite() || !r.jerk.allFinite() ||
      !std::isfinite(r.yaw) || !std::isfinite(r.yaw_rate))
    return false;
  *ref = r;
  return true;
}

double yawOf(const Eigen::Quaterniond& q) {
  const Eigen::Vector3d x = q * Eigen::Vector3d::UnitX();
  return std::atan2(x.y(), x.x());
}

}  // namespace topo_planner
