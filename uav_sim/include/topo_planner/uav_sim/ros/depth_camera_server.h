#pragma once
// DepthCameraServer: the simulated depth camera (uav_sim/depth_camera.h) on the vehicle. Renders the
// true map from the latest odometry pose times the camera extrinsic at rate_hz and publishes the
// image with the camera pose of the same stamp (the odometry's), as the mapping expects from a
// depth camera plus a state estimator. The node `depth_camera_node` runs one.
//
// Topics (relative names, resolved in the node's namespace)
//   Subscribed  odom                         nav_msgs/Odometry        the body pose
//               map_generator/global_cloud   sensor_msgs/PointCloud2  the true map (latched)
//               quadrotor_sim/depth_blackout std_msgs/Bool            the simulator's depth blackout
//                                                                     fault: no image while true
//               quadrotor_sim/odom_offset    geometry_msgs/Vector3Stamped  the simulator's odometry
//                                                                     jump offset [m]
//   Published   camera/depth/image_rect_raw  sensor_msgs/Image        32FC1 [m] (NaN invalid, +inf no
//                                                                     return) or 16UC1 [mm] (0 = none),
//                                                                     frame camera_frame
//               camera/depth/camera_info     sensor_msgs/CameraInfo   same stamp
//               camera/pose                  geometry_msgs/PoseStamped optical frame in world_frame,
//                                                                     same stamp as the image
//
// Faults (uav_sim/ros/quadrotor_sim.h, uav_sim/fault_schedule.h: the simulator owns the schedule and
// its clock). During a depth blackout no image, camera_info or pose is published. After an odometry
// jump the camera still sees the true world: it renders from the odometry pose minus the latest
// offset, and publishes the odometry's (offset) pose, as a camera on a relocalised VIO would. An
// odometry blackout needs nothing here: without new odometry no frame is rendered.
//
// Threads. Odometry is stored by the main spinner thread; rendering runs on a timer in its own
// callback queue and thread (the cloud's map build too), so a slow frame never delays odometry. A
// frame that takes longer than the period makes the timer skip ticks instead of queueing them; a
// tick without newer odometry than the last frame renders nothing (a paused clock or a stopped
// estimator gives no duplicate images). The status line reports the achieved rate, with a warning
// when it falls below 90 % of rate_hz.
//
// Parameters (private; defaults are the Config defaults below; config/depth_camera.yaml documents them)
//   rate_hz 30, encoding 32FC1|16UC1, method rasterize|raycast, camera/{width,height,fx,fy,cx,cy}
//   (640 x 480, fx 387.23...), min_range_m 0.1, max_range_m 6, noise_stddev_at_1m 0, seed 1, extrinsic/translation_m [0 0 0],
//   extrinsic/quaternion_xyzw [-0.5 0.5 -0.5 0.5], world_frame world, camera_frame camera_optical,
//   max_odom_age_s 0.5, truth_map_margin_m 1.5, truth_esdf_max_distance_m 2, status_period_s 10;
//   /sim/* for the true map's resolution and window.

#include <geometry_msgs/Vector3Stamped.h>
#include <nav_msgs/Odometry.h>
#include <std_msgs/Bool.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "topo_planner/uav_sim/depth_camera.h"
#include "topo_planner/uav_sim/ros/truth_map.h"

namespace topo_planner {

class DepthCameraServer {
 public:
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

  enum class Encoding { kFloat32, kUInt16 };

  struct Config {
    DepthCamera::Config camera;                               ///< intrinsics, range, noise, seed
    SimScenario scenario;                                     ///< true map resolution and window (/sim/*)
    double rate_hz = 30.0;                                    ///< frame rate [Hz]
    Encoding encoding = Encoding::kFloat32;                   ///< 32FC1 [m] or 16UC1 [mm]
    Eigen::Isometry3d T_body_camera = defaultBodyToCamera();  ///< optical frame in the body frame
    std::string world_frame = "world";            ///< frame of ~camera/pose
    std::string camera_frame = "camera_optical";  ///< frame of the image and camera_info
    double max_odom_age_s = 0.5;             ///< no frame from odometry older than this (ROS time) [s]
    /// Render from the simulator's true pose at the odometry's stamp (quadrotor_sim/ground_truth) and
    /// send the odometry's pose: the map then carries the estimate's noise and drift, as on a real
    /// drone. false: render from the odometry (minus injected jumps).
    bool render_from_truth = false;
    double truth_map_margin_m = 1.5;         ///< free margin of the true map's window [m]
    double truth_esdf_max_distance_m = 2.0;  ///< ESDF truncation of the true map: the longest sphere-tracing step [m]
    double status_period_s = 10.0;           ///< period of the status line (wall) [s]

    static Eigen::Isometry3d defaultBodyToCamera();
    bool validate(std::string* why) const;
  };

  static std::unique_ptr<DepthCameraServer> create(const ros::NodeHandle& nh, const Config& config, std::string* error);
  ~DepthCameraServer();

 private:
  DepthCameraServer(const ros::NodeHandle& nh, const Config& config);
  void odomCallback(const nav_msgs::OdometryConstPtr& msg);
  void blackoutCallback(const std_msgs::BoolConstPtr& msg);
  void truthCallback(const nav_msgs::OdometryConstPtr& msg);
  void offsetCallback(const geometry_msgs::Vector3StampedConstPtr& msg);
  void renderCallback(const ros::TimerEvent&);

  ros::NodeHandle nh_;
  Config config_;

  std::mutex odom_mutex_;  // guards the three below (written by the main thread, read by the render thread)
  nav_msgs::OdometryConstPtr latest_odom_;
  bool blackout_ = false;                                   // depth blackout fault
  Eigen::Vector3d odom_offset_ = Eigen::Vector3d::Zero();   // odometry jump fault [m]
  std::deque<nav_msgs::OdometryConstPtr> truth_poses_;       // the last 2 s of true poses (render_from_truth)
  uint64_t blackout_frames_ = 0;                            // frames not sent for a blackout (render thread)

  // Render thread only.
  std::shared_ptr<const TruthMap> camera_map_;  // the map camera_ renders (kept alive with it)
  std::unique_ptr<DepthCamera> camera_;
  ros::Time last_rendered_stamp_;
  std::vector<float> depth_;
  std::vector<uint16_t> depth_mm_;
  uint64_t frames_ = 0, period_frames_ = 0, period_blackout_start_ = 0;
  double period_render_ms_ = 0.0, period_max_render_ms_ = 0.0;
  ros::WallTime period_start_wall_;
  ros::Time period_start_;

  ros::CallbackQueue render_queue_;
  std::unique_ptr<ros::AsyncSpinner> render_spinner_;
  std::unique_ptr<TruthMapSubscriber> truth_;
  ros::Subscriber odom_sub_, blackout_sub_, offset_sub_, truth_sub_;
  ros::Timer render_timer_;
  ros::Publisher image_pub_, info_pub_, pose_pub_;
};

/// Reads the parameters into *config; false with a ROS_ERROR when any is invalid.
bool readDepthCameraParams(const ros::NodeHandle& pnh, DepthCameraServer::Config* config);

}  // namespace topo_planner
