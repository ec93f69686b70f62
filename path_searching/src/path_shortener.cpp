#include "topo_planner/path_searching/path_shortener.h"

namespace topo_planner {

Path PathShortener::shorten(const Path& raw, bool* fell_back) const {
  if (fell_back) *fell_back = false;
  if (raw.size() <= 2) return raw;
  const double res = checker_.resolution();
  const Path dense = resamplePath(raw, 2.0 * res);  // the paper discretises uniformly; two voxels suffice
  Path out{dense.front()};
  // Invariant: out.back() sees dense[d - 1].
  for (size_t d = 1; d < dense.size(); ++d) {
    Eigen::Vector3d block;
    if (checker_.lineVisible(out.back(), dense[d], &block)) continue;
    bool appended = false;
    const DistanceQuery q = checker_.esdf().query(block);
    if ((q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown) && q.gradient.norm() > 1e-6) {
      // Push the blocking voxel away from the obstacle, orthogonally to the line of sight and in
      // the plane of the line and the ESDF gradient.
      const Eigen::Vector3d sight = (dense[d] - out.back()).normalized();
      Eigen::Vector3d push = q.gradient - q.gradient.dot(sight) * sight;
      if (push.norm() > 1e-6) {
        push.normalize();
        for (int k = 1; k <= 4 && !appended; ++k) {
          const Eigen::Vector3d candidate = block + push * (k * res);
          if (checker_.isFree(candidate) && checker_.lineVisible(out.back(), candidate) &&
              checker_.lineVisible(candidate, dense[d])) {
            out.push_back(candidate);
            appended = true;
          }
        }
      }
    }
    if (!appended && (out.back() - dense[d - 1]).norm() > 1e-12) out.push_back(dense[d - 1]);
  }
  if ((out.back() - dense.back()).norm() > 1e-12) out.push_back(dense.back());

  bool safe = true;
  for (size_t i = 1; i < out.size() && safe; ++i) safe = checker_.lineVisible(out[i - 1], out[i]);
  if (!safe || pathLength(out) > pathLength(raw) + 1e-9 || !uniformVisibilityEquivalent(out, raw, checker_)) {
    if (fell_back) *fell_back = true;
    return raw;
  }
  return out;
}

}  // namespace topo_planner
