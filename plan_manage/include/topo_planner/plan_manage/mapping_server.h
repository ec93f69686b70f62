#pragma once
// MappingServer: the ROS wrapper of the plan_env occupancy grid and ESDF (the mapping of Zhou et
// al. ICRA 2020, Sec. III: a probabilistic occupancy grid fused from depth images, and an ESDF
// over it for the gradient-based trajectory optimisation). The node `mapping_node` runs one.
//
// Topics (all in the node's private namespace; remap them in the launch file)
//   Subscribed
//     ~depth               sensor_msgs/Image          depth image, 16UC1/mono16 [mm] or 32FC1 [m] (REP 118),
//                                                     either byte order, any row step
//     ~camera_pose         geometry_msgs/PoseStamped  pose of the camera *optical* frame (x right, y down,
//                                                     z forward) in frame_id; used when pose_type = pose
//     ~odometry            nav_msgs/Odometry          pose of the body in frame_id; the camera pose is
//                                                     odometry * extrinsic; used when pose_type = odometry
//     ~camera_info         sensor_msgs/CameraInfo     the depth camera's intrinsics (K, width, height), used
//                                                     from the first valid one on (camera/from_camera_info); until
//                                                     then, and when it is off, camera/* below
//     ~cloud               sensor_msgs/PointCloud2    points in frame_id (x, y, z FLOAT32 or FLOAT64); the
//                                                     sensor origin is the latest pose/odometry camera
//                                                     position, or cloud/sensor_origin_m
//     The depth image and the pose (or odometry) are paired by message_filters' ApproximateTime
//     policy; the pose topic is also tracked alone as the sensor origin of the clouds.
//   Published (PointCloud2 in frame_id, on timers, only while someone subscribes)
//     ~occupancy           centres of the occupied voxels
//     ~occupancy_inflated  centres of the voxels within esdf/inflate_radius_m of an obstacle
//     ~esdf_slice          the ESDF at height publish/esdf_slice_height_m, field `intensity` = distance [m]
//   Published at once, for every frame (image or cloud) that reached the map
//     ~depth_fused         std_msgs/Header, the frame's stamp (the simulator's perception lockstep)
//
// Parameters (private; the default is the default of the config struct below / of plan_env)
//   frame_id                    "world"   world frame of the map, the poses and the clouds
//   check_frame_id              true      refuse poses/clouds whose header frame_id is set and differs
//   pose_type                   "pose"    pose | odometry: which topic gives the camera pose
//   sync_queue_size             10        ApproximateTime queue per topic [messages]
//   sync_max_interval_s         0.05      largest stamp difference of a depth/pose pair; 0 = no limit [s]
//   map_file                    ""        .bt/.ot/.pcd map loaded at start (empty = none); a file that
//                                         cannot be read stops the node
//   recenter_on_vehicle         false     move the window in x/y to keep the sensor near its centre
//   recenter_threshold_m        2.0       sensor distance (x/y) from the window centre that triggers it [m]
//   map/resolution_m            0.1       voxel edge [m]
//   map/size_m                  [20, 20, 5]     window extent [m]
//   map/origin_m                [-10, -10, -1]  window lower corner [m]
//   map/prob_hit, prob_miss, prob_min, prob_max, prob_occupied   0.70, 0.35, 0.12, 0.97, 0.80
//   map/min_ray_length_m        0.1       shorter returns are ignored [m]
//   map/max_ray_length_m        4.5       longer rays only clear space up to here [m]
//   map/depth_pixel_skip        2         fuse every n-th pixel in u and v
//   map/max_image_pixels        16777216  larger images are refused [pixels]
//   map/merge_rays              true      stop a ray where another ray of the frame cleared space
//   map/project_free_space      true      depth images: free space by projection (no unseen holes)
//   map/max_memory_mb           4096      refuse larger maps [MB]
//   esdf/max_distance_m         2.0       ESDF truncation distance [m]
//   esdf/inflate_radius_m       0.2       obstacle inflation radius [m]
//   esdf/unknown_as_occupied    false     unknown voxels count as obstacles in the ESDF
//   esdf/num_threads            2         ESDF worker threads, the caller included
//   camera/width, camera/height 640, 480  image size the intrinsics belong to [px]
//   camera/fx, fy, cx, cy       387.23, 387.23, 321.05, 243.45  pinhole intrinsics [px]
//   camera/uint16_depth_scale_m 0.001     metres per unit of a 16UC1 image [m]
//   extrinsic/translation_m     [0, 0, 0]             camera optical frame origin in the body frame [m]
//   extrinsic/quaternion_xyzw   [-0.5, 0.5, -0.5, 0.5] rotation body <- camera optical frame (a camera
//                                         looking along body +x in a FLU body frame)
//   extrinsic/matrix_row_major  []        alternatively the 4x4 T_body_camera, 16 values row-major
//   camera/from_camera_info     true      intrinsics from ~camera_info once one arrives (camera/* until then)
//   body_frame_id               ""        with pose_type odometry: the extrinsic from tf2, body_frame_id ->
//                                         the depth image's header frame_id (as a robot's URDF / static
//                                         transform publisher give it); extrinsic/* until tf has it.
//                                         Empty: extrinsic/* only
//   cloud/origin_from_pose      true      sensor origin of a cloud = latest camera position
//   cloud/sensor_origin_m       [0, 0, 0] the fixed sensor origin otherwise [m]
//   cloud/max_pose_age_s        0.2       refuse a cloud whose latest pose is older/newer than this [s]
//   cloud/max_points            2000000   refuse a cloud with more points (width x height) than this
//   publish/occupancy_rate_hz   1.0       ~occupancy and ~occupancy_inflated; 0 = off [Hz]
//   publish/esdf_rate_hz        1.0       ~esdf_slice; 0 = off [Hz]
//   publish/esdf_slice_height_m 1.0       height of the slice (inside the window) [m]
//   status_period_s             5.0       period of the ROS_INFO status line [s]
//   max_stamp_lead_s            0.5       refuse a frame (image or cloud) stamped further ahead of the clock [s]
//
// Bad input (NaN/inf or non-unit poses, wrong encodings, empty, oversized or truncated images,
// size different from the intrinsics, poses/clouds in another frame, stamps past 2^31 s) is
// refused with a throttled ROS_WARN giving the status string; the map is left unchanged and the
// node keeps running. Invalid parameters stop the node at start with a ROS_ERROR saying why.

#include <Eigen/Geometry>
#include <geometry_msgs/PoseStamped.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <vector>

#include "topo_planner/plan_env/depth_image.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_manage/health.h"
#include "topo_planner/plan_manage/ros_conversions.h"
#include "topo_planner/plan_manage/stamp_guard.h"

namespace topo_planner {

/// Owns the occupancy map and its ESDF, fuses the sensor topics into them and publishes them.
///
/// Locking rule: `map_mutex_` guards occupancy_ and esdf_. The only writer is integrate() (window
/// recentering, fusion of one frame and the ESDF update of what it changed, all under one
/// unique_lock, so readers never see an occupancy grid newer than its ESDF). Readers (the publish
/// timers, readMaps()) hold a shared_lock only while they copy voxel centres out, and convert and
/// publish after releasing it. `pose_mutex_` guards the latest pose only; it is never held while
/// taking map_mutex_. Callbacks may run on several spinner threads.
class MappingServer {
 public:
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

  enum class PoseType { kPose, kOdometry };

  struct Config {
    OccupancyMap::Config occupancy;  ///< grid (see plan_env/occupancy_map.h)
    EsdfMap::Config esdf;            ///< distance field (see plan_env/esdf_map.h)
    PinholeCamera camera;            ///< depth camera intrinsics
    DepthScales depth_scales;        ///< metres per unit of each depth encoding

    std::string frame_id = "world";  ///< world frame of the map, the poses and the clouds
    bool check_frame_id = true;      ///< refuse poses/clouds whose non-empty frame_id differs from frame_id
    PoseType pose_type = PoseType::kPose;  ///< camera pose from ~camera_pose or from ~odometry * extrinsic
    /// Camera optical frame in the body frame (odometry only). Default: camera at the body origin
    /// looking along body +x of a FLU body (optical z = body x, x = -body y, y = -body z).
    Eigen::Isometry3d T_body_camera = defaultBodyToCamera();
    bool camera_info = true;      ///< intrinsics from ~camera_info once a valid one arrives
    std::string body_frame_id;    ///< non-empty: T_body_camera from tf2 (body -> image frame), YAML until then
    int sync_queue_size = 10;           ///< ApproximateTime queue per topic [messages]
    double sync_max_interval_s = 0.05;  ///< largest stamp difference of a depth/pose pair; 0 = no limit [s]

    bool cloud_origin_from_pose = true;  ///< sensor origin of a cloud = latest camera position
    Eigen::Vector3d cloud_sensor_origin_m = Eigen::Vector3d::Zero();  ///< fixed origin otherwise [m]
    double cloud_max_pose_age_s = 0.2;   ///< refuse a cloud whose latest pose is further away in time [s]
    int cloud_max_points = 2000000;      ///< refuse a cloud with more points than this (width x height)

    std::string map_file;             ///< .bt/.ot/.pcd loaded at start; empty = none
    bool recenter_on_vehicle = false;   ///< keep the window centred (x, y) on the sensor
    double recenter_threshold_m = 2.0;  ///< sensor offset from the window centre that moves it [m]

    double occupancy_publish_rate_hz = 1.0;  ///< ~occupancy, ~occupancy_inflated; 0 = off [Hz]
    double esdf_publish_rate_hz = 1.0;       ///< ~esdf_slice; 0 = off [Hz]
    double esdf_slice_height_m = 1.0;        ///< height of ~esdf_slice [m]
    double status_period_s = 5.0;            ///< period of the status log line [s]
    /// A frame stamped further ahead of the clock is refused: no sensor of this clock took it, and its
    /// stamp would make every later frame look old to the planner [s].
    double max_stamp_lead_s = 0.5;

    static Eigen::Isometry3d defaultBodyToCamera();
    /// True when every field (including the core configs) is in range; otherwise says why.
    bool validate(std::string* why) const;
  };

  /// Counters of the fusion, for the status line.
  struct Stats {
    uint64_t frames_fused = 0;     ///< depth images and clouds fused
    uint64_t frames_refused = 0;   ///< refused by the conversions, the frame check or the core
    double last_fusion_ms = 0.0;   ///< duration of the last fusion [ms]
    double last_esdf_ms = 0.0;     ///< duration of the last ESDF update [ms]
    /// Liveness of the inputs (ROS time seconds; -1 = never): the last depth frame or cloud that
    /// reached the map (fused, or valid but empty, e.g. a camera facing open sky) and the last
    /// accepted pose/odometry, by stamp and by arrival.
    double depth_stamp_s = -1.0, depth_arrival_s = -1.0;
    double pose_stamp_s = -1.0, pose_arrival_s = -1.0;
  };

  /// Builds the maps, loads config.map_file, subscribes and advertises in `nh` (the node's
  /// private handle). nullptr with a reason when the maps cannot be built or the file loaded.
  static std::unique_ptr<MappingServer> create(const ros::NodeHandle& nh, const Config& config, std::string* error);

  const Config& config() const { return config_; }
  Stats stats() const;
  /// The mapping's health at ROS time `now` for /diagnostics (plan_manage/health.h).
  HealthReport health(double now);

  /// Forgets the map (every voxel unknown), e.g. after the odometry jumped: what was mapped in the
  /// old frame would sit in the wrong place in the new one.
  void clearMap(const std::string& why);

  /// Calls fn(occupancy, esdf) under the shared lock (for an in-process planner).
  void readMaps(const std::function<void(const OccupancyMap&, const EsdfMap&)>& fn) const;

 private:
  using ImagePoseSync = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, geometry_msgs::PoseStamped>;
  using ImageOdomSync = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, nav_msgs::Odometry>;

  MappingServer(const ros::NodeHandle& nh, const Config& config);
  bool buildMaps(std::string* error);
  void subscribeAndAdvertise();

  void depthPoseCallback(const sensor_msgs::ImageConstPtr& image, const geometry_msgs::PoseStampedConstPtr& pose);
  void depthOdomCallback(const sensor_msgs::ImageConstPtr& image, const nav_msgs::OdometryConstPtr& odom);
  void poseCallback(const geometry_msgs::PoseStampedConstPtr& pose);
  void odomCallback(const nav_msgs::OdometryConstPtr& odom);
  void cloudCallback(const sensor_msgs::PointCloud2ConstPtr& cloud);
  void fuseDepth(const sensor_msgs::Image& image, const Eigen::Isometry3d& T_world_camera);
  void cameraInfoCallback(const sensor_msgs::CameraInfoConstPtr& info);
  /// With body_frame_id: the extrinsic in use from tf (body -> `camera_frame`), when tf has it.
  void refreshExtrinsic(const std::string& camera_frame);
  /// Camera pose of a pose/odometry message, or false (with a throttled warning) if it is unusable.
  bool cameraPoseOf(const std_msgs::Header& header, const geometry_msgs::Pose& pose, bool is_odometry,
                    Eigen::Isometry3d* T_world_camera) const;
  bool frameAccepted(const std::string& frame, const char* what) const;

  /// The writer: recenters the window if asked, runs `fuse` and updates the ESDF, under map_mutex_.
  void integrate(const char* source, const ros::Time& stamp, const Eigen::Vector3d& sensor_position,
                 const std::function<FusionResult(OccupancyMap&)>& fuse);
  VoxelBox recenterLocked(const Eigen::Vector3d& sensor_position);

  void publishOccupancy(const ros::TimerEvent&);
  void publishEsdfSlice(const ros::TimerEvent&);

  ros::NodeHandle nh_;
  Config config_;
  MappingHealth health_;  // thread-safe

  mutable std::shared_mutex map_mutex_;
  std::shared_ptr<OccupancyMap> occupancy_;  // written under map_mutex_
  std::unique_ptr<EsdfMap> esdf_;            // holds occupancy_ as shared_ptr<const>
  Stats stats_;                              // written under the unique lock of map_mutex_
  std::atomic<uint64_t> frames_refused_{0};  // counted outside the lock too (refused before fusion)

  mutable std::mutex pose_mutex_;
  bool have_pose_ = false;
  ros::Time latest_pose_stamp_;
  double latest_pose_arrival_s_ = -1.0;
  Eigen::Vector3d latest_camera_position_ = Eigen::Vector3d::Zero();

  message_filters::Subscriber<sensor_msgs::Image> depth_sub_;
  message_filters::Subscriber<geometry_msgs::PoseStamped> pose_sub_;
  message_filters::Subscriber<nav_msgs::Odometry> odom_sub_;
  StampGuard<sensor_msgs::Image> depth_guard_;  // between the subscribers and the synchronisers
  StampGuard<geometry_msgs::PoseStamped> pose_guard_;
  StampGuard<nav_msgs::Odometry> odom_guard_;
  std::unique_ptr<message_filters::Synchronizer<ImagePoseSync>> pose_sync_;
  std::unique_ptr<message_filters::Synchronizer<ImageOdomSync>> odom_sync_;
  ros::Subscriber cloud_sub_, camera_info_sub_;
  mutable std::mutex camera_mutex_;   // guards camera_, extrinsic_
  PinholeCamera camera_;              // the intrinsics in use (camera/*, then ~camera_info)
  bool camera_from_info_ = false;
  Eigen::Isometry3d extrinsic_;       // the body -> camera transform in use (extrinsic/*, then tf2)
  bool extrinsic_from_tf_ = false;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;            // with body_frame_id only
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Publisher occupancy_pub_, inflated_pub_, esdf_slice_pub_;
  ros::Publisher fused_pub_;  // ~depth_fused: the stamp of every frame that reached the map
  ros::Timer occupancy_timer_, esdf_timer_;
};

/// Reads every parameter above from `nh` into *config (absent ones keep the struct default),
/// validates them and the core configs, and returns false after a ROS_ERROR saying what is wrong.
/// Warns about private parameters it does not know (typos).
bool readMappingParams(const ros::NodeHandle& nh, MappingServer::Config* config);

}  // namespace topo_planner
