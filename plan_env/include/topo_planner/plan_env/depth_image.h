#pragma once
// Sensor inputs of the mapping core, without any ROS type: a pinhole camera and a borrowed view of
// a depth image's pixels (16-bit unsigned or 32-bit float, any size and row step).

#include <cstddef>
#include <cstdint>
#include <string>

namespace topo_planner {

/// Pinhole intrinsics of the depth camera. Camera frame: x right, y down, z forward (ROS optical frame).
struct PinholeCamera {
  int width = 640;   ///< image width the intrinsics belong to [px]
  int height = 480;  ///< image height [px]
  double fx = 387.229248046875;  ///< focal length x [px]
  double fy = 387.229248046875;  ///< focal length y [px]
  double cx = 321.04638671875;   ///< principal point x [px]
  double cy = 243.44969177246094;  ///< principal point y [px]

  /// True when all values are finite, focal lengths positive and the size positive.
  bool valid() const;
};

enum class DepthEncoding {
  kUInt16,   ///< 16UC1, depth = value * depth_scale (millimetres: scale 0.001); 0 means no return
  kFloat32,  ///< 32FC1, depth = value * depth_scale (metres: scale 1); NaN/-inf invalid, +inf no return (REP 117)
};

/// Non-owning view of a depth image in host byte order.
struct DepthImageView {
  const uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  size_t row_step_bytes = 0;  ///< bytes from one row to the next (>= width * bytes per pixel)
  DepthEncoding encoding = DepthEncoding::kFloat32;
  double depth_scale = 1.0;  ///< metres per stored unit

  size_t bytesPerPixel() const { return encoding == DepthEncoding::kUInt16 ? 2 : 4; }
  /// Depth of pixel (u, v) in metres, before range checks: NaN for "invalid", +inf for "no return".
  double depthAt(int u, int v) const;
};

}  // namespace topo_planner
