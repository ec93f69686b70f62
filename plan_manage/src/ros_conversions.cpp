#include "topo_planner/plan_manage/ros_conversions.h"

#include <sensor_msgs/PointField.h>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace topo_planner {

namespace {

bool hostIsBigEndian() {
  const uint16_t probe = 1;
  uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}

// Reads a scalar of `bytes` bytes at p, swapping its bytes when `swap`.
template <typename T>
T readScalar(const uint8_t* p, bool swap) {
  uint8_t b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

struct XyzLayout {
  uint32_t offset[3] = {0, 0, 0};
  bool is_double = false;
};

bool findXyzFields(const sensor_msgs::PointCloud2& msg, XyzLayout* layout) {
  const char* names[3] = {"x", "y", "z"};
  int datatype = -1;
  for (int a = 0; a < 3; ++a) {
    const auto it = std::find_if(msg.fields.begin(), msg.fields.end(),
                                 [&](const sensor_msgs::PointField& f) { return f.name == names[a]; });
    if (it == msg.fields.end()) return false;
    if (it->datatype != sensor_msgs::PointField::FLOAT32 && it->datatype != sensor_msgs::PointField::FLOAT64)
      return false;
    if (datatype >= 0 && it->datatype != datatype) return false;  // mixed float/double: not worth supporting
    datatype = it->datatype;
    const uint32_t size = it->datatype == sensor_msgs::PointField::FLOAT64 ? 8 : 4;
    if (uint64_t(it->offset) + size > msg.point_step) return false;
    layout->offset[a] = it->offset;
  }
  layout->is_double = datatype == sensor_msgs::PointField::FLOAT64;
  return true;
}

void setXyzFields(bool with_intensity, size_t n, sensor_msgs::PointCloud2* msg) {
  sensor_msgs::PointCloud2Modifier modifier(*msg);
  if (with_intensity) {
    modifier.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1,
                                  sensor_msgs::PointField::FLOAT32, "z", 1, sensor_msgs::PointField::FLOAT32,
                                  "intensity", 1, sensor_msgs::PointField::FLOAT32);
  } else {
    modifier.setPointCloud2Fields(3, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1,
                                  sensor_msgs::PointField::FLOAT32, "z", 1, sensor_msgs::PointField::FLOAT32);
  }
  modifier.resize(n);  // sets width = n, height = 1, row_step and data
  msg->height = 1;
  msg->width = uint32_t(n);
  msg->is_bigendian = hostIsBigEndian();
  msg->is_dense = true;
}

}  // namespace

const char* toString(ConversionStatus status) {
  switch (status) {
    case ConversionStatus::kOk: return "ok";
    case ConversionStatus::kUnsupportedEncoding: return "unsupported depth encoding (expected 16UC1, mono16 or 32FC1)";
    case ConversionStatus::kEmptyImage: return "empty image";
    case ConversionStatus::kTruncatedData: return "image data shorter than step * height, or step shorter than a row";
    case ConversionStatus::kImageTooLarge: return "image dimensions out of range";
    case ConversionStatus::kInvalidPose: return "invalid pose (NaN/inf, or quaternion not of unit norm)";
    case ConversionStatus::kMissingFields: return "point cloud lacks FLOAT32/FLOAT64 x, y, z fields";
    case ConversionStatus::kTruncatedCloud: return "point cloud data shorter than its header says";
    case ConversionStatus::kInvalidCameraInfo:
      return "camera info without usable intrinsics (K not finite, focal length <= 0, zero size, binning or ROI)";
  }
  return "unknown status";
}

ConversionStatus depthImageToView(const sensor_msgs::Image& msg, const DepthScales& scales,
                                  std::vector<uint8_t>* swap_buffer, DepthImageView* view) {
  namespace enc = sensor_msgs::image_encodings;
  DepthImageView v;
  if (msg.encoding == enc::TYPE_16UC1 || msg.encoding == enc::MONO16) {
    v.encoding = DepthEncoding::kUInt16;
    v.depth_scale = scales.uint16_m;
  } else if (msg.encoding == enc::TYPE_32FC1) {
    v.encoding = DepthEncoding::kFloat32;
    v.depth_scale = scales.float32_m;
  } else {
    return ConversionStatus::kUnsupportedEncoding;
  }
  if (msg.width == 0 || msg.height == 0 || msg.data.empty()) return ConversionStatus::kEmptyImage;
  const uint32_t int_max = uint32_t(std::numeric_limits<int>::max());
  if (msg.width > int_max || msg.height > int_max) return ConversionStatus::kImageTooLarge;
  const uint64_t bpp = v.bytesPerPixel();
  const uint64_t row_bytes = uint64_t(msg.width) * bpp;
  // The last row needs only its pixels, not a full step (some drivers trim the padding).
  if (msg.step < row_bytes || uint64_t(msg.step) * (msg.height - 1) + row_bytes > msg.data.size())
    return ConversionStatus::kTruncatedData;

  v.width = int(msg.width);
  v.height = int(msg.height);
  v.row_step_bytes = msg.step;
  v.data = msg.data.data();
  if (bool(msg.is_bigendian) != hostIsBigEndian()) {
    swap_buffer->assign(msg.data.begin(), msg.data.end());
    for (uint64_t r = 0; r < msg.height; ++r) {
      uint8_t* row = swap_buffer->data() + r * msg.step;
      for (uint64_t px = 0; px < msg.width; ++px) std::reverse(row + px * bpp, row + (px + 1) * bpp);
    }
    v.data = swap_buffer->data();
  }
  *view = v;
  return ConversionStatus::kOk;
}

ConversionStatus poseToIsometry(const geometry_msgs::Pose& msg, Eigen::Isometry3d* T) {
  const Eigen::Vector3d p(msg.position.x, msg.position.y, msg.position.z);
  Eigen::Quaterniond q(msg.orientation.w, msg.orientation.x, msg.orientation.y, msg.orientation.z);
  if (!p.allFinite() || !q.coeffs().allFinite()) return ConversionStatus::kInvalidPose;
  const double n = q.norm();
  if (std::abs(n - 1.0) > 1e-2) return ConversionStatus::kInvalidPose;
  q.coeffs() /= n;
  T->setIdentity();
  T->linear() = q.toRotationMatrix();
  T->translation() = p;
  return ConversionStatus::kOk;
}

ConversionStatus pointCloud2ToPoints(const sensor_msgs::PointCloud2& msg, std::vector<Eigen::Vector3d>* points) {
  points->clear();
  XyzLayout layout;
  if (!findXyzFields(msg, &layout)) return ConversionStatus::kMissingFields;
  const uint64_t n = uint64_t(msg.width) * msg.height;
  if (n == 0) return ConversionStatus::kOk;
  const uint64_t row_bytes = uint64_t(msg.width) * msg.point_step;
  if (msg.row_step < row_bytes || uint64_t(msg.row_step) * (msg.height - 1) + row_bytes > msg.data.size())
    return ConversionStatus::kTruncatedCloud;
  const bool swap = bool(msg.is_bigendian) != hostIsBigEndian();
  points->reserve(n);
  for (uint64_t r = 0; r < msg.height; ++r) {
    const uint8_t* row = msg.data.data() + r * msg.row_step;
    for (uint64_t c = 0; c < msg.width; ++c) {
      const uint8_t* pt = row + c * msg.point_step;
      Eigen::Vector3d p;
      for (int a = 0; a < 3; ++a)
        p[a] = layout.is_double ? readScalar<double>(pt + layout.offset[a], swap)
                                : double(readScalar<float>(pt + layout.offset[a], swap));
      points->push_back(p);
    }
  }
  return ConversionStatus::kOk;
}

void pointsToPointCloud2(const std::vector<Eigen::Vector3d>& points, const std::string& frame_id,
                         const ros::Time& stamp, sensor_msgs::PointCloud2* msg) {
  msg->header.frame_id = frame_id;
  msg->header.stamp = stamp;
  setXyzFields(false, points.size(), msg);
  if (points.empty()) return;  // the iterators index data[0]: undefined on an empty cloud
  sensor_msgs::PointCloud2Iterator<float> x(*msg, "x"), y(*msg, "y"), z(*msg, "z");
  for (const Eigen::Vector3d& p : points) {
    *x = float(p.x());
    *y = float(p.y());
    *z = float(p.z());
    ++x, ++y, ++z;
  }
}

void pointsToPointCloud2(const std::vector<Eigen::Vector3d>& points, const std::vector<float>& intensities,
                         const std::string& frame_id, const ros::Time& stamp, sensor_msgs::PointCloud2* msg) {
  msg->header.frame_id = frame_id;
  msg->header.stamp = stamp;
  const size_t n = std::min(points.size(), intensities.size());
  setXyzFields(true, n, msg);
  if (n == 0) return;  // the iterators index data[0]: undefined on an empty cloud
  sensor_msgs::PointCloud2Iterator<float> x(*msg, "x"), y(*msg, "y"), z(*msg, "z"), in(*msg, "intensity");
  for (size_t i = 0; i < n; ++i) {
    *x = float(points[i].x());
    *y = float(points[i].y());
    *z = float(points[i].z());
    *in = intensities[i];
    ++x, ++y, ++z, ++in;
  }
}

ConversionStatus cameraInfoToPinhole(const sensor_msgs::CameraInfo& msg, PinholeCamera* camera) {
  const auto& K = msg.K;
  const bool finite = std::all_of(K.begin(), K.end(), [](double v) { return std::isfinite(v); });
  const bool binned = msg.binning_x > 1 || msg.binning_y > 1;
  const auto& roi = msg.roi;
  const bool cropped = (roi.width != 0 || roi.height != 0 || roi.x_offset != 0 || roi.y_offset != 0) &&
                       !(roi.x_offset == 0 && roi.y_offset == 0 && roi.width == msg.width && roi.height == msg.height);
  if (!finite || binned || cropped || msg.width == 0 || msg.height == 0 || msg.width > 1u << 16 ||
      msg.height > 1u << 16 || !(K[0] > 0.0) || !(K[4] > 0.0))
    return ConversionStatus::kInvalidCameraInfo;
  PinholeCamera c;
  c.width = int(msg.width);
  c.height = int(msg.height);
  c.fx = K[0];
  c.fy = K[4];
  c.cx = K[2];
  c.cy = K[5];
  if (!c.valid()) return ConversionStatus::kInvalidCameraInfo;
  *camera = c;
  return ConversionStatus::kOk;
}

void healthToStatus(const HealthReport& report, diagnostic_updater::DiagnosticStatusWrapper* status) {
  using diagnostic_msgs::DiagnosticStatus;
  const unsigned char level = report.level == HealthLevel::kOk     ? DiagnosticStatus::OK
                              : report.level == HealthLevel::kWarn ? DiagnosticStatus::WARN
                                                                   : DiagnosticStatus::ERROR;
  status->summary(level, report.message);
  for (const auto& kv : report.values) status->add(kv.first, kv.second);
}

}  // namespace topo_planner
