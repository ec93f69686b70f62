// Rostest of hostile_traffic.test: malformed and out-of-range messages on every topic the planner,
// its mapping and the trajectory server subscribe to, at a high rate, while the vehicle flies a
// mission in simulated time (fault_flight.launch).
//
// Every message sent here is one the nodes must refuse: non-finite values, sizes over their limits
// or not matching their own layout, wrong encodings and frames, stamps far in the past or the
// future. (A well-formed message with a current stamp cannot be told from the real one: ROS 1 has no
// authentication; docs/security.md.) The depth images and point clouds sent would draw a wall in
// front of the vehicle if they were fused. Checks, once the flight monitor reports:
//   - the flight succeeded: every goal reached, no collision, no setpoint jump, no planner restart;
//   - no node died (the nodes of the closed loop are still registered with the master);
//   - the map is unchanged by the bad messages: every occupied voxel of the planner's map lies within
//     0.3 m of the true map's obstacles (no phantom wall), and the mapping counted refused frames;
//   - the nodes' warnings are throttled: per node and message kind at most about one a second on
//     /rosout while thousands of bad messages arrive.
// The wall-clock limit guards against a hang only; the flight runs on the simulator's clock.

#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/master.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_msgs/String.h>
#include <topo_planner/Bspline.h>
#include <topo_planner/FlightResult.h>
#include <topo_planner/PlannerHeartbeat.h>
#include <topo_planner/PositionCommand.h>

#include "../../test/wall_scale.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Stamps no node may take: far in the past, an hour ahead, zero.
ros::Time badStamp(const ros::Time& now, int k) {
  switch (k % 3) {
    case 0: return ros::Time(1, 0);
    case 1: return now + ros::Duration(3600.0);
    default: return ros::Time(0, 0);
  }
}

template <typename T>
void fillBytes(std::vector<uint8_t>* data, size_t count, T value) {
  data->resize(count * sizeof(T));
  for (size_t i = 0; i < count; ++i) std::memcpy(data->data() + i * sizeof(T), &value, sizeof(T));
}

sensor_msgs::PointCloud2 cloudOf(const std::vector<std::array<float, 3>>& points, const ros::Time& stamp,
                                 const std::string& frame) {
  sensor_msgs::PointCloud2 c;
  c.header.stamp = stamp;
  c.header.frame_id = frame;
  sensor_msgs::PointCloud2Modifier mod(c);
  mod.setPointCloud2FieldsByString(1, "xyz");
  mod.resize(points.size());
  sensor_msgs::PointCloud2Iterator<float> x(c, "x"), y(c, "y"), z(c, "z");
  for (const auto& p : points) {
    *x = p[0], *y = p[1], *z = p[2];
    ++x, ++y, ++z;
  }
  return c;
}

class Hostile {
 public:
  explicit Hostile(ros::NodeHandle& nh) {
    odom_ = nh.advertise<nav_msgs::Odometry>("/odom", 10);
    depth_ = nh.advertise<sensor_msgs::Image>("/camera/depth/image_rect_raw", 2);
    info_ = nh.advertise<sensor_msgs::CameraInfo>("/camera/depth/camera_info", 2);
    pose_ = nh.advertise<geometry_msgs::PoseStamped>("/camera/pose", 10);
    cloud_ = nh.advertise<sensor_msgs::PointCloud2>("/planner/mapping/cloud", 2);
    goal_ = nh.advertise<geometry_msgs::PoseStamped>("/move_base_simple/goal", 10);
    waypoints_ = nh.advertise<nav_msgs::Path>("/planning/waypoints", 10);
    bspline_ = nh.advertise<topo_planner::Bspline>("/planning/bspline", 10);
    heartbeat_ = nh.advertise<topo_planner::PlannerHeartbeat>("/planning/heartbeat", 10);
    cmd_ = nh.advertise<topo_planner::PositionCommand>("/planning/position_cmd", 10);
    // A wall of points 1 m ahead of the start, 2 m wide and 1 m high.
    for (int i = -10; i < 10; ++i)
      for (int j = 5; j < 15; ++j) wall_.push_back({-14.0f, 0.1f * i, 0.1f * j});
  }

  int sent() const { return sent_; }
  int rounds() const { return round_; }

  void step() {
    const ros::Time now = ros::Time::now();
    const int k = round_++;
    publish(odom_, odometry(now, k));
    publish(depth_, depthImage(now, k));
    publish(info_, cameraInfo(now, k));
    publish(pose_, cameraPose(now, k));
    publish(cloud_, cloud(now, k));
    publish(goal_, goal(now, k));
    publish(waypoints_, waypoints(now, k));
    publish(bspline_, bspline(now, k));
    publish(heartbeat_, heartbeat(now, k));
    publish(cmd_, positionCmd(now, k));
    if (k % 40 == 39) publish(depth_, bigImage(now));
    if (k % 40 == 19) publish(waypoints_, manyWaypoints(now));
  }

 private:
  template <typename M>
  void publish(ros::Publisher& pub, const M& msg) {
    pub.publish(msg);
    ++sent_;
  }

  static void header(std_msgs::Header* h, const ros::Time& stamp, const std::string& frame = "world") {
    h->stamp = stamp;
    h->frame_id = frame;
  }

  nav_msgs::Odometry odometry(const ros::Time& now, int k) const {
    nav_msgs::Odometry m;
    header(&m.header, now);
    m.pose.pose.orientation.w = 1.0;
    m.pose.pose.position.x = -15.0, m.pose.pose.position.z = 1.0;
    switch (k % 4) {
      case 0: m.pose.pose.position.x = kNaN; break;
      case 1: m.twist.twist.linear.y = kInf; break;
      case 2: m.header.stamp = (k / 4) % 2 ? now + ros::Duration(3600.0) : ros::Time(0, 0); break;  // finite, stamped wrong
      default: m.pose.pose.orientation.w = kNaN; break;
    }
    return m;
  }

  // A wall 1 m in front of the camera, in a form the mapping must refuse.
  sensor_msgs::Image depthImage(const ros::Time& now, int k) const {
    sensor_msgs::Image m;
    header(&m.header, now, "camera_optical");
    m.height = 48, m.width = 64;
    switch (k % 8) {
      case 0:  // an encoding it does not read
        m.encoding = "rgb8", m.step = 64 * 3;
        m.data.assign(m.step * m.height, 0);
        break;
      case 1:  // data shorter than its rows
        m.encoding = "32FC1", m.step = 64 * 4;
        fillBytes(&m.data, 64 * 10, 1.0f);
        break;
      case 2:  // a row step shorter than a row
        m.encoding = "16UC1", m.step = 64;
        fillBytes(&m.data, 64 * 48, uint16_t(1000));
        break;
      case 3:  // absurd dimensions, little data
        m.encoding = "32FC1", m.height = m.width = 1u << 20, m.step = (1u << 20) * 4;
        fillBytes(&m.data, 16, 1.0f);
        break;
      case 4:  // another frame
        m.encoding = "32FC1", m.step = 64 * 4;
        fillBytes(&m.data, 64 * 48, 1.0f);
        m.header.frame_id = "hostile_frame";
        break;
      default:  // stamps far in the past, ahead, zero
        m.encoding = "16UC1", m.step = 64 * 2;
        fillBytes(&m.data, 64 * 48, uint16_t(1000));
        m.header.stamp = badStamp(now, k);
        break;
    }
    return m;
  }

  // Over map/max_image_pixels (16777216): 4100 x 4100.
  sensor_msgs::Image bigImage(const ros::Time& now) const {
    sensor_msgs::Image m;
    header(&m.header, now, "camera_optical");
    m.height = m.width = 4100;
    m.encoding = "16UC1", m.step = 4100 * 2;
    fillBytes(&m.data, size_t(4100) * 4100, uint16_t(1000));
    return m;
  }

  sensor_msgs::CameraInfo cameraInfo(const ros::Time& now, int k) const {
    sensor_msgs::CameraInfo m;
    header(&m.header, now, "camera_optical");
    m.height = 480, m.width = 640;
    m.K = {320.0, 0.0, 320.0, 0.0, 320.0, 240.0, 0.0, 0.0, 1.0};
    switch (k % 4) {
      case 0: m.K[0] = kNaN; break;
      case 1: m.K[0] = 0.0; break;
      case 2: m.binning_x = 4; break;
      default: m.width = 0; break;
    }
    return m;
  }

  geometry_msgs::PoseStamped cameraPose(const ros::Time& now, int k) const {
    geometry_msgs::PoseStamped m;
    header(&m.header, now);
    m.pose.position.x = -15.0, m.pose.position.z = 1.0;
    m.pose.orientation.w = 1.0;
    switch (k % 4) {
      case 0: m.pose.position.y = kNaN; break;
      case 1: m.pose.orientation.w = 0.0; break;  // not a rotation
      case 2: m.header.frame_id = "hostile_frame"; break;
      default: m.header.stamp = badStamp(now, k / 4); break;
    }
    return m;
  }

  sensor_msgs::PointCloud2 cloud(const ros::Time& now, int k) const {
    switch (k % 4) {
      case 0: return cloudOf(wall_, now, "hostile_frame");
      case 1: {
        const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
        return cloudOf(std::vector<std::array<float, 3>>(50, {nan, inf, 1.0f}), now, "world");
      }
      case 2: {  // a point step shorter than its fields
        sensor_msgs::PointCloud2 c = cloudOf(wall_, now, "world");
        c.point_step = 4;
        return c;
      }
      default: {  // more points declared than data, and more than cloud/max_points
        sensor_msgs::PointCloud2 c = cloudOf({wall_.begin(), wall_.begin() + 10}, now, "world");
        c.width = 1u << 24;
        c.row_step = c.width * c.point_step;
        return c;
      }
    }
  }

  geometry_msgs::PoseStamped goal(const ros::Time& now, int k) const {
    geometry_msgs::PoseStamped m;
    header(&m.header, now);
    m.pose.orientation.w = 1.0;
    switch (k % 3) {
      case 0: m.pose.position.x = kNaN; break;
      case 1: m.pose.position.x = 1e6, m.pose.position.z = 1.0; break;  // far out of the map
      default: m.header.frame_id = "hostile_frame", m.pose.position.x = 5.0; break;
    }
    return m;
  }

  nav_msgs::Path waypoints(const ros::Time& now, int k) const {
    nav_msgs::Path m;
    header(&m.header, now);
    geometry_msgs::PoseStamped p;
    p.pose.orientation.w = 1.0;
    switch (k % 3) {
      case 0:
        p.pose.position.x = kInf;
        m.poses.assign(3, p);
        break;
      case 1:
        p.pose.position.x = 1e6;  // out of the map
        m.poses.assign(3, p);
        break;
      default:  // a goal in another frame
        p.pose.position.x = 5.0, p.pose.position.z = 1.0;
        m.poses.assign(2, p);
        m.header.frame_id = "hostile_frame";
        break;
    }
    return m;
  }

  // Over the waypoint limit (kMaxWaypoints).
  nav_msgs::Path manyWaypoints(const ros::Time& now) const {
    nav_msgs::Path m;
    header(&m.header, now);
    geometry_msgs::PoseStamped p;
    p.pose.orientation.w = 1.0;
    p.pose.position.x = 5.0, p.pose.position.z = 1.0;
    m.poses.assign(100000, p);
    return m;
  }

  topo_planner::Bspline bspline(const ros::Time& now, int k) const {
    topo_planner::Bspline m;
    header(&m.header, now);
    m.planner_session = 12345;
    m.trajectory_id = 1000000 + k;
    m.start_time = now;
    m.order = 3;
    m.knot_span_s = 0.1;
    for (int i = 0; i < 10; ++i) {
      geometry_msgs::Point q;
      q.x = -15.0 + 0.1 * i, q.z = 1.0;
      m.control_points.push_back(q);
    }
    switch (k % 6) {
      case 0: m.control_points[3].x = kNaN; break;
      case 1: m.knot_span_s = -0.1; break;
      case 2: m.order = 40; break;
      case 3: m.control_points.resize(2); break;
      case 4: m.header.frame_id = "hostile_frame"; break;
      default: m.knot_span_s = kInf; break;
    }
    return m;
  }

  topo_planner::PlannerHeartbeat heartbeat(const ros::Time& now, int k) const {
    topo_planner::PlannerHeartbeat m;
    header(&m.header, badStamp(now, k), k % 2 ? "hostile_frame" : "world");
    m.planner_session = 999;
    m.fsm_state = "HOSTILE";
    m.inputs_ok = true;
    m.depth_age_s = kNaN;
    m.odom_age_s = -kInf;
    return m;
  }

  topo_planner::PositionCommand positionCmd(const ros::Time& now, int k) const {
    topo_planner::PositionCommand m;
    header(&m.header, now);
    m.position.x = 5.0, m.position.z = 1.0;
    m.mode = topo_planner::PositionCommand::MODE_HOLD;
    switch (k % 4) {
      case 0: m.position.x = kNaN; break;
      case 1: m.header.stamp = now + ros::Duration(3600.0); break;  // an hour ahead
      case 2: m.header.frame_id = "hostile_frame"; break;
      default: m.velocity.y = kInf; break;
    }
    return m;
  }

  ros::Publisher odom_, depth_, info_, pose_, cloud_, goal_, waypoints_, bspline_, heartbeat_, cmd_;
  std::vector<std::array<float, 3>> wall_;
  int round_ = 0, sent_ = 0;
};

using Voxel = std::tuple<int, int, int>;
Voxel voxelOf(float x, float y, float z) {
  return Voxel(int(std::floor(x / 0.1)), int(std::floor(y / 0.1)), int(std::floor(z / 0.1)));
}
std::vector<Voxel> voxelsOf(const sensor_msgs::PointCloud2& c) {
  std::vector<Voxel> out;
  for (sensor_msgs::PointCloud2ConstIterator<float> x(c, "x"), y(c, "y"), z(c, "z"); x != x.end(); ++x, ++y, ++z)
    if (std::isfinite(*x) && std::isfinite(*y) && std::isfinite(*z)) out.push_back(voxelOf(*x, *y, *z));
  return out;
}

TEST(HostileTraffic, TheFlightGoesOnAndTheMapIsUnchanged) {
  ros::NodeHandle nh, pnh("~");
  double wall_timeout_s = 400.0, rate_hz = 20.0;
  pnh.param("wall_timeout_s", wall_timeout_s, wall_timeout_s);
  pnh.param("rate_hz", rate_hz, rate_hz);

  topo_planner::FlightResultConstPtr result;
  std::string report;
  sensor_msgs::PointCloud2ConstPtr truth, occupancy;
  int refused = -1;
  std::map<std::pair<std::string, std::string>, std::vector<double>> warnings;  // (node, kind) -> wall times
  ros::Subscriber result_sub = nh.subscribe<topo_planner::FlightResult>(
      "/flight_monitor/result", 1, [&](const topo_planner::FlightResultConstPtr& m) { result = m; });
  ros::Subscriber report_sub = nh.subscribe<std_msgs::String>(
      "/flight_monitor/report", 1, [&](const std_msgs::StringConstPtr& m) { report = m->data; });
  ros::Subscriber truth_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "/map_generator/global_cloud", 1, [&](const sensor_msgs::PointCloud2ConstPtr& m) { truth = m; });
  ros::Subscriber diag_sub = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 20, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
        for (const auto& st : m->status)
          if (st.name.size() >= 7 && st.name.compare(st.name.size() - 7, 7, "mapping") == 0)
            for (const auto& kv : st.values)
              if (kv.key == "depth frames refused") refused = std::stoi(kv.value);
      });
  int log_messages = 0;
  ros::Subscriber log_sub = nh.subscribe<rosgraph_msgs::Log>("/rosout", 5000, [&](const rosgraph_msgs::LogConstPtr& m) {
    ++log_messages;
    if (m->level < rosgraph_msgs::Log::WARN || m->name == ros::this_node::getName()) return;
    // The kind: the message up to its first number (what follows is the value of the moment).
    const size_t digit = m->msg.find_first_of("0123456789");
    warnings[{m->name, m->msg.substr(0, std::min<size_t>(digit, 60))}].push_back(ros::WallTime::now().toSec());
  });

  Hostile hostile(nh);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(wall_timeout_s);
  // The mission first (the monitor sends it 1 s of simulated time in), then the traffic.
  while (ros::ok() && ros::WallTime::now() < deadline && ros::Time::now().toSec() < 3.0) {
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  // rate_hz rounds per second of simulated time, so the load per simulated second (what the flight
  // sees) does not grow when every node runs slower (a loaded machine, the sanitizers).
  while (ros::ok() && ros::WallTime::now() < deadline && !result) {
    hostile.step();
    const ros::Time next = ros::Time::now() + ros::Duration(1.0 / rate_hz);
    do {
      ros::spinOnce();
      ros::WallDuration(0.002).sleep();
    } while (ros::ok() && ros::WallTime::now() < deadline && !result && ros::Time::now() < next);
  }
  ASSERT_TRUE(result != nullptr) << "no /flight_monitor/result within " << wall_timeout_s << " s of wall time";
  // The report comes on its own latched topic: a connection of its own, so it may arrive after the
  // result (ROS 1 orders messages within a topic only).
  while (ros::ok() && ros::WallTime::now() < deadline && report.empty()) {
    ros::spinOnce();
    ros::WallDuration(0.02).sleep();
  }
  ASSERT_FALSE(report.empty()) << "no /flight_monitor/report within " << wall_timeout_s << " s of wall time";
  ROS_INFO("hostile traffic: %d bad messages in %d rounds; flight %s: %u/%u goals, %u collisions", hostile.sent(),
           hostile.rounds(), result->success ? "success" : "FAILURE", result->goals_reached, result->goals_total,
           result->collisions);

  // No node died.
  std::vector<std::string> nodes;
  ASSERT_TRUE(ros::master::getNodes(nodes));
  for (const char* n : {"/planner", "/traj_server", "/quadrotor_sim", "/geometric_controller", "/depth_camera"})
    EXPECT_NE(std::find(nodes.begin(), nodes.end(), n), nodes.end()) << n << " is gone";

  // The flight.
  EXPECT_TRUE(result->success) << result->message;
  EXPECT_EQ(result->collisions, 0u);
  EXPECT_NE(report.find("\"setpoint_jumps\": 0,"), std::string::npos) << report.substr(0, 800);
  EXPECT_NE(report.find("\"planner_restarts\": 0,"), std::string::npos);

  // The map: no phantom obstacle where the refused images and clouds would have put one.
  ros::Subscriber occ_sub = nh.subscribe<sensor_msgs::PointCloud2>(
      "/planner/mapping/occupancy", 1, [&](const sensor_msgs::PointCloud2ConstPtr& m) { occupancy = m; });
  const ros::WallTime map_deadline = ros::WallTime::now() + ros::WallDuration(30.0 * topo_planner_test::wallScale());
  while (ros::ok() && ros::WallTime::now() < map_deadline && (!occupancy || !truth || refused < 0)) {
    ros::spinOnce();
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_TRUE(truth) << "no true map on /map_generator/global_cloud";
  ASSERT_TRUE(occupancy) << "no /planner/mapping/occupancy";
  std::set<Voxel> near;
  for (const Voxel& v : voxelsOf(*truth))
    for (int dx = -3; dx <= 3; ++dx)
      for (int dy = -3; dy <= 3; ++dy)
        for (int dz = -3; dz <= 3; ++dz)
          near.insert(Voxel(std::get<0>(v) + dx, std::get<1>(v) + dy, std::get<2>(v) + dz));
  const std::vector<Voxel> occupied = voxelsOf(*occupancy);
  int phantom = 0;
  for (const Voxel& v : occupied) phantom += !near.count(v);
  ROS_INFO("hostile traffic: %zu occupied voxels in the planner's map, %d farther than 0.3 m from the true "
           "obstacles; the mapping refused %d depth frames",
           occupied.size(), phantom, refused);
  EXPECT_GT(occupied.size(), 100u);
  EXPECT_EQ(phantom, 0);
  EXPECT_GT(refused, 0);

  // Throttled warnings: per node and kind, at most about one a second (a burst of three allowed).
  double worst_rate = 0.0;
  std::string worst;
  int total = 0;
  for (const auto& kv : warnings) {
    const auto& t = kv.second;
    total += int(t.size());
    if (t.size() <= 3) continue;
    const double rate = double(t.size() - 3) / std::max(1.0, t.back() - t.front());
    if (rate > worst_rate) worst_rate = rate, worst = kv.first.first + ": " + kv.first.second;
  }
  ROS_INFO("hostile traffic: %d log messages, %d warnings of %zu kinds; the most frequent %.2f/s (%s)", log_messages,
           total, warnings.size(), worst_rate, worst.c_str());
  EXPECT_GT(total, 0) << "no warning seen on /rosout: the nodes said nothing of thousands of bad messages?";
  EXPECT_LE(worst_rate, 1.2) << "unthrottled warnings: " << worst;
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_hostile_traffic");
  return RUN_ALL_TESTS();
}
