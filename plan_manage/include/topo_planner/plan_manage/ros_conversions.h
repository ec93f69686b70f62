#pragma once
// Message conversions of the mapping node, at the edge between ROS and the ROS-free plan_env core
// (STYLE.md: one conversions file per wrapper). Every function checks its input and says what is
// wrong with it in a status value; none of them throws or asserts on message content.

#include <Eigen/Geometry>
#include <diagnostic_updater/DiagnosticStatusWrapper.h>
#include <geometry_msgs/Pose.h>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>

#include <cstdint>
#include <string>
#include <vector>

#include "topo_planner/plan_env/depth_image.h"
#include "topo_planner/plan_manage/health.h"

namespace topo_planner {

/// Outcome of a message conversion (problems the core never sees because the message is refused here).
enum class ConversionStatus {
  kOk,
  kUnsupportedEncoding,  ///< depth image encoding other than 16UC1/mono16/32FC1
  kEmptyImage,           ///< zero width/height or no pixel data
  kTruncatedData,        ///< row step shorter than a row, or fewer bytes than step * height
  kImageTooLarge,        ///< width/height beyond the range of the core's int sizes
  kInvalidPose,          ///< NaN/inf position or orientation, or a quaternion far from unit norm
  kMissingFields,        ///< point cloud without FLOAT32 (or FLOAT64) x, y, z fields
  kTruncatedCloud,       ///< point cloud data shorter than its header says
  kInvalidCameraInfo,    ///< CameraInfo without a usable K (NaN, non-positive focal length, zero size) or binned / cropped
};

const char* toString(ConversionStatus status);

/// Depth scale of the supported encodings (REP 118): 16UC1 in millimetres, 32FC1 in metres.
struct DepthScales {
  double uint16_m = 0.001;  ///< metres per unit of a 16UC1/mono16 image [m]
  double float32_m = 1.0;   ///< metres per unit of a 32FC1 image [m]
};

/// Borrowed view of `msg`'s pixels for the core. If the image's byte order differs from the
/// host's, the pixels are byte-swapped into `swap_buffer` and the view points there; otherwise
/// the view points into `msg.data`. Either way the view is valid while both live unchanged.
ConversionStatus depthImageToView(const sensor_msgs::Image& msg, const DepthScales& scales,
                                  std::vector<uint8_t>* swap_buffer, DepthImageView* view);

/// Pose -> isometry. A quaternion within 1% of unit norm is normalised; anything else (zero,
/// NaN, inf, far from unit) is refused rather than guessed.
ConversionStatus poseToIsometry(const geometry_msgs::Pose& msg, Eigen::Isometry3d* T);

/// Points of a PointCloud2 with x, y, z fields (FLOAT32 or FLOAT64, either byte order). NaN
/// points are kept: the core counts and skips them.
ConversionStatus pointCloud2ToPoints(const sensor_msgs::PointCloud2& msg, std::vector<Eigen::Vector3d>* points);

/// Unorganised FLOAT32 x, y, z cloud (height 1) of `points`.
void pointsToPointCloud2(const std::vector<Eigen::Vector3d>& points, const std::string& frame_id,
                         const ros::Time& stamp, sensor_msgs::PointCloud2* msg);

/// As pointsToPointCloud2 with a FLOAT32 `intensity` field; intensities.size() == points.size().
void pointsToPointCloud2(const std::vector<Eigen::Vector3d>& points, const std::vector<float>& intensities,
                         const std::string& frame_id, const ros::Time& stamp, sensor_msgs::PointCloud2* msg);

/// Pinhole intrinsics of a CameraInfo (K: fx, fy, cx, cy; width, height). The depth image is taken
/// as rectified (distortion is not applied: a depth driver's rectified or aligned stream). Binning
/// or a region of interest other than the full image is refused, as is a K that is not finite or
/// has a non-positive focal length, or a zero size.
ConversionStatus cameraInfoToPinhole(const sensor_msgs::CameraInfo& msg, PinholeCamera* camera);

/// A health report (plan_manage/health.h) as a diagnostic status: level, message and values.
void healthToStatus(const HealthReport& report, diagnostic_updater::DiagnosticStatusWrapper* status);

}  // namespace topo_planner
