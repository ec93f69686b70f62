#include "topo_planner/path_searching/path.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

double pathLength(const Path& path) {
  double len = 0.0;
  for (size_t i = 1; i < path.size(); ++i) len += (path[i] - path[i - 1]).norm();
  return len;
}

Eigen::Vector3d pointAtArcLength(const Path& path, double s) {
  if (path.size() == 1) return path.front();
  const double target = std::clamp(s, 0.0, 1.0) * pathLength(path);
  double walked = 0.0;
  for (size_t i = 1; i < path.size(); ++i) {
    const double seg = (path[i] - path[i - 1]).norm();
    if (walked + seg >= target && seg > 0.0) return path[i - 1] + (path[i] - path[i - 1]) * ((target - walked) / seg);
    walked += seg;
  }
  return path.back();
}

Path discretizeByArcLength(const Path& path, int k) {
  Path out;
  if (path.empty() || k < 1) return out;
  out.reserve(size_t(k) + 1);
  const double total = pathLength(path);
  if (path.size() == 1 || total <= 0.0) return Path(size_t(k) + 1, path.front());
  // One walk along the path: the targets i * total / k increase.
  size_t seg = 1;
  double seg_start = 0.0;
  for (int i = 0; i <= k; ++i) {
    const double target = total * i / k;
    double seg_len = (path[seg] - path[seg - 1]).norm();
    while (seg + 1 < path.size() && seg_start + seg_len < target) {
      seg_start += seg_len;
      ++seg;
      seg_len = (path[seg] - path[seg - 1]).norm();
    }
    const double t = seg_len > 0.0 ? std::clamp((target - seg_start) / seg_len, 0.0, 1.0) : 1.0;
    out.push_back(path[seg - 1] + (path[seg] - path[seg - 1]) * t);
  }
  out.back() = path.back();
  return out;
}

Path resamplePath(const Path& path, double step) {
  Path out;
  if (path.empty()) return out;
  out.push_back(path.front());
  for (size_t i = 1; i < path.size(); ++i) {
    const Eigen::Vector3d d = path[i] - path[i - 1];
    const int n = std::max(1, int(std::ceil(d.norm() / step)));
    for (int j = 1; j <= n; ++j) out.push_back(path[i - 1] + d * (double(j) / n));
  }
  return out;
}

}  // namespace topo_planner
