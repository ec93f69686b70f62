#include "topo_planner/uav_sim/ros/depth_camera_server.h"

#include <geometry_msgs/PoseStamped.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>

#include "topo_planner/uav_sim/ros/conversions.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

namespace {
bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }

bool hostIsBigEndian() {
  const uint16_t probe = 1;
  uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}
}  // namespace

Eigen::Isometry3d DepthCameraServer::Config::defaultBodyToCamera() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // columns: optical x, y, z in the FLU body frame
  return T;
}

bool DepthCameraServer::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string core;
  if (!camera.camera.valid())
    err << "camera intrinsics must be finite, sizes and focal lengths positive; ";
  else if (int64_t(camera.camera.width) * camera.camera.height > 4096 * 4096)
    err << "camera image larger than 4096^2; ";
  if (!(std::isfinite(camera.min_range_m) && camera.min_range_m >= 0.0 && camera.max_range_m > camera.min_range_m &&
        camera.max_range_m <= 1000.0))
    err << "need 0 <= min_range_m < max_range_m <= 1000; ";
  if (!(std::isfinite(camera.noise_stddev_at_1m) && camera.noise_stddev_at_1m >= 0.0))
    err << "noise_stddev_at_1m must be >= 0; ";
  if (!(camera.invalid_fraction >= 0.0 && camera.invalid_fraction < 1.0)) err << "invalid_fraction must be in [0, 1); ";
  if (!scenario.validate(&core)) err << core << "; ";
  if (!(finitePositive(rate_hz) && rate_hz >= 0.01 && rate_hz <= 1000.0)) err << "rate_hz must be in [0.01, 1000]; ";
  if (!T_body_camera.matrix().allFinite()) err << "extrinsic must be finite; ";
  if (world_frame.empty() || camera_frame.empty()) err << "frame names must not be empty; ";
  if (!(finitePositive(max_odom_age_s) && max_odom_age_s <= 3600.0)) err << "max_odom_age_s must be in (0, 3600]; ";
  if (!(std::isfinite(truth_map_margin_m) && truth_map_margin_m >= 0.0 && truth_map_margin_m <= 100.0))
    err << "truth_map_margin_m must be in [0, 100]; ";
  if (!(finitePositive(truth_esdf_max_distance_m) && truth_esdf_max_distance_m <= 20.0))
    err << "truth_esdf_max_distance_m must be in (0, 20]; ";
  if (!finitePositive(status_period_s)) err << "status_period_s must be positive; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readDepthCameraParams(const ros::NodeHandle& pnh, DepthCameraServer::Config* config) {
  DepthCameraServer::Config& c = *config;
  ParamReader r(pnh);
  std::string scenario_error;
  if (!readSimScenario(&c.scenario, &scenario_error)) r.errors() << scenario_error << "; ";
  r.read("rate_hz", c.rate_hz);
  std::string encoding = c.encoding == DepthCameraServer::Encoding::kFloat32 ? "32FC1" : "16UC1";
  r.read("encoding", encoding);
  if (encoding == "32FC1")
    c.encoding = DepthCameraServer::Encoding::kFloat32;
  else if (encoding == "16UC1")
    c.encoding = DepthCameraServer::Encoding::kUInt16;
  else
    r.errors() << "encoding must be 32FC1 or 16UC1, not '" << encoding << "'; ";
  std::string method = c.camera.method == DepthCamera::Method::kRasterize ? "rasterize" : "raycast";
  r.read("method", method);
  if (method == "rasterize")
    c.camera.method = DepthCamera::Method::kRasterize;
  else if (method == "raycast")
    c.camera.method = DepthCamera::Method::kRaycast;
  else
    r.errors() << "method must be rasterize or raycast, not '" << method << "'; ";
  PinholeCamera& k = c.camera.camera;
  r.read("camera/width", k.width);
  r.read("camera/height", k.height);
  r.read("camera/fx", k.fx);
  r.read("camera/fy", k.fy);
  r.read("camera/cx", k.cx);
  r.read("camera/cy", k.cy);
  r.read("min_range_m", c.camera.min_range_m);
  r.read("max_range_m", c.camera.max_range_m);
  r.read("noise_stddev_at_1m", c.camera.noise_stddev_at_1m);
  r.read("invalid_fraction", c.camera.invalid_fraction);
  r.read("render_from_truth", c.render_from_truth);
  r.readUnsigned("seed", c.camera.seed);
  r.readTransform("extrinsic", c.T_body_camera);
  r.read("world_frame", c.world_frame);
  r.read("camera_frame", c.camera_frame);
  r.read("max_odom_age_s", c.max_odom_age_s);
  r.read("truth_map_margin_m", c.truth_map_margin_m);
  r.read("truth_esdf_max_distance_m", c.truth_esdf_max_distance_m);
  r.read("status_period_s", c.status_period_s);
  std::string range;
  c.validate(&range);
  return r.finish("depth_camera", range);
}

DepthCameraServer::DepthCameraServer(const ros::NodeHandle& nh, const Config& config) : nh_(nh), config_(config) {}

DepthCameraServer::~DepthCameraServer() {
  if (render_spinner_) render_spinner_->stop();  // no render callback runs past this point
}

std::unique_ptr<DepthCameraServer> DepthCameraServer::create(const ros::NodeHandle& nh, const Config& config,
                                                             std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid config: " + why;
    return nullptr;
  }
  std::unique_ptr<DepthCameraServer> s(new DepthCameraServer(nh, config));
  s->image_pub_ = s->nh_.advertise<sensor_msgs::Image>("camera/depth/image_rect_raw", 2);
  s->info_pub_ = s->nh_.advertise<sensor_msgs::CameraInfo>("camera/depth/camera_info", 2);
  // Poses are small and a consumer pairs them with the images by stamp: a deeper queue than the
  // images' (a slow link drops the oldest; under ThreadSanitizer the pose of a delivered image was).
  s->pose_pub_ = s->nh_.advertise<geometry_msgs::PoseStamped>("camera/pose", 20);
  s->odom_sub_ =
      s->nh_.subscribe("odom", 1, &DepthCameraServer::odomCallback, s.get(), ros::TransportHints().tcpNoDelay());
  s->blackout_sub_ = s->nh_.subscribe("quadrotor_sim/depth_blackout", 10, &DepthCameraServer::blackoutCallback, s.get());
  s->offset_sub_ = s->nh_.subscribe("quadrotor_sim/odom_offset", 10, &DepthCameraServer::offsetCallback, s.get(),
                                    ros::TransportHints().tcpNoDelay());
  if (config.render_from_truth)
    s->truth_sub_ = s->nh_.subscribe("quadrotor_sim/ground_truth", 400, &DepthCameraServer::truthCallback, s.get(),
                                     ros::TransportHints().tcpNoDelay());
  // The render thread: the map build and the frames.
  ros::NodeHandle render_nh(s->nh_);
  render_nh.setCallbackQueue(&s->render_queue_);
  s->truth_ = std::make_unique<TruthMapSubscriber>(
      render_nh, "map_generator/global_cloud",
      truthMapConfig(config.scenario, config.truth_map_margin_m, config.truth_esdf_max_distance_m), "depth_camera");
  s->render_timer_ =
      render_nh.createTimer(ros::Duration(1.0 / config.rate_hz), &DepthCameraServer::renderCallback, s.get());
  s->period_start_wall_ = ros::WallTime::now();
  s->render_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &s->render_queue_);
  s->render_spinner_->start();
  const PinholeCamera& k = config.camera.camera;
  ROS_INFO("depth_camera: %d x %d, fx %.1f, range %.1f-%.1f m, %.0f Hz, %s, %s renderer", k.width, k.height, k.fx,
           config.camera.min_range_m, config.camera.max_range_m, config.rate_hz,
           config.encoding == Encoding::kFloat32 ? "32FC1" : "16UC1", DepthCamera::toString(config.camera.method));
  return s;
}

void DepthCameraServer::odomCallback(const nav_msgs::OdometryConstPtr& msg) {
  std::lock_guard<std::mutex> lock(odom_mutex_);
  latest_odom_ = msg;
}

void DepthCameraServer::truthCallback(const nav_msgs::OdometryConstPtr& msg) {
  std::lock_guard<std::mutex> lock(odom_mutex_);
  truth_poses_.push_back(msg);
  while (truth_poses_.size() > 1 && (msg->header.stamp - truth_poses_.front()->header.stamp).toSec() > 2.0)
    truth_poses_.pop_front();
}

void DepthCameraServer::blackoutCallback(const std_msgs::BoolConstPtr& msg) {
  std::lock_guard<std::mutex> lock(odom_mutex_);
  if (msg->data != blackout_)
    ROS_WARN("depth_camera: %s", msg->data ? "depth blackout (injected fault): no images until it ends"
                                           : "depth blackout over: images again");
  blackout_ = msg->data;
}

void DepthCameraServer::offsetCallback(const geometry_msgs::Vector3StampedConstPtr& msg) {
  const Eigen::Vector3d offset(msg->vector.x, msg->vector.y, msg->vector.z);
  if (!offset.allFinite()) return;
  std::lock_guard<std::mutex> lock(odom_mutex_);
  if (!offset.isApprox(odom_offset_))
    ROS_WARN("depth_camera: odometry offset (injected jump) now (%.2f %.2f %.2f) m: rendering from the true pose",
             offset.x(), offset.y(), offset.z());
  odom_offset_ = offset;
}

void DepthCameraServer::renderCallback(const ros::TimerEvent&) {
  const std::shared_ptr<const TruthMap> map = truth_->map();
  if (!map) {
    ROS_INFO_THROTTLE(5.0, "depth_camera: waiting for the true map on %s",
                      nh_.resolveName("map_generator/global_cloud").c_str());
    return;
  }
  if (map != camera_map_) {
    camera_ = std::make_unique<DepthCamera>(config_.camera, map->esdf());
    camera_map_ = map;
  }
  nav_msgs::OdometryConstPtr odom, truth;
  bool blackout;
  Eigen::Vector3d offset;
  {
    std::lock_guard<std::mutex> lock(odom_mutex_);
    odom = latest_odom_;
    blackout = blackout_;
    offset = odom_offset_;
    // The true pose at the estimate's stamp (the simulator publishes both from the same step).
    if (odom && config_.render_from_truth)
      for (auto it = truth_poses_.rbegin(); it != truth_poses_.rend(); ++it)
        if (std::abs(((*it)->header.stamp - odom->header.stamp).toSec()) < 1e-4) {
          truth = *it;
          break;
        }
  }
  if (!odom || odom->header.stamp == last_rendered_stamp_) return;  // nothing new to see
  if (blackout) {
    ++blackout_frames_;
    last_rendered_stamp_ = odom->header.stamp;
    return;
  }
  const ros::Time now = ros::Time::now();
  if ((now - odom->header.stamp).toSec() > config_.max_odom_age_s) {
    ROS_WARN_THROTTLE(5.0, "depth_camera: the latest odometry is %.2f s old: no frame",
                      (now - odom->header.stamp).toSec());
    return;
  }
  Quadrotor::State body;
  std::string why;
  if (!odometryToState(*odom, false, &body, &why)) {
    ROS_WARN_THROTTLE(1.0, "depth_camera: refusing odometry: %s", why.c_str());
    last_rendered_stamp_ = odom->header.stamp;
    return;
  }
  Eigen::Isometry3d T_world_body = Eigen::Isometry3d::Identity();
  T_world_body.linear() = body.orientation.toRotationMatrix();
  T_world_body.translation() = body.position;
  const Eigen::Isometry3d T_world_camera = T_world_body * config_.T_body_camera;  // as the estimator says
  Eigen::Isometry3d T_true_body = T_world_body;  // where the camera really is (odometry jumps removed)
  T_true_body.translation() -= offset;
  if (config_.render_from_truth) {
    // Noise and drift of the estimate are not where the camera is: render from the true pose, send
    // the estimate's (what a VIO gives the mapping).
    Quadrotor::State true_body;
    if (!truth || !odometryToState(*truth, false, &true_body, &why)) {
      ROS_WARN_THROTTLE(5.0, "depth_camera: no true pose at the odometry's stamp: no frame");
      return;
    }
    T_true_body.linear() = true_body.orientation.toRotationMatrix();
    T_true_body.translation() = true_body.position;
  }

  const auto t0 = std::chrono::steady_clock::now();
  if (!camera_->render(T_true_body * config_.T_body_camera, &depth_)) return;
  const double render_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  last_rendered_stamp_ = odom->header.stamp;

  const PinholeCamera& k = config_.camera.camera;
  sensor_msgs::Image image;
  image.header.stamp = odom->header.stamp;
  image.header.frame_id = config_.camera_frame;
  image.width = uint32_t(k.width);
  image.height = uint32_t(k.height);
  image.is_bigendian = hostIsBigEndian();
  if (config_.encoding == Encoding::kFloat32) {
    image.encoding = sensor_msgs::image_encodings::TYPE_32FC1;
    image.step = image.width * 4;
    image.data.resize(depth_.size() * 4);
    std::memcpy(image.data.data(), depth_.data(), image.data.size());
  } else {
    DepthCamera::toMillimetres(depth_, &depth_mm_);
    image.encoding = sensor_msgs::image_encodings::TYPE_16UC1;
    image.step = image.width * 2;
    image.data.resize(depth_mm_.size() * 2);
    std::memcpy(image.data.data(), depth_mm_.data(), image.data.size());
  }

  sensor_msgs::CameraInfo info;
  info.header = image.header;
  info.width = image.width;
  info.height = image.height;
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  info.K = {k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0};
  info.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  info.P = {k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0};

  geometry_msgs::PoseStamped pose;
  pose.header.stamp = image.header.stamp;
  pose.header.frame_id = config_.world_frame;
  const Eigen::Quaterniond q(T_world_camera.linear());
  pose.pose.position.x = T_world_camera.translation().x();
  pose.pose.position.y = T_world_camera.translation().y();
  pose.pose.position.z = T_world_camera.translation().z();
  pose.pose.orientation.w = q.w();
  pose.pose.orientation.x = q.x();
  pose.pose.orientation.y = q.y();
  pose.pose.orientation.z = q.z();

  // The pose first: a consumer pairing them by stamp has it when the image arrives.
  pose_pub_.publish(pose);
  info_pub_.publish(info);
  image_pub_.publish(image);

  ++frames_;
  ++period_frames_;
  period_render_ms_ += render_ms;
  period_max_render_ms_ = std::max(period_max_render_ms_, render_ms);
  const ros::WallTime wall = ros::WallTime::now();
  if (period_start_.isZero()) period_start_ = now;
  const double wall_s = (wall - period_start_wall_).toSec();
  if (wall_s >= config_.status_period_s) {
    const double ros_s = (now - period_start_).toSec();
    const double rate = ros_s > 0.0 ? period_frames_ / ros_s : 0.0;
    const double mean_ms = period_render_ms_ / period_frames_;
    ROS_INFO("depth_camera: %lu frames, %.1f Hz (asked %.1f), render %.1f ms mean, %.1f ms max, %lu withheld "
             "(depth blackout)",
             (unsigned long)frames_, rate, config_.rate_hz, mean_ms, period_max_render_ms_,
             (unsigned long)blackout_frames_);
    // A blackout in the period explains a low rate (a clock step may also show as one).
    if (rate < 0.9 * config_.rate_hz && blackout_frames_ == period_blackout_start_)
      ROS_WARN(
          "depth_camera: publishing %.1f Hz of the %.1f Hz asked: a frame takes %.0f ms to render; ticks that "
          "find the renderer busy are skipped, not queued",
          rate, config_.rate_hz, mean_ms);
    period_start_wall_ = wall;
    period_start_ = now;
    period_frames_ = 0;
    period_blackout_start_ = blackout_frames_;
    period_render_ms_ = period_max_render_ms_ = 0.0;
  }
}

}  // namespace topo_planner
