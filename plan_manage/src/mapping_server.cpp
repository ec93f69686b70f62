#include "topo_planner/plan_manage/mapping_server.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <sstream>
#include <utility>

#include "topo_planner/plan_env/map_io.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

bool isRigid(const Eigen::Isometry3d& T) {
  if (!T.matrix().allFinite()) return false;
  const Eigen::Matrix3d R = T.linear();
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-3 && R.determinant() > 0.0;
}

bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }
bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }

void readExtrinsic(ParamReader& r, Eigen::Isometry3d* T) {
  const std::string t_name = "extrinsic/translation_m", q_name = "extrinsic/quaternion_xyzw",
                    m_name = "extrinsic/matrix_row_major";
  const Eigen::Quaterniond q0(T->linear());
  std::vector<double> t{T->translation().x(), T->translation().y(), T->translation().z()};
  std::vector<double> q{q0.x(), q0.y(), q0.z(), q0.w()};
  std::vector<double> m;
  const bool has_tq = r.has(t_name) || r.has(q_name);
  r.read(t_name, t);
  r.read(q_name, q);
  r.read(m_name, m);
  if (!m.empty()) {
    if (has_tq) {
      r.errors() << "give the extrinsic either as " << m_name << " or as " << t_name << " + " << q_name
                 << ", not both; ";
      return;
    }
    if (m.size() != 16) {
      r.errors() << m_name << " must hold 16 numbers (4x4 row-major); ";
      return;
    }
    Eigen::Matrix4d M;
    for (int i = 0; i < 16; ++i) M(i / 4, i % 4) = m[size_t(i)];
    if (!M.allFinite() || (M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9) {
      r.errors() << m_name << " must be finite with last row 0 0 0 1; ";
      return;
    }
    T->matrix() = M;  // orthonormality is checked by Config::validate
    return;
  }
  if (t.size() != 3 || q.size() != 4) {
    r.errors() << t_name << " needs 3 and " << q_name << " 4 numbers; ";
    return;
  }
  Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
  const double n = quat.norm();
  if (!std::isfinite(n) || std::abs(n - 1.0) > 1e-2) {
    r.errors() << q_name << " must be a unit quaternion [x, y, z, w]; ";
    return;
  }
  quat.coeffs() /= n;
  T->setIdentity();
  T->linear() = quat.toRotationMatrix();
  T->translation() = Eigen::Vector3d(t[0], t[1], t[2]);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Configuration

Eigen::Isometry3d MappingServer::Config::defaultBodyToCamera() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  // Columns: the optical x, y, z axes in the FLU body frame.
  T.linear() << 0, 0, 1,
               -1, 0, 0,
                0, -1, 0;
  return T;
}

bool MappingServer::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string core;
  if (!occupancy.validate(&core)) err << "map: " << core << "; ";
  if (!esdf.validate(&core)) err << "esdf: " << core << "; ";
  if (!camera.valid()) {
    err << "camera: intrinsics must be finite, fx, fy, width and height positive; ";
  } else if (int64_t(camera.width) * camera.height > occupancy.max_image_pixels) {
    err << "camera: width * height exceeds map/max_image_pixels; ";
  }
  if (!finitePositive(depth_scales.uint16_m) || !finitePositive(depth_scales.float32_m))
    err << "camera/uint16_depth_scale_m must be positive; ";
  if (frame_id.empty()) err << "frame_id must not be empty; ";
  if (!isRigid(T_body_camera)) err << "extrinsic must be a finite rigid transform (orthonormal rotation); ";
  if (sync_queue_size < 1) err << "sync_queue_size must be >= 1; ";
  if (!(finiteNonNegative(sync_max_interval_s) && sync_max_interval_s <= 3600.0))
    err << "sync_max_interval_s must be in [0, 3600]; ";
  if (!cloud_sensor_origin_m.allFinite()) err << "cloud/sensor_origin_m must be finite; ";
  if (!finitePositive(cloud_max_pose_age_s)) err << "cloud/max_pose_age_s must be positive; ";
  if (cloud_max_points < 1) err << "cloud/max_points must be >= 1; ";
  const double half_window = 0.5 * std::min(occupancy.size_m.x(), occupancy.size_m.y());
  if (recenter_on_vehicle && !(finitePositive(recenter_threshold_m) && recenter_threshold_m < half_window))
    err << "recenter_threshold_m must be positive and below half the window's x/y size; ";
  // Rates and intervals become ros::Duration, which throws beyond 2^31 s: keep them sensible.
  auto rate_ok = [](double hz) { return hz == 0.0 || (std::isfinite(hz) && hz >= 1e-3 && hz <= 1e3); };
  if (!rate_ok(occupancy_publish_rate_hz)) err << "publish/occupancy_rate_hz must be 0 (off) or in [0.001, 1000]; ";
  if (!rate_ok(esdf_publish_rate_hz)) err << "publish/esdf_rate_hz must be 0 (off) or in [0.001, 1000]; ";
  if (!std::isfinite(esdf_slice_height_m)) err << "publish/esdf_slice_height_m must be finite; ";
  if (!finitePositive(status_period_s)) err << "status_period_s must be positive; ";
  if (!finitePositive(max_stamp_lead_s)) err << "max_stamp_lead_s must be positive; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readMappingParams(const ros::NodeHandle& nh, MappingServer::Config* config) {
  MappingServer::Config& c = *config;
  ParamReader r(nh);

  r.read("frame_id", c.frame_id);
  r.read("check_frame_id", c.check_frame_id);
  std::string pose_type = c.pose_type == MappingServer::PoseType::kPose ? "pose" : "odometry";
  r.read("pose_type", pose_type);
  if (pose_type == "pose") {
    c.pose_type = MappingServer::PoseType::kPose;
  } else if (pose_type == "odometry") {
    c.pose_type = MappingServer::PoseType::kOdometry;
  } else {
    r.errors() << "pose_type must be 'pose' or 'odometry', not '" << pose_type << "'; ";
  }
  r.read("sync_queue_size", c.sync_queue_size);
  r.read("sync_max_interval_s", c.sync_max_interval_s);
  r.read("map_file", c.map_file);
  r.read("recenter_on_vehicle", c.recenter_on_vehicle);
  r.read("recenter_threshold_m", c.recenter_threshold_m);

  OccupancyMap::Config& m = c.occupancy;
  r.read("map/resolution_m", m.resolution_m);
  r.readVector3("map/size_m", m.size_m);
  r.readVector3("map/origin_m", m.origin_m);
  r.read("map/prob_hit", m.prob_hit);
  r.read("map/prob_miss", m.prob_miss);
  r.read("map/prob_min", m.prob_min);
  r.read("map/prob_max", m.prob_max);
  r.read("map/prob_occupied", m.prob_occupied);
  r.read("map/min_ray_length_m", m.min_ray_length_m);
  r.read("map/max_ray_length_m", m.max_ray_length_m);
  r.read("map/depth_pixel_skip", m.depth_pixel_skip);
  r.read("map/max_image_pixels", m.max_image_pixels);
  r.read("map/merge_rays", m.merge_rays);
  r.read("map/project_free_space", m.project_free_space);
  r.read("map/max_memory_mb", m.max_memory_mb);

  EsdfMap::Config& e = c.esdf;
  r.read("esdf/max_distance_m", e.max_distance_m);
  r.read("esdf/inflate_radius_m", e.inflate_radius_m);
  r.read("esdf/unknown_as_occupied", e.unknown_as_occupied);
  r.read("esdf/num_threads", e.num_threads);

  PinholeCamera& cam = c.camera;
  r.read("camera/width", cam.width);
  r.read("camera/height", cam.height);
  r.read("camera/fx", cam.fx);
  r.read("camera/fy", cam.fy);
  r.read("camera/cx", cam.cx);
  r.read("camera/cy", cam.cy);
  r.read("camera/uint16_depth_scale_m", c.depth_scales.uint16_m);

  readExtrinsic(r, &c.T_body_camera);
  r.read("camera/from_camera_info", c.camera_info);
  r.read("body_frame_id", c.body_frame_id);

  r.read("cloud/origin_from_pose", c.cloud_origin_from_pose);
  r.readVector3("cloud/sensor_origin_m", c.cloud_sensor_origin_m);
  r.read("cloud/max_pose_age_s", c.cloud_max_pose_age_s);
  r.read("cloud/max_points", c.cloud_max_points);

  r.read("publish/occupancy_rate_hz", c.occupancy_publish_rate_hz);
  r.read("publish/esdf_rate_hz", c.esdf_publish_rate_hz);
  r.read("publish/esdf_slice_height_m", c.esdf_slice_height_m);
  r.read("status_period_s", c.status_period_s);
  r.read("max_stamp_lead_s", c.max_stamp_lead_s);

  // The type errors and the range errors are reported together (a field with the wrong type kept
  // its default, so the range check of the rest is still meaningful).
  std::string range_errors;
  c.validate(&range_errors);
  return r.finish("mapping", range_errors);
}

// ---------------------------------------------------------------------------------------------
// Construction

MappingServer::MappingServer(const ros::NodeHandle& nh, const Config& config)
    : nh_(nh), config_(config), camera_(config.camera), extrinsic_(config.T_body_camera) {}

std::unique_ptr<MappingServer> MappingServer::create(const ros::NodeHandle& nh, const Config& config,
                                                     std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid config: " + why;
    return nullptr;
  }
  std::unique_ptr<MappingServer> server(new MappingServer(nh, config));
  if (!server->buildMaps(error)) return nullptr;
  server->subscribeAndAdvertise();
  return server;
}

bool MappingServer::buildMaps(std::string* error) {
  std::string why;
  std::unique_ptr<OccupancyMap> occ = OccupancyMap::create(config_.occupancy, &why);
  if (!occ) {
    if (error) *error = why;
    return false;
  }
  occupancy_ = std::move(occ);
  esdf_ = EsdfMap::create(config_.esdf, occupancy_, &why);
  if (!esdf_) {
    if (error) *error = why;
    return false;
  }
  const GridGeometry& g = occupancy_->geometry();
  // In metres: the voxel index of a far height would not fit an int (params fuzz harness, 1.7e300 m).
  if (!(config_.esdf_slice_height_m >= g.windowMin().z() && config_.esdf_slice_height_m < g.windowMax().z())) {
    if (error) {
      std::ostringstream s;
      s << "publish/esdf_slice_height_m = " << config_.esdf_slice_height_m << " is outside the map's z range ["
        << g.windowMin().z() << ", " << g.windowMax().z() << ")";
      *error = s.str();
    }
    return false;
  }

  if (!config_.map_file.empty()) {
    MapFile file;
    const MapStatus status = readMapFile(config_.map_file, &file, &why);
    if (status != MapStatus::kSuccess) {
      if (error) *error = std::string("cannot load map_file: ") + toString(status) + ": " + why;
      return false;
    }
    const MapInsertStats ins = insertMapFile(file, occupancy_.get());
    ROS_INFO("mapping: loaded %s: %zu occupied and %zu free voxels", config_.map_file.c_str(), ins.occupied_voxels,
             ins.free_voxels);
    if (ins.clipped_cells > 0)
      ROS_WARN("mapping: %zu cells of %s lie outside the map window [%.2f %.2f %.2f] - [%.2f %.2f %.2f]",
               ins.clipped_cells, config_.map_file.c_str(), g.windowMin().x(), g.windowMin().y(), g.windowMin().z(),
               g.windowMax().x(), g.windowMax().y(), g.windowMax().z());
  }
  const auto t0 = std::chrono::steady_clock::now();
  esdf_->updateAll();
  stats_.last_esdf_ms = msSince(t0);
  ROS_INFO("mapping: %d x %d x %d voxels of %.3f m from [%.2f %.2f %.2f], full ESDF in %.1f ms", g.size().x(),
           g.size().y(), g.size().z(), g.resolution(), g.windowMin().x(), g.windowMin().y(), g.windowMin().z(),
           stats_.last_esdf_ms);
  return true;
}

void MappingServer::subscribeAndAdvertise() {
  const uint32_t q = uint32_t(config_.sync_queue_size);
  depth_sub_.subscribe(nh_, "depth", q);
  depth_guard_.connectInput(depth_sub_);
  if (config_.pose_type == PoseType::kPose) {
    pose_sub_.subscribe(nh_, "camera_pose", q);
    pose_guard_.connectInput(pose_sub_);
    ImagePoseSync policy(q);
    if (config_.sync_max_interval_s > 0.0) policy.setMaxIntervalDuration(ros::Duration(config_.sync_max_interval_s));
    // as_const: the Synchronizer(F0&, F1&, F2&) overload would otherwise take the policy as an input.
    pose_sync_ = std::make_unique<message_filters::Synchronizer<ImagePoseSync>>(std::as_const(policy), depth_guard_,
                                                                                 pose_guard_);
    pose_sync_->registerCallback(&MappingServer::depthPoseCallback, this);
    pose_guard_.registerCallback(&MappingServer::poseCallback, this);
  } else {
    odom_sub_.subscribe(nh_, "odometry", q);
    odom_guard_.connectInput(odom_sub_);
    ImageOdomSync policy(q);
    if (config_.sync_max_interval_s > 0.0) policy.setMaxIntervalDuration(ros::Duration(config_.sync_max_interval_s));
    odom_sync_ = std::make_unique<message_filters::Synchronizer<ImageOdomSync>>(std::as_const(policy), depth_guard_,
                                                                                 odom_guard_);
    odom_sync_->registerCallback(&MappingServer::depthOdomCallback, this);
    odom_guard_.registerCallback(&MappingServer::odomCallback, this);
  }
  cloud_sub_ = nh_.subscribe("cloud", q, &MappingServer::cloudCallback, this);
  if (config_.camera_info) camera_info_sub_ = nh_.subscribe("camera_info", 1, &MappingServer::cameraInfoCallback, this);
  if (config_.pose_type == PoseType::kOdometry && !config_.body_frame_id.empty()) {
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh_);
  }

  occupancy_pub_ = nh_.advertise<sensor_msgs::PointCloud2>("occupancy", 1);
  inflated_pub_ = nh_.advertise<sensor_msgs::PointCloud2>("occupancy_inflated", 1);
  esdf_slice_pub_ = nh_.advertise<sensor_msgs::PointCloud2>("esdf_slice", 1);
  fused_pub_ = nh_.advertise<std_msgs::Header>("depth_fused", 10);
  if (config_.occupancy_publish_rate_hz > 0.0)
    occupancy_timer_ = nh_.createTimer(ros::Duration(1.0 / config_.occupancy_publish_rate_hz),
                                       &MappingServer::publishOccupancy, this);
  if (config_.esdf_publish_rate_hz > 0.0)
    esdf_timer_ =
        nh_.createTimer(ros::Duration(1.0 / config_.esdf_publish_rate_hz), &MappingServer::publishEsdfSlice, this);
  ROS_INFO("mapping: depth on %s with the camera pose from %s, clouds on %s", depth_sub_.getTopic().c_str(),
           config_.pose_type == PoseType::kPose ? pose_sub_.getTopic().c_str() : odom_sub_.getTopic().c_str(),
           cloud_sub_.getTopic().c_str());
}

MappingServer::Stats MappingServer::stats() const {
  std::shared_lock<std::shared_mutex> lock(map_mutex_);
  Stats s = stats_;
  s.frames_refused = frames_refused_;
  std::lock_guard<std::mutex> pose_lock(pose_mutex_);
  if (have_pose_) {
    s.pose_stamp_s = latest_pose_stamp_.toSec();
    s.pose_arrival_s = latest_pose_arrival_s_;
  }
  return s;
}

HealthReport MappingServer::health(double now) {
  const Stats s = stats();
  MappingHealth::Inputs in;
  in.frames_fused = s.frames_fused;
  in.frames_refused = s.frames_refused;
  in.depth_stamp_s = s.depth_stamp_s;
  in.depth_arrival_s = s.depth_arrival_s;
  in.pose_arrival_s = s.pose_arrival_s;
  in.last_fusion_ms = s.last_fusion_ms;
  in.last_esdf_ms = s.last_esdf_ms;
  return health_.report(now, in);
}

void MappingServer::clearMap(const std::string& why) {
  {
    std::unique_lock<std::shared_mutex> lock(map_mutex_);
    occupancy_->clear();
    esdf_->updateAll();
  }
  ROS_WARN("mapping: map cleared: %s", why.c_str());
}

void MappingServer::readMaps(const std::function<void(const OccupancyMap&, const EsdfMap&)>& fn) const {
  std::shared_lock<std::shared_mutex> lock(map_mutex_);
  fn(*occupancy_, *esdf_);
}

// ---------------------------------------------------------------------------------------------
// Inputs

bool MappingServer::frameAccepted(const std::string& frame, const char* what) const {
  if (!config_.check_frame_id || frame.empty() || frame == config_.frame_id) return true;
  // Strip a leading '/' (tf1 style) before complaining.
  if (frame.size() == config_.frame_id.size() + 1 && frame[0] == '/' &&
      frame.compare(1, frame.npos, config_.frame_id) == 0)
    return true;
  ROS_WARN_THROTTLE(1.0, "mapping: %s in frame '%s', expected '%s' (frame_id); ignored", what, frame.c_str(),
                    config_.frame_id.c_str());
  return false;
}

bool MappingServer::cameraPoseOf(const std_msgs::Header& header, const geometry_msgs::Pose& pose, bool is_odometry,
                                 Eigen::Isometry3d* T_world_camera) const {
  const char* what = is_odometry ? "odometry" : "camera pose";
  if (!frameAccepted(header.frame_id, what)) return false;
  Eigen::Isometry3d T;
  const ConversionStatus status = poseToIsometry(pose, &T);
  if (status != ConversionStatus::kOk) {
    ROS_WARN_THROTTLE(1.0, "mapping: %s refused: %s", what, toString(status));
    return false;
  }
  if (is_odometry) {
    std::lock_guard<std::mutex> lock(camera_mutex_);
    *T_world_camera = T * extrinsic_;
  } else {
    *T_world_camera = T;
  }
  return true;
}

void MappingServer::cameraInfoCallback(const sensor_msgs::CameraInfoConstPtr& info) {
  PinholeCamera camera;
  const ConversionStatus status = cameraInfoToPinhole(*info, &camera);
  if (status != ConversionStatus::kOk) {
    ROS_WARN_THROTTLE(5.0, "mapping: camera info ignored: %s", toString(status));
    return;
  }
  std::lock_guard<std::mutex> lock(camera_mutex_);
  const bool changed = camera.width != camera_.width || camera.height != camera_.height || camera.fx != camera_.fx ||
                       camera.fy != camera_.fy || camera.cx != camera_.cx || camera.cy != camera_.cy;
  if (changed || !camera_from_info_)
    ROS_INFO("mapping: intrinsics from %s: %d x %d, fx %.2f fy %.2f cx %.2f cy %.2f", camera_info_sub_.getTopic().c_str(),
             camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy);
  camera_ = camera;
  camera_from_info_ = true;
}

void MappingServer::refreshExtrinsic(const std::string& camera_frame) {
  if (!tf_buffer_ || camera_frame.empty()) return;
  std::string error;
  try {
    const geometry_msgs::TransformStamped t =
        tf_buffer_->lookupTransform(config_.body_frame_id, camera_frame, ros::Time(0));
    geometry_msgs::Pose pose;
    pose.position.x = t.transform.translation.x;
    pose.position.y = t.transform.translation.y;
    pose.position.z = t.transform.translation.z;
    pose.orientation = t.transform.rotation;
    Eigen::Isometry3d T;
    if (poseToIsometry(pose, &T) == ConversionStatus::kOk) {
      std::lock_guard<std::mutex> lock(camera_mutex_);
      if (!extrinsic_from_tf_ || !T.isApprox(extrinsic_, 1e-9))
        ROS_INFO("mapping: camera extrinsic from tf %s -> %s: translation (%.3f, %.3f, %.3f) m", config_.body_frame_id.c_str(),
                 camera_frame.c_str(), T.translation().x(), T.translation().y(), T.translation().z());
      extrinsic_ = T;
      extrinsic_from_tf_ = true;
      return;
    }
    error = "not a rigid transform";
  } catch (const tf2::TransformException& e) {
    error = e.what();
  }
  std::lock_guard<std::mutex> lock(camera_mutex_);
  ROS_WARN_THROTTLE(5.0, "mapping: no tf %s -> %s (%s): the %s extrinsic is used", config_.body_frame_id.c_str(),
                    camera_frame.c_str(), error.c_str(), extrinsic_from_tf_ ? "last tf" : "parameters'");
}

void MappingServer::depthPoseCallback(const sensor_msgs::ImageConstPtr& image,
                                      const geometry_msgs::PoseStampedConstPtr& pose) {
  Eigen::Isometry3d T_world_camera;
  if (!cameraPoseOf(pose->header, pose->pose, false, &T_world_camera)) {
    ++frames_refused_;
    ROS_WARN_THROTTLE(1.0, "mapping: depth image not fused: %s", toString(MapStatus::kInvalidPose));
    return;
  }
  fuseDepth(*image, T_world_camera);
}

void MappingServer::depthOdomCallback(const sensor_msgs::ImageConstPtr& image, const nav_msgs::OdometryConstPtr& odom) {
  refreshExtrinsic(image->header.frame_id);
  Eigen::Isometry3d T_world_camera;
  if (!cameraPoseOf(odom->header, odom->pose.pose, true, &T_world_camera)) {
    ++frames_refused_;
    ROS_WARN_THROTTLE(1.0, "mapping: depth image not fused: %s", toString(MapStatus::kInvalidPose));
    return;
  }
  fuseDepth(*image, T_world_camera);
}

void MappingServer::poseCallback(const geometry_msgs::PoseStampedConstPtr& pose) {
  Eigen::Isometry3d T;
  if (!cameraPoseOf(pose->header, pose->pose, false, &T)) return;
  std::lock_guard<std::mutex> lock(pose_mutex_);
  have_pose_ = true;
  latest_pose_stamp_ = pose->header.stamp;
  latest_pose_arrival_s_ = ros::Time::now().toSec();
  latest_camera_position_ = T.translation();
}

void MappingServer::odomCallback(const nav_msgs::OdometryConstPtr& odom) {
  Eigen::Isometry3d T;
  if (!cameraPoseOf(odom->header, odom->pose.pose, true, &T)) return;
  std::lock_guard<std::mutex> lock(pose_mutex_);
  have_pose_ = true;
  latest_pose_stamp_ = odom->header.stamp;
  latest_pose_arrival_s_ = ros::Time::now().toSec();
  latest_camera_position_ = T.translation();
}

void MappingServer::fuseDepth(const sensor_msgs::Image& image, const Eigen::Isometry3d& T_world_camera) {
  std::vector<uint8_t> swapped;  // only used for images in the other byte order
  DepthImageView view;
  const ConversionStatus status = depthImageToView(image, config_.depth_scales, &swapped, &view);
  if (status != ConversionStatus::kOk) {
    ++frames_refused_;
    ROS_WARN_THROTTLE(1.0, "mapping: depth image refused: %s (encoding '%s', %u x %u, step %u, %zu bytes)",
                      toString(status), image.encoding.c_str(), image.width, image.height, image.step,
                      image.data.size());
    return;
  }
  PinholeCamera camera;
  {
    std::lock_guard<std::mutex> lock(camera_mutex_);
    camera = camera_;
  }
  integrate("depth image", image.header.stamp, T_world_camera.translation(), [&](OccupancyMap& map) {
    return map.fuseDepthImage(view, camera, T_world_camera);
  });
}

void MappingServer::cloudCallback(const sensor_msgs::PointCloud2ConstPtr& cloud) {
  if (!frameAccepted(cloud->header.frame_id, "point cloud")) {
    ++frames_refused_;
    return;
  }
  if (uint64_t(cloud->width) * cloud->height > uint64_t(config_.cloud_max_points)) {
    ++frames_refused_;
    ROS_WARN_THROTTLE(1.0, "mapping: point cloud of %u x %u points refused (cloud/max_points = %d)", cloud->width,
                      cloud->height, config_.cloud_max_points);
    return;
  }
  Eigen::Vector3d origin = config_.cloud_sensor_origin_m;
  if (config_.cloud_origin_from_pose) {
    bool have_pose;
    double age_s;
    {
      std::lock_guard<std::mutex> lock(pose_mutex_);
      have_pose = have_pose_;
      age_s = std::abs(cloud->header.stamp.toSec() - latest_pose_stamp_.toSec());  // no ros::Duration: it throws
      origin = latest_camera_position_;
    }
    if (!have_pose) {
      ++frames_refused_;
      ROS_WARN_THROTTLE(1.0, "mapping: point cloud ignored: no valid pose received yet (sensor origin unknown)");
      return;
    }
    if (age_s > config_.cloud_max_pose_age_s) {
      ++frames_refused_;
      ROS_WARN_THROTTLE(1.0,
                        "mapping: point cloud ignored: the latest pose is %.3f s from its stamp "
                        "(cloud/max_pose_age_s = %.3f)",
                        age_s, config_.cloud_max_pose_age_s);
      return;
    }
  }
  std::vector<Eigen::Vector3d> points;
  const ConversionStatus status = pointCloud2ToPoints(*cloud, &points);
  if (status != ConversionStatus::kOk) {
    ++frames_refused_;
    ROS_WARN_THROTTLE(1.0, "mapping: point cloud refused: %s", toString(status));
    return;
  }
  integrate("point cloud", cloud->header.stamp, origin, [&](OccupancyMap& map) { return map.fusePointCloud(points, origin); });
}

// ---------------------------------------------------------------------------------------------
// The writer

VoxelBox MappingServer::recenterLocked(const Eigen::Vector3d& p) {
  const GridGeometry& g = occupancy_->geometry();
  // A finite but absurd position (1e12 m) would overflow the int voxel indices (undefined
  // behaviour in indexOf); such a frame is refused by the fusion as out of the map anyway.
  if (!p.allFinite() || (p.cwiseAbs() * g.inverseResolution()).maxCoeff() > 1e8) return VoxelBox();
  const Eigen::Vector3d center = 0.5 * (g.windowMin() + g.windowMax());
  if ((p - center).head<2>().norm() <= config_.recenter_threshold_m) return VoxelBox();
  // x and y follow the vehicle; z stays (the window spans floor to ceiling, and the ESDF slice
  // height stays inside it).
  Eigen::Vector3i origin = g.indexOf(p) - g.size() / 2;
  origin.z() = g.originIndex().z();
  const VoxelBox moved = occupancy_->setOriginIndex(origin);
  ROS_INFO("mapping: window recentred on (%.2f, %.2f), now from (%.2f, %.2f)", p.x(), p.y(), g.windowMin().x(),
           g.windowMin().y());
  return moved;
}

void MappingServer::integrate(const char* source, const ros::Time& stamp, const Eigen::Vector3d& sensor_position,
                              const std::function<FusionResult(OccupancyMap&)>& fuse) {
  const double lead = stamp.toSec() - ros::Time::now().toSec();
  if (lead > config_.max_stamp_lead_s) {
    ++frames_refused_;
    ROS_WARN_THROTTLE(1.0, "mapping: %s stamped %.3f s ahead of the clock refused (max_stamp_lead_s = %.2f)", source,
                      lead, config_.max_stamp_lead_s);
    return;
  }
  std::unique_lock<std::shared_mutex> lock(map_mutex_);
  VoxelBox changed;
  if (config_.recenter_on_vehicle) changed = recenterLocked(sensor_position);
  const auto t0 = std::chrono::steady_clock::now();
  const FusionResult result = fuse(*occupancy_);
  const double fusion_ms = msSince(t0);
  if (result.status == MapStatus::kSuccess) changed.merge(result.changed_box);
  // update() also catches up with a moved window (a full recompute) when the fusion failed.
  const auto t1 = std::chrono::steady_clock::now();
  esdf_->update(changed);
  const double esdf_ms = msSince(t1);
  // A frame that reached the map proves the sensor alive, also when it held no valid return.
  const bool reached = result.status == MapStatus::kSuccess || result.status == MapStatus::kNoValidData;
  if (reached) {
    stats_.depth_stamp_s = stamp.toSec();
    stats_.depth_arrival_s = ros::Time::now().toSec();
    // Announced once fused (the simulator's perception lockstep waits for it).
    std_msgs::Header fused;
    fused.stamp = stamp;
    fused.frame_id = config_.frame_id;
    fused_pub_.publish(fused);
  }
  if (result.status != MapStatus::kSuccess) {
    ++frames_refused_;
    lock.unlock();
    if (result.status == MapStatus::kNoValidData) {  // e.g. a camera facing the sky: normal, not bad input
      ROS_INFO_THROTTLE(5.0, "mapping: %s not fused: %s", source, toString(result.status));
    } else {
      ROS_WARN_THROTTLE(1.0, "mapping: %s not fused: %s", source, toString(result.status));
    }
    return;
  }
  ++stats_.frames_fused;
  stats_.last_fusion_ms = fusion_ms;
  stats_.last_esdf_ms = esdf_ms;
  Stats s = stats_;
  lock.unlock();
  s.frames_refused = frames_refused_;
  ROS_INFO_THROTTLE(config_.status_period_s,
                    "mapping: %lu frames fused, %lu refused; last fusion %.2f ms (%d rays), last ESDF %.2f ms",
                    static_cast<unsigned long>(s.frames_fused), static_cast<unsigned long>(s.frames_refused),
                    s.last_fusion_ms, result.rays, s.last_esdf_ms);
}

// ---------------------------------------------------------------------------------------------
// Outputs

void MappingServer::publishOccupancy(const ros::TimerEvent&) {
  const bool want_occupied = occupancy_pub_.getNumSubscribers() > 0;
  const bool want_inflated = inflated_pub_.getNumSubscribers() > 0;
  if (!want_occupied && !want_inflated) return;
  std::vector<Eigen::Vector3d> occupied, inflated;
  {
    std::shared_lock<std::shared_mutex> lock(map_mutex_);
    const GridGeometry& g = occupancy_->geometry();
    if (want_occupied)
      occupancy_->forEachOccupied([&](const Eigen::Vector3i& i) { occupied.push_back(g.centerOf(i)); });
    if (want_inflated) {
      const VoxelBox w = g.windowBox();
      Eigen::Vector3i i;
      for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
        for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
          for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x())
            if (esdf_->isInflatedOccupied(i)) inflated.push_back(g.centerOf(i));
    }
  }
  const ros::Time stamp = ros::Time::now();
  if (want_occupied) {
    sensor_msgs::PointCloud2 msg;
    pointsToPointCloud2(occupied, config_.frame_id, stamp, &msg);
    occupancy_pub_.publish(msg);
  }
  if (want_inflated) {
    sensor_msgs::PointCloud2 msg;
    pointsToPointCloud2(inflated, config_.frame_id, stamp, &msg);
    inflated_pub_.publish(msg);
  }
}

void MappingServer::publishEsdfSlice(const ros::TimerEvent&) {
  if (esdf_slice_pub_.getNumSubscribers() == 0) return;
  std::vector<Eigen::Vector3d> points;
  std::vector<float> distances;
  {
    std::shared_lock<std::shared_mutex> lock(map_mutex_);
    const GridGeometry& g = occupancy_->geometry();
    const VoxelBox w = g.windowBox();
    const double h = config_.esdf_slice_height_m;
    if (!(h >= g.windowMin().z() && h < g.windowMax().z())) {  // buildMaps checked it, and z never moves
      ROS_WARN_THROTTLE(10.0, "mapping: ESDF slice height %.2f m is outside the map", config_.esdf_slice_height_m);
      return;
    }
    Eigen::Vector3i i = g.indexOf(Eigen::Vector3d(0, 0, h));
    i.z() = std::min(std::max(i.z(), w.min.z()), w.max.z());  // h a rounding below windowMax
    points.reserve(size_t(g.size().x()) * size_t(g.size().y()));
    distances.reserve(points.capacity());
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        double d;
        if (esdf_->distance(i, &d) == QueryStatus::kOutOfMap) continue;
        points.push_back(g.centerOf(i));
        distances.push_back(float(d));
      }
  }
  sensor_msgs::PointCloud2 msg;
  pointsToPointCloud2(points, distances, config_.frame_id, ros::Time::now(), &msg);
  esdf_slice_pub_.publish(msg);
}

}  // namespace topo_planner
