// Rostest of the mapping node's wiring (mapping_node.test starts one node per case).
//
// Scene: a camera at (0, 0, 1) looking along world +x at the face of a box, the rectangle
// x = 3.05, |y| <= 1, 0.5 <= z <= 1.5; the depth image is rendered here. With 0.1 m voxels the
// face lies in the voxel layer x index 30 (centres x = 3.05), so the published occupancy must hold
// the face's voxel centres there and nothing in the free space in front (x < 3.0). The node
// needs two hits per voxel (prob_hit 0.7, prob_occupied 0.8), so frames are sent repeatedly.
//
// Cases: 32FC1 depth + PoseStamped (with the inflated cloud and the ESDF slice checked), 16UC1 in
// both byte orders, bad input first (NaN/inf/non-unit poses, wrong frame, wrong size, oversized,
// wrong encoding, empty, truncated, overflowing stamps: none may reach the map or stop the node),
// Odometry + extrinsic, a world-frame PointCloud2, and a window that follows the vehicle.
//
// Waiting is bounded by iteration counts (kMaxIterations x kStep, generous); the node runs its
// publish timers at 5 Hz, so a passing case takes about a second.

#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <Eigen/Geometry>
#include <algorithm>
#include "../../test/wall_scale.h"

#include <cmath>
#include <cstring>
#include <functional>
#include <iostream>
#include <limits>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace {

constexpr double kResolution = 0.1;
constexpr double kFaceX = 3.05;
constexpr double kFaceYMax = 1.0;
constexpr double kFaceZMin = 0.5, kFaceZMax = 1.5;
constexpr int kFaceXIndex = 30;
constexpr int kMaxIterations = 400;  // x kStep = 20 s, far above the ~1 s a pass takes
const ros::WallDuration kStep(0.05);

// Camera of the test nodes (mapping_node.test sets the same values).
constexpr int kWidth = 160, kHeight = 120;
constexpr double kFx = 100.0, kFy = 100.0, kCx = 79.5, kCy = 59.5;

using Index = std::tuple<int, int, int>;

Index indexOf(double x, double y, double z) {
  return Index(int(std::floor(x / kResolution)), int(std::floor(y / kResolution)), int(std::floor(z / kResolution)));
}

// Rotation world <- camera optical frame of a camera looking along world +x (optical z = x,
// optical x = -y, optical y = -z), as quaternion x, y, z, w.
const Eigen::Quaterniond kLookAlongX(0.5, -0.5, 0.5, -0.5);  // (w, x, y, z)

enum class Encoding { kFloat32, kUInt16 };

// Depth image of a wall x = wall_x seen from camera_position: depth along the optical axis is
// wall_x - camera x; pixels whose ray misses the face get "no return" (+inf / 0). With
// full_wall every pixel sees the wall (for decoys).
sensor_msgs::Image renderDepth(Encoding encoding, const Eigen::Vector3d& camera_position, double wall_x,
                               bool full_wall, bool big_endian = false, int width = kWidth, int height = kHeight) {
  sensor_msgs::Image img;
  img.width = uint32_t(width);
  img.height = uint32_t(height);
  img.encoding = encoding == Encoding::kFloat32 ? "32FC1" : "16UC1";
  const int bpp = encoding == Encoding::kFloat32 ? 4 : 2;
  img.step = uint32_t(width * bpp);
  img.is_bigendian = big_endian;
  img.data.resize(size_t(img.step) * height);
  const double depth = wall_x - camera_position.x();
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const double y = camera_position.y() - depth * (u - kCx) / kFx;
      const double z = camera_position.z() - depth * (v - kCy) / kFy;
      const bool hit = full_wall || (std::abs(y) <= kFaceYMax && z >= kFaceZMin && z <= kFaceZMax);
      uint8_t bytes[4];
      if (encoding == Encoding::kFloat32) {
        const float d = hit ? float(depth) : std::numeric_limits<float>::infinity();
        std::memcpy(bytes, &d, 4);
      } else {
        const uint16_t d = hit ? uint16_t(std::lround(depth * 1000.0)) : 0;
        std::memcpy(bytes, &d, 2);
      }
      if (big_endian) std::reverse(bytes, bytes + bpp);  // the test hosts are little-endian
      std::memcpy(&img.data[size_t(v) * img.step + size_t(u) * bpp], bytes, size_t(bpp));
    }
  return img;
}

geometry_msgs::Pose makePose(const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
  geometry_msgs::Pose pose;
  pose.position.x = p.x();
  pose.position.y = p.y();
  pose.position.z = p.z();
  pose.orientation.x = q.x();
  pose.orientation.y = q.y();
  pose.orientation.z = q.z();
  pose.orientation.w = q.w();
  return pose;
}

std::vector<Eigen::Vector3d> readXyz(const sensor_msgs::PointCloud2& msg) {
  std::vector<Eigen::Vector3d> pts;
  if (msg.width * msg.height == 0) return pts;
  sensor_msgs::PointCloud2ConstIterator<float> x(msg, "x"), y(msg, "y"), z(msg, "z");
  for (; x != x.end(); ++x, ++y, ++z) pts.emplace_back(*x, *y, *z);
  return pts;
}

// Keeps the latest message of a PointCloud2 topic.
struct CloudWatcher {
  CloudWatcher(ros::NodeHandle& nh, const std::string& topic)
      : sub(nh.subscribe(topic, 5, &CloudWatcher::callback, this)) {}
  void callback(const sensor_msgs::PointCloud2ConstPtr& msg) {
    latest = msg;
    ++count;
  }
  ros::Subscriber sub;
  sensor_msgs::PointCloud2ConstPtr latest;
  int count = 0;
};

// What the published occupancy says about the scene.
struct WallCheck {
  int missing_face_voxels = 0;  // interior face voxels not occupied
  int voxels_in_front = 0;      // occupied voxels in the free space before the face
  int voxels_off_face = 0;      // occupied voxels not in the face's layer
  size_t total = 0;
};

WallCheck checkWall(const sensor_msgs::PointCloud2& msg, int face_x_index = kFaceXIndex) {
  WallCheck c;
  std::set<Index> occupied;
  for (const Eigen::Vector3d& p : readXyz(msg)) {
    const Index i = indexOf(p.x(), p.y(), p.z());
    occupied.insert(i);
    if (std::get<0>(i) < face_x_index) ++c.voxels_in_front;
    if (std::get<0>(i) != face_x_index) ++c.voxels_off_face;
  }
  c.total = occupied.size();
  // Interior of the face: one voxel in from its edges, where every frame hits every voxel.
  for (int iy = -9; iy <= 8; ++iy)
    for (int iz = 6; iz <= 13; ++iz) c.missing_face_voxels += !occupied.count(Index(face_x_index, iy, iz));
  return c;
}

bool wallComplete(const CloudWatcher& w, int face_x_index = kFaceXIndex) {
  return w.latest && checkWall(*w.latest, face_x_index).missing_face_voxels == 0;
}

// Spins until done() or the iteration budget runs out; step() is called once per iteration.
bool spinUntil(const std::function<bool()>& done, const std::function<void(int)>& step = nullptr) {
  for (int i = 0; i < kMaxIterations * topo_planner_test::wallScale(); ++i) {
    if (step) step(i);
    kStep.sleep();
    ros::spinOnce();
    if (done()) return true;
  }
  return false;
}

bool nodeAlive(const std::string& name) {
  std::vector<std::string> nodes;
  if (!ros::master::getNodes(nodes)) return false;
  return std::find(nodes.begin(), nodes.end(), name) != nodes.end();
}

// Publishers and watchers of one mapping node whose topics are remapped under /<ns>/.
class MappingNodeCase {
 public:
  explicit MappingNodeCase(const std::string& ns)
      : depth_pub_(nh_.advertise<sensor_msgs::Image>("/" + ns + "/depth", 100)),
        pose_pub_(nh_.advertise<geometry_msgs::PoseStamped>("/" + ns + "/camera_pose", 100)),
        odom_pub_(nh_.advertise<nav_msgs::Odometry>("/" + ns + "/odometry", 100)),
        cloud_pub_(nh_.advertise<sensor_msgs::PointCloud2>("/" + ns + "/cloud", 100)),
        occupancy_(nh_, "/" + ns + "/occupancy"),
        inflated_(nh_, "/" + ns + "/occupancy_inflated"),
        slice_(nh_, "/" + ns + "/esdf_slice") {}

  /// Waits until the node subscribes to `input` and publishes the occupancy.
  bool connect(const ros::Publisher& input) {
    return spinUntil([&] { return input.getNumSubscribers() > 0 && occupancy_.sub.getNumPublishers() > 0; });
  }

  void sendDepthWithPose(const sensor_msgs::Image& image, const geometry_msgs::Pose& pose,
                         const std::string& frame = "world") {
    sendDepthWithPoseAt(image, pose, nextStamp(), frame);
  }

  void sendDepthWithPoseAt(const sensor_msgs::Image& image, const geometry_msgs::Pose& pose, const ros::Time& stamp,
                           const std::string& frame = "world") {
    sensor_msgs::Image img = image;
    img.header.stamp = stamp;
    img.header.frame_id = "camera_optical";
    geometry_msgs::PoseStamped ps;
    ps.header.stamp = stamp;
    ps.header.frame_id = frame;
    ps.pose = pose;
    pose_pub_.publish(ps);
    depth_pub_.publish(img);
  }

  void sendDepthWithOdometry(const sensor_msgs::Image& image, const geometry_msgs::Pose& body_pose) {
    const ros::Time stamp = nextStamp();
    sensor_msgs::Image img = image;
    img.header.stamp = stamp;
    nav_msgs::Odometry odom;
    odom.header.stamp = stamp;
    odom.header.frame_id = "world";
    odom.child_frame_id = "body";
    odom.pose.pose = body_pose;
    odom_pub_.publish(odom);
    depth_pub_.publish(img);
  }

  /// Pose of the sensor, then a world-frame cloud with the same stamp.
  void sendCloudWithPose(const std::vector<Eigen::Vector3d>& points, const geometry_msgs::Pose& pose) {
    const ros::Time stamp = nextStamp();
    geometry_msgs::PoseStamped ps;
    ps.header.stamp = stamp;
    ps.header.frame_id = "world";
    ps.pose = pose;
    pose_pub_.publish(ps);
    sensor_msgs::PointCloud2 cloud;
    cloud.header.stamp = stamp;
    cloud.header.frame_id = "world";
    sensor_msgs::PointCloud2Modifier mod(cloud);
    mod.setPointCloud2FieldsByString(1, "xyz");
    mod.resize(points.size());
    sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
    for (const Eigen::Vector3d& p : points) {
      *x = float(p.x()), *y = float(p.y()), *z = float(p.z());
      ++x, ++y, ++z;
    }
    cloud_pub_.publish(cloud);
  }

  ros::NodeHandle nh_;
  ros::Publisher depth_pub_, pose_pub_, odom_pub_, cloud_pub_;
  CloudWatcher occupancy_, inflated_, slice_;

 private:
  // Strictly increasing stamps, one per frame, so that ApproximateTime pairs exactly.
  ros::Time nextStamp() {
    ros::Time now = ros::Time::now();
    if (now <= last_stamp_) now = last_stamp_ + ros::Duration(0.001);
    last_stamp_ = now;
    return now;
  }
  ros::Time last_stamp_;
};

const Eigen::Vector3d kCameraPosition(0.0, 0.0, 1.0);

void expectWall(const CloudWatcher& w, int face_x_index = kFaceXIndex) {
  ASSERT_TRUE(w.latest);
  const WallCheck c = checkWall(*w.latest, face_x_index);
  EXPECT_EQ(c.missing_face_voxels, 0);
  EXPECT_EQ(c.voxels_in_front, 0) << "occupied voxels in the free space before the wall";
  EXPECT_EQ(c.voxels_off_face, 0) << "occupied voxels outside the wall's layer";
  EXPECT_GE(c.total, size_t(18 * 8));
}

// A depth image in the wrong place would show up as occupied voxels at x = 1.55 (in front).
sensor_msgs::Image decoy(Encoding e = Encoding::kFloat32, int width = kWidth, int height = kHeight) {
  return renderDepth(e, kCameraPosition, 1.55, true, false, width, height);
}

TEST(MappingNode, Float32DepthBuildsTheWallAndItsEsdf) {
  MappingNodeCase t("f32");
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.pose_pub_)) << "mapping_f32 did not come up";
  ASSERT_TRUE(spinUntil([&] { return t.inflated_.sub.getNumPublishers() > 0 && t.slice_.sub.getNumPublishers() > 0; }));
  const sensor_msgs::Image image = renderDepth(Encoding::kFloat32, kCameraPosition, kFaceX, false);
  const geometry_msgs::Pose pose = makePose(kCameraPosition, kLookAlongX);

  // Until the wall is there and both derived clouds have been published after it.
  int occupancy_seen = -1;
  auto inflated_has = [&](double x) {
    if (!t.inflated_.latest) return false;
    const Index want = indexOf(x, 0.05, 1.05);
    for (const Eigen::Vector3d& p : readXyz(*t.inflated_.latest))
      if (indexOf(p.x(), p.y(), p.z()) == want) return true;
    return false;
  };
  ASSERT_TRUE(spinUntil(
      [&] {
        if (occupancy_seen < 0 && wallComplete(t.occupancy_)) occupancy_seen = t.inflated_.count;
        return occupancy_seen >= 0 && t.inflated_.count > occupancy_seen + 1 && inflated_has(2.85);
      },
      [&](int) { t.sendDepthWithPose(image, pose); }))
      << "no complete wall in ~occupancy / inflated wall in ~occupancy_inflated";
  expectWall(t.occupancy_);

  // Inflation radius 0.2 m: the voxel two in front of the wall is inflated, three in front is not.
  EXPECT_TRUE(inflated_has(2.85));
  EXPECT_FALSE(inflated_has(2.75));

  // ESDF slice at z = 1.0 (voxel centres 1.05): 0.5 m in front of the wall's centre voxel.
  const int slice_count = t.slice_.count;
  ASSERT_TRUE(spinUntil([&] { return t.slice_.count > slice_count; }));
  const sensor_msgs::PointCloud2& slice = *t.slice_.latest;
  EXPECT_EQ(slice.header.frame_id, "world");
  sensor_msgs::PointCloud2ConstIterator<float> x(slice, "x"), y(slice, "y"), z(slice, "z"), d(slice, "intensity");
  bool found = false;
  size_t n = 0;
  for (; x != x.end(); ++x, ++y, ++z, ++d, ++n) {
    EXPECT_NEAR(*z, 1.05, 1e-4);
    if (indexOf(*x, *y, *z) == indexOf(2.55, 0.05, 1.05)) {
      found = true;
      EXPECT_NEAR(*d, 0.5, 1e-4);
    }
  }
  EXPECT_TRUE(found);
  EXPECT_EQ(n, size_t(100 * 100));  // the 10 m x 10 m window at 0.1 m
}

TEST(MappingNode, UInt16DepthInBothByteOrders) {
  MappingNodeCase t("u16");
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.pose_pub_)) << "mapping_u16 did not come up";
  const sensor_msgs::Image little = renderDepth(Encoding::kUInt16, kCameraPosition, kFaceX, false, false);
  const sensor_msgs::Image big = renderDepth(Encoding::kUInt16, kCameraPosition, kFaceX, false, true);
  const geometry_msgs::Pose pose = makePose(kCameraPosition, kLookAlongX);
  // Alternate byte orders: 3050 mm read with the wrong order is 59915 mm, which would break the wall.
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_); },
                        [&](int i) { t.sendDepthWithPose(i % 2 ? big : little, pose); }));
  // One more publication after a few more frames, to catch a late corruption.
  const int seen = t.occupancy_.count;
  ASSERT_TRUE(spinUntil([&] { return t.occupancy_.count > seen + 1; },
                        [&](int i) { t.sendDepthWithPose(i % 2 ? big : little, pose); }));
  expectWall(t.occupancy_);
}

TEST(MappingNode, BadInputIsRefusedAndTheNodeKeepsRunning) {
  MappingNodeCase t("bad");
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.pose_pub_)) << "mapping_bad did not come up";
  const geometry_msgs::Pose good_pose = makePose(kCameraPosition, kLookAlongX);
  const double nan = std::numeric_limits<double>::quiet_NaN();

  // Every one of these carries a decoy wall at x = 1.55 that must never reach the map. Paced and
  // queued generously so that no message is dropped (a dropped pose could pair a decoy image with
  // the pose of a neighbouring frame); the pace stretches with the wall scale, since a sanitizer's
  // node drains its queues that much slower (under TSan at 100 Hz, 8 of the 39 were counted).
  const ros::WallDuration pace(0.01 * topo_planner_test::wallScale());
  auto send = [&](const sensor_msgs::Image& image, const geometry_msgs::Pose& pose,
                  const std::string& frame = "world") {
    t.sendDepthWithPose(image, pose, frame);
    pace.sleep();
  };
  for (int round = 0; round < 3; ++round) {
    send(decoy(), makePose(Eigen::Vector3d(nan, 0, 1), kLookAlongX));  // NaN position
    geometry_msgs::Pose bad_q = good_pose;
    bad_q.orientation.w = nan;
    send(decoy(), bad_q);  // NaN orientation
    geometry_msgs::Pose zero_q = good_pose;
    zero_q.orientation.x = zero_q.orientation.y = zero_q.orientation.z = zero_q.orientation.w = 0.0;
    send(decoy(), zero_q);  // not a rotation
    geometry_msgs::Pose inf_p = good_pose;
    inf_p.position.x = std::numeric_limits<double>::infinity();
    send(decoy(), inf_p);
    send(decoy(), good_pose, "some_other_frame");                // pose in the wrong frame
    send(decoy(Encoding::kFloat32, kWidth / 2, kHeight / 2), good_pose);  // size != intrinsics
    send(decoy(Encoding::kFloat32, 200, 200), good_pose);        // over map/max_image_pixels
    sensor_msgs::Image wrong_encoding = decoy();
    wrong_encoding.encoding = "rgb8";
    send(wrong_encoding, good_pose);
    sensor_msgs::Image empty;
    empty.encoding = "32FC1";
    send(empty, good_pose);
    sensor_msgs::Image truncated = decoy();
    truncated.data.resize(truncated.data.size() / 2);
    send(truncated, good_pose);
    sensor_msgs::Image short_step = decoy();
    short_step.step = kWidth;  // a quarter of a 32FC1 row
    send(short_step, good_pose);
    sensor_msgs::Image mislabelled = decoy(Encoding::kUInt16);
    mislabelled.encoding = "32FC1";  // 2-byte pixels claimed as 4-byte: the data is too short
    send(mislabelled, good_pose);
  }
  // Stamps whose differences overflow ros::Duration (which throws inside ApproximateTime and used
  // to abort the node): unpaired, in 2106 and in 1970. NaN poses keep the decoys out regardless.
  {
    geometry_msgs::PoseStamped ps;
    ps.header.frame_id = "world";
    ps.pose = makePose(Eigen::Vector3d(nan, 0, 1), kLookAlongX);
    sensor_msgs::Image img = decoy();
    const uint32_t stamps[][2] = {{4294967295u, 1u}, {2u, 4294967294u}, {3u, 4u}, {4294967000u, 5u}};
    for (const auto& st : stamps) {
      img.header.stamp = ros::Time(st[0], 0);
      ps.header.stamp = ros::Time(st[1], 0);
      t.depth_pub_.publish(img);
      t.pose_pub_.publish(ps);
      pace.sleep();
    }
  }

  // Still publishing, and nothing was fused.
  const int seen = t.occupancy_.count;
  ASSERT_TRUE(spinUntil([&] { return t.occupancy_.count > seen + 1; })) << "mapping_bad stopped publishing";
  EXPECT_EQ(readXyz(*t.occupancy_.latest).size(), 0u) << "bad input reached the map";
  EXPECT_TRUE(nodeAlive("/mapping_bad"));

  // Good frames after all that build exactly the wall.
  const sensor_msgs::Image image = renderDepth(Encoding::kFloat32, kCameraPosition, kFaceX, false);
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_); },
                        [&](int) { t.sendDepthWithPose(image, good_pose); }));
  expectWall(t.occupancy_);
  EXPECT_TRUE(nodeAlive("/mapping_bad"));

  // /diagnostics counts what was refused and fused (plan_manage/health.h).
  ros::NodeHandle nh;
  diagnostic_msgs::DiagnosticStatus status;
  bool have_status = false;
  const ros::Subscriber diag_sub = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& msg) {
        for (const auto& st : msg->status)
          if (st.name.find("mapping_bad: mapping") != std::string::npos) status = st, have_status = true;
      });
  auto value = [&](const std::string& key) {
    for (const auto& kv : status.values)
      if (kv.key == key) return kv.value;
    return std::string();
  };
  ASSERT_TRUE(spinUntil([&] { return have_status && value("depth frames fused") != "0"; })) << "no mapping status on /diagnostics";
  EXPECT_EQ(status.hardware_id, "topo_planner");
  EXPECT_GT(std::stoi(value("depth frames refused")), 10) << status.message;
  std::cout << "[ bad input ] depth frames refused: " << value("depth frames refused") << ", fused: "
            << value("depth frames fused") << std::endl;
  EXPECT_GT(std::stoi(value("depth frames fused")), 0);
  EXPECT_FALSE(value("fusion rate [Hz]").empty());
}

TEST(MappingNode, OdometryWithExtrinsic) {
  MappingNodeCase t("odom");
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.odom_pub_)) << "mapping_odom did not come up";
  // Body at (0, 0, 1), level, facing +x; the node's extrinsic puts the optical frame 0.1 m ahead,
  // looking along body +x. Without the extrinsic's rotation the wall would appear overhead.
  const Eigen::Vector3d body(0.0, 0.0, 1.0);
  const Eigen::Vector3d camera = body + Eigen::Vector3d(0.1, 0.0, 0.0);
  const geometry_msgs::Pose body_pose = makePose(body, Eigen::Quaterniond::Identity());
  const double nan = std::numeric_limits<double>::quiet_NaN();

  for (int round = 0; round < 3; ++round) {
    geometry_msgs::Pose bad = body_pose;
    bad.position.z = nan;
    t.sendDepthWithOdometry(decoy(), bad);
    bad = body_pose;
    bad.orientation.z = nan;
    t.sendDepthWithOdometry(decoy(), bad);
    kStep.sleep();
  }
  const sensor_msgs::Image image = renderDepth(Encoding::kFloat32, camera, kFaceX, false);
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_); },
                        [&](int) { t.sendDepthWithOdometry(image, body_pose); }));
  expectWall(t.occupancy_);
}

TEST(MappingNode, PointCloudWithOriginFromPose) {
  MappingNodeCase t("cloud");
  ASSERT_TRUE(t.connect(t.cloud_pub_) && t.connect(t.pose_pub_)) << "mapping_cloud did not come up";
  // Points every 5 cm on the face, plus a NaN point the core must skip.
  std::vector<Eigen::Vector3d> points;
  for (double y = -0.975; y < kFaceYMax; y += 0.05)
    for (double z = kFaceZMin + 0.025; z < kFaceZMax; z += 0.05) points.emplace_back(kFaceX, y, z);
  points.emplace_back(std::numeric_limits<double>::quiet_NaN(), 0.0, 1.0);
  const geometry_msgs::Pose pose = makePose(kCameraPosition, kLookAlongX);
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_); },
                        [&](int) { t.sendCloudWithPose(points, pose); }));
  expectWall(t.occupancy_);
}

TEST(MappingNode, WindowFollowsTheVehicle) {
  MappingNodeCase t("recenter");
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.pose_pub_)) << "mapping_recenter did not come up";
  // The window starts at x in [-5, 5). A camera at x = 3 is beyond recenter_threshold_m = 1 from
  // its centre, so the window moves to x in [-2, 8) and a wall at x = 6.05 (3.05 m ahead, outside
  // the initial window) is mapped.
  const Eigen::Vector3d camera(3.0, 0.0, 1.0);
  const double wall_x = 6.05;
  const int wall_index = 60;
  const sensor_msgs::Image image = renderDepth(Encoding::kFloat32, camera, wall_x, false);
  const geometry_msgs::Pose pose = makePose(camera, kLookAlongX);
  // A finite but absurd position must neither move the window nor overflow its indices.
  t.sendDepthWithPose(decoy(), makePose(Eigen::Vector3d(1e12, 0.0, 1.0), kLookAlongX));
  ros::WallDuration(0.01).sleep();
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_, wall_index); },
                        [&](int) { t.sendDepthWithPose(image, pose); }));
  expectWall(t.occupancy_, wall_index);
  for (const Eigen::Vector3d& p : readXyz(*t.occupancy_.latest)) EXPECT_GE(p.x(), -2.0);
}

// The intrinsics come from camera_info (the node's parameters say fx = fy = 200: with them the
// wall would be mapped half as wide, its edges missing). An unusable camera_info is ignored.
TEST(MappingNode, IntrinsicsFromCameraInfo) {
  MappingNodeCase t("info");
  ros::Publisher info_pub = t.nh_.advertise<sensor_msgs::CameraInfo>("/info/camera_info", 10, true);
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.pose_pub_)) << "mapping_info did not come up";
  sensor_msgs::CameraInfo bad;
  bad.width = kWidth, bad.height = kHeight;
  bad.K = {std::nan(""), 0, kCx, 0, kFy, kCy, 0, 0, 1};
  info_pub.publish(bad);
  ros::WallDuration(0.2).sleep();
  sensor_msgs::CameraInfo info;
  info.header.frame_id = "camera_optical";
  info.width = kWidth, info.height = kHeight;
  info.K = {kFx, 0, kCx, 0, kFy, kCy, 0, 0, 1};
  info_pub.publish(info);
  ASSERT_TRUE(spinUntil([&] { return info_pub.getNumSubscribers() > 0; }));
  ros::WallDuration(0.3).sleep();  // the latched info reaches the node before the first frame
  const geometry_msgs::Pose pose = makePose(kCameraPosition, kLookAlongX);
  const sensor_msgs::Image image = renderDepth(Encoding::kFloat32, kCameraPosition, kFaceX, false);
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_); }, [&](int) { t.sendDepthWithPose(image, pose); }))
      << "the wall was not mapped with the camera_info intrinsics";
  expectWall(t.occupancy_);
}

// The camera extrinsic comes from tf, base_link -> the image's frame (the node's parameters give
// no rotation: with them the wall would appear overhead).
TEST(MappingNode, ExtrinsicFromTf) {
  MappingNodeCase t("tf");
  ASSERT_TRUE(t.connect(t.depth_pub_) && t.connect(t.odom_pub_)) << "mapping_tf did not come up";
  tf2_ros::StaticTransformBroadcaster broadcaster;
  geometry_msgs::TransformStamped body_camera;
  body_camera.header.stamp = ros::Time::now();
  body_camera.header.frame_id = "base_link";
  body_camera.child_frame_id = "tf_camera_optical";
  body_camera.transform.translation.x = 0.1;
  body_camera.transform.rotation.x = -0.5, body_camera.transform.rotation.y = 0.5;
  body_camera.transform.rotation.z = -0.5, body_camera.transform.rotation.w = 0.5;
  broadcaster.sendTransform(body_camera);
  const Eigen::Vector3d body(0.0, 0.0, 1.0), camera = body + Eigen::Vector3d(0.1, 0.0, 0.0);
  sensor_msgs::Image image = renderDepth(Encoding::kFloat32, camera, kFaceX, false);
  image.header.frame_id = "tf_camera_optical";
  const geometry_msgs::Pose body_pose = makePose(body, Eigen::Quaterniond::Identity());
  ASSERT_TRUE(spinUntil([&] { return wallComplete(t.occupancy_); }, [&](int) { t.sendDepthWithOdometry(image, body_pose); }))
      << "the wall was not mapped with the tf extrinsic";
  expectWall(t.occupancy_);
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_mapping_node");
  ros::NodeHandle nh;  // keeps the node up across the cases
  return RUN_ALL_TESTS();
}
