#include "topo_planner/plan_env/depth_image.h"

#include <cmath>
#include <cstring>
#include <limits>

namespace topo_planner {

bool PinholeCamera::valid() const {
  return width > 0 && height > 0 && std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) &&
         std::isfinite(cy) && fx > 0.0 && fy > 0.0;
}

double DepthImageView::depthAt(int u, int v) const {
  const uint8_t* p = data + size_t(v) * row_step_bytes + size_t(u) * bytesPerPixel();
  if (encoding == DepthEncoding::kUInt16) {
    uint16_t raw;
    std::memcpy(&raw, p, sizeof(raw));
    if (raw == 0) return std::numeric_limits<double>::quiet_NaN();
    return raw * depth_scale;
  }
  float raw;
  std::memcpy(&raw, p, sizeof(raw));
  return double(raw) * depth_scale;
}

}  // namespace topo_planner
