#include "topo_planner/plan_env/occupancy_map.h"

#include <cmath>
#include <limits>
#include <new>
#include <sstream>

#include "topo_planner/plan_env/raycast.h"

namespace topo_planner {

namespace {

float logit(double p) { return float(std::log(p / (1.0 - p))); }

bool validPose(const Eigen::Isometry3d& T) {
  if (!T.matrix().allFinite()) return false;
  const Eigen::Matrix3d R = T.linear();
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-3 && R.determinant() > 0.0;
}

bool probabilityInRange(double p) { return std::isfinite(p) && p > 0.0 && p < 1.0; }

}  // namespace

const char* toString(VoxelState state) {
  switch (state) {
    case VoxelState::kUnknown: return "unknown";
    case VoxelState::kFree: return "free";
    case VoxelState::kOccupied: return "occupied";
    case VoxelState::kOutOfMap: return "out of map";
  }
  return "?";
}

bool OccupancyMap::Config::validate(std::string* why) const {
  std::ostringstream err;
  if (!(std::isfinite(resolution_m) && resolution_m > 0.0)) err << "resolution_m must be positive; ";
  if (!(size_m.allFinite() && (size_m.array() > 0.0).all())) err << "size_m must be positive; ";
  if (!origin_m.allFinite()) err << "origin_m must be finite; ";
  if (origin_m.allFinite() && resolution_m > 0.0 && (origin_m.array().abs() / resolution_m > double(kMaxOriginIndex)).any())
    err << "origin_m is too far from 0 for the voxel indices; ";
  for (double p : {prob_hit, prob_miss, prob_min, prob_max, prob_occupied})
    if (!probabilityInRange(p)) {
      err << "probabilities must be in (0, 1); ";
      break;
    }
  if (!(prob_hit > 0.5)) err << "prob_hit must exceed 0.5; ";
  if (!(prob_miss < 0.5)) err << "prob_miss must be below 0.5; ";
  if (!(prob_min < prob_occupied && prob_occupied < prob_max)) err << "need prob_min < prob_occupied < prob_max; ";
  if (!(std::isfinite(min_ray_length_m) && min_ray_length_m >= 0.0)) err << "min_ray_length_m must be >= 0; ";
  if (!(std::isfinite(max_ray_length_m) && max_ray_length_m > min_ray_length_m))
    err << "max_ray_length_m must exceed min_ray_length_m; ";
  if (depth_pixel_skip < 1) err << "depth_pixel_skip must be >= 1; ";
  if (max_image_pixels < 1) err << "max_image_pixels must be >= 1; ";
  if (!(max_memory_mb > 0.0)) err << "max_memory_mb must be positive; ";
  std::string s = err.str();
  if (s.empty() && resolution_m > 0.0) {
    const Eigen::Vector3d n = (size_m / resolution_m).array().ceil();
    if ((n.array() > 1e6).any()) {
      s = "size_m / resolution_m exceeds 1e6 voxels on an axis; ";
    } else {
      const double mb = n.prod() * double(kBytesPerVoxel) / (1024.0 * 1024.0);
      if (mb > max_memory_mb) {
        std::ostringstream m;
        m << "map of " << n.x() << " x " << n.y() << " x " << n.z() << " voxels needs " << mb
          << " MB, more than max_memory_mb = " << max_memory_mb << "; ";
        s = m.str();
      }
    }
  }
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

std::unique_ptr<OccupancyMap> OccupancyMap::create(const Config& config, std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid occupancy map config: " + why;
    return nullptr;
  }
  try {
    return std::unique_ptr<OccupancyMap>(new OccupancyMap(config));
  } catch (const std::bad_alloc&) {
    if (error) *error = "out of memory allocating the occupancy map";
    return nullptr;
  }
}

OccupancyMap::OccupancyMap(const Config& config) : config_(config) {
  const Eigen::Vector3i size = (config.size_m / config.resolution_m).array().ceil().cast<int>().max(1);
  const Eigen::Vector3i origin = (config.origin_m / config.resolution_m).array().round().cast<int>();
  geometry_ = GridGeometry(config.resolution_m, size, origin);
  hit_log_ = logit(config.prob_hit);
  miss_log_ = logit(config.prob_miss);
  min_log_ = logit(config.prob_min);
  max_log_ = logit(config.prob_max);
  occupied_log_ = logit(config.prob_occupied);
  unknown_value_ = min_log_ - 1.0f;
  unknown_threshold_ = min_log_ - 0.5f;
  log_odds_.assign(geometry_.numVoxels(), unknown_value_);
  stamp_.assign(geometry_.numVoxels(), 0u);
}

VoxelState OccupancyMap::state(const Eigen::Vector3i& index) const {
  if (!geometry_.inWindow(index)) return VoxelState::kOutOfMap;
  return stateOfValue(log_odds_[geometry_.address(index)]);
}

VoxelState OccupancyMap::state(const Eigen::Vector3d& point) const {
  if (!geometry_.inWindow(point)) return VoxelState::kOutOfMap;
  return state(geometry_.indexOf(point));
}

bool OccupancyMap::isKnownWithin(const Eigen::Vector3d& point, double radius,
                                 const std::function<bool(const Eigen::Vector3d&)>& assume_known) const {
  if (!(radius >= 0.0) || radius > kMaxKnownRadius || !geometry_.inWindow(point)) return false;
  const double half = 0.5 * geometry_.resolution(), r2 = radius * radius;
  const Eigen::Vector3i lo = geometry_.indexOf(point - Eigen::Vector3d::Constant(radius));
  const Eigen::Vector3i hi = geometry_.indexOf(point + Eigen::Vector3d::Constant(radius));
  Eigen::Vector3i i;
  for (i.z() = lo.z(); i.z() <= hi.z(); ++i.z()) {
    for (i.y() = lo.y(); i.y() <= hi.y(); ++i.y()) {
      for (i.x() = lo.x(); i.x() <= hi.x(); ++i.x()) {
        if (!geometry_.inWindow(i)) continue;
        // Distance from the point to the voxel's cube.
        const Eigen::Vector3d gap = ((point - geometry_.centerOf(i)).cwiseAbs().array() - half).max(0.0).matrix();
        if (gap.squaredNorm() >= r2 && !(i == geometry_.indexOf(point))) continue;
        if (isUnknownValue(log_odds_[geometry_.address(i)]) && !(assume_known && assume_known(geometry_.centerOf(i))))
          return false;
      }
    }
  }
  return true;
}

double OccupancyMap::probability(const Eigen::Vector3i& index) const {
  if (!geometry_.inWindow(index)) return std::numeric_limits<double>::quiet_NaN();
  const float l = log_odds_[geometry_.address(index)];
  if (isUnknownValue(l)) return std::numeric_limits<double>::quiet_NaN();
  return 1.0 / (1.0 + std::exp(-double(l)));
}

bool OccupancyMap::setState(const Eigen::Vector3i& index, VoxelState state) {
  if (!geometry_.inWindow(index)) return false;
  float& l = log_odds_[geometry_.address(index)];
  switch (state) {
    case VoxelState::kOccupied: l = max_log_; break;
    case VoxelState::kFree: l = min_log_; break;
    case VoxelState::kUnknown: l = unknown_value_; break;
    case VoxelState::kOutOfMap: return false;
  }
  return true;
}

void OccupancyMap::clear() { std::fill(log_odds_.begin(), log_odds_.end(), unknown_value_); }

size_t OccupancyMap::countState(VoxelState state) const {
  size_t n = 0;
  for (float l : log_odds_) n += stateOfValue(l) == state;
  return n;
}

void OccupancyMap::readSiteLineX(const Eigen::Vector3i& start, int n, bool unknown_is_site, uint8_t* out) const {
  // Consecutive x are consecutive addresses except where the ring buffer wraps.
  const int sx = geometry_.size().x();
  size_t addr = geometry_.address(start);
  const size_t row = addr - addr % size_t(sx);
  int ring_x = int(addr - row);
  for (int i = 0; i < n; ++i) {
    const float l = log_odds_[row + size_t(ring_x)];
    out[i] = isOccupiedValue(l) || (unknown_is_site && isUnknownValue(l));
    if (++ring_x == sx) ring_x = 0;
  }
}

VoxelBox OccupancyMap::setOriginIndex(const Eigen::Vector3i& origin_index) {
  const VoxelBox old_box = geometry_.windowBox();
  // Keep origin + size far from int overflow; such a window would be kilometres of voxels away.
  if ((origin_index.array().abs() > kMaxOriginIndex).any()) return VoxelBox();
  if (origin_index == geometry_.originIndex()) return VoxelBox();
  geometry_.setOriginIndex(origin_index);
  const VoxelBox new_box = geometry_.windowBox();
  // The storage slot of every entering voxel held a leaving one: reset those slots. The entering
  // voxels are the new window minus the old, covered by one slab per axis.
  for (int a = 0; a < 3; ++a) {
    VoxelBox slab = new_box;
    if (new_box.min[a] < old_box.min[a]) {
      slab.max[a] = std::min(new_box.max[a], old_box.min[a] - 1);
    } else if (new_box.max[a] > old_box.max[a]) {
      slab.min[a] = std::max(new_box.min[a], old_box.max[a] + 1);
    } else {
      continue;
    }
    Eigen::Vector3i i;
    for (i.z() = slab.min.z(); i.z() <= slab.max.z(); ++i.z())
      for (i.y() = slab.min.y(); i.y() <= slab.max.y(); ++i.y())
        for (i.x() = slab.min.x(); i.x() <= slab.max.x(); ++i.x()) {
          const size_t addr = geometry_.address(i);
          log_odds_[addr] = unknown_value_;
          stamp_[addr] = 0u;
        }
  }
  return new_box;
}

VoxelBox OccupancyMap::recenter(const Eigen::Vector3d& center) {
  if (!center.allFinite() || (center.array().abs() * geometry_.inverseResolution() > double(kMaxOriginIndex)).any())
    return VoxelBox();
  return setOriginIndex(geometry_.indexOf(center) - geometry_.size() / 2);
}

void OccupancyMap::beginFrame() {
  touched_.clear();
  ++frame_;
  if (frame_ >= (1u << 31)) {  // the stamp keeps the frame in 31 bits; restart before it wraps
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    frame_ = 1;
  }
}

void OccupancyMap::castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& end, bool is_hit,
                           FusionResult* result) {
  const uint32_t mark_free = frame_ << 1;
  const uint32_t mark_hit = mark_free | 1u;
  // A ray whose end is not finite carries no information (degenerate intrinsics: a direction of
  // infinite norm scaled by zero gives NaN), and its clipping would be NaN too.
  if (!origin.allFinite() || !end.allFinite()) return;
  // Most rays of a frame end in a voxel an earlier ray already ended in (hit) or freed (max-range
  // ray with merging): they would stop at their first voxel, so skip the clipping and DDA set-up.
  // The end's index only when it lies in the window: the int cast of a far end is undefined
  // (found by the depth_image and pointcloud2 fuzz harnesses).
  if (geometry_.inWindow(end)) {
    const Eigen::Vector3i end_index = geometry_.indexOf(end);
    const uint32_t s = stamp_[geometry_.address(end_index)];
    if ((is_hit && s == mark_hit) || (!is_hit && config_.merge_rays && s == mark_free)) return;
  }
  // Clip to the window, shrunk slightly so that clipped points fall inside the border voxels.
  const double eps = 1e-6 * geometry_.resolution();
  const Eigen::Vector3d lo = geometry_.windowMin().array() + eps;
  const Eigen::Vector3d hi = geometry_.windowMax().array() - eps;
  double t0, t1;
  if (!clipSegmentToBox(origin, end, lo, hi, &t0, &t1)) return;
  Eigen::Vector3d from = end;
  if (t1 < 1.0) {
    from = origin + t1 * (end - origin);
    is_hit = false;  // the return lies outside the window: its free part only
  }
  const Eigen::Vector3d to = origin + t0 * (end - origin);
  ++result->rays;
  bool first = true;
  traverseVoxels(from, to, geometry_.resolution(), [&](const Eigen::Vector3i& idx) {
    if (!geometry_.inWindow(idx)) return true;  // rounding at the clipped ends
    const size_t addr = geometry_.address(idx);
    uint32_t& s = stamp_[addr];
    const bool end_voxel = first;
    first = false;
    if (end_voxel && is_hit) {
      if (s == mark_hit) return false;  // another ray of this frame ended here: same ray, done
      if (s != mark_free) touched_.push_back({addr, idx});
      s = mark_hit;
      return true;
    }
    if (s == mark_hit) return true;  // never free a voxel this frame has hit
    if (s == mark_free) return !config_.merge_rays;
    s = mark_free;
    touched_.push_back({addr, idx});
    return true;
  });
}

void OccupancyMap::applyFrame(FusionResult* result) {
  const uint32_t mark_hit = (frame_ << 1) | 1u;
  for (const Touched& t : touched_) {
    float& l = log_odds_[t.address];
    const VoxelState before = stateOfValue(l);
    const bool hit = stamp_[t.address] == mark_hit;
    const float base = before == VoxelState::kUnknown ? 0.0f : l;
    l = std::min(max_log_, std::max(min_log_, base + (hit ? hit_log_ : miss_log_)));
    result->touched_box.extend(t.index);
    if (stateOfValue(l) != before) result->changed_box.extend(t.index);
    result->voxels_hit += hit;
  }
  result->voxels_updated = int(touched_.size());
  touched_.clear();
}

FusionResult OccupancyMap::fuseDepthImage(const DepthImageView& image, const PinholeCamera& camera,
                                          const Eigen::Isometry3d& T_world_camera) {
  FusionResult result;
  if (!validPose(T_world_camera)) {
    result.status = MapStatus::kInvalidPose;
    return result;
  }
  if (!camera.valid()) {
    result.status = MapStatus::kInvalidIntrinsics;
    return result;
  }
  if (image.data == nullptr || image.width <= 0 || image.height <= 0) {
    result.status = MapStatus::kEmptyImage;
    return result;
  }
  if (int64_t(image.width) * image.height > config_.max_image_pixels) {
    result.status = MapStatus::kImageTooLarge;
    return result;
  }
  if (image.width != camera.width || image.height != camera.height ||
      image.row_step_bytes < size_t(image.width) * image.bytesPerPixel()) {
    result.status = MapStatus::kImageSizeMismatch;
    return result;
  }
  if (!(std::isfinite(image.depth_scale) && image.depth_scale > 0.0)) {
    result.status = MapStatus::kInvalidIntrinsics;
    return result;
  }

  beginFrame();
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d origin = T_world_camera.translation();
  const double max_len = config_.max_ray_length_m, min_len = config_.min_ray_length_m;
  const int skip = config_.depth_pixel_skip;
  int valid = 0;
  for (int v = 0; v < image.height; v += skip) {
    const double y = (v - camera.cy) / camera.fy;
    for (int u = 0; u < image.width; u += skip) {
      const double depth = image.depthAt(u, v);
      if (std::isnan(depth) || depth <= 0.0) {  // NaN, -inf, zero: no information
        ++result.invalid;
        continue;
      }
      const Eigen::Vector3d ray((u - camera.cx) / camera.fx, y, 1.0);
      const double len_per_depth = ray.norm();
      double length = std::isinf(depth) ? INFINITY : depth * len_per_depth;
      if (length < min_len) {
        ++result.invalid;
        continue;
      }
      ++valid;
      const bool hit = length <= max_len;
      if (!hit) length = max_len;
      const Eigen::Vector3d end = origin + R * (ray * (length / len_per_depth));
      if (config_.project_free_space) {
        markRayEnd(origin, end, hit, &result);
      } else {
        castRay(origin, end, hit, &result);
      }
    }
  }
  if (valid == 0) {
    touched_.clear();
    result.status = MapStatus::kNoValidData;
    return result;
  }
  if (result.rays == 0) {
    touched_.clear();
    result.status = MapStatus::kOutOfMap;
    return result;
  }
  if (config_.project_free_space) projectFreeSpace(image, camera, T_world_camera);
  applyFrame(&result);
  return result;
}

void OccupancyMap::markRayEnd(const Eigen::Vector3d& origin, const Eigen::Vector3d& end, bool is_hit,
                              FusionResult* result) {
  if (!origin.allFinite() || !end.allFinite()) return;
  if (!geometry_.inWindow(end)) {
    // Only whether it meets the window (its free part, projected): a ray all outside is not one.
    const double eps = 1e-6 * geometry_.resolution();
    double t0, t1;
    if (clipSegmentToBox(origin, end, geometry_.windowMin().array() + eps, geometry_.windowMax().array() - eps, &t0, &t1))
      ++result->rays;
    return;
  }
  ++result->rays;
  if (!is_hit) return;
  const Eigen::Vector3i idx = geometry_.indexOf(end);
  const size_t addr = geometry_.address(idx);
  const uint32_t mark_hit = (frame_ << 1) | 1u;
  if (stamp_[addr] == mark_hit) return;
  stamp_[addr] = mark_hit;
  touched_.push_back({addr, idx});
}

void OccupancyMap::projectFreeSpace(const DepthImageView& image, const PinholeCamera& camera,
                                    const Eigen::Isometry3d& T_world_camera) {
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d origin = T_world_camera.translation();
  const double max_len = config_.max_ray_length_m, min_len = config_.min_ray_length_m, res = geometry_.resolution();
  // The view's bounding box: the camera and a 5 x 5 grid of directions over the image at max range,
  // padded by the sphere's bulge between them (under 3% of the range for views up to 120 degrees).
  Eigen::Vector3d lo = origin, hi = origin;
  for (int i = 0; i <= 4; ++i)
    for (int j = 0; j <= 4; ++j) {
      const Eigen::Vector3d ray(((camera.width - 1) * i / 4.0 - camera.cx) / camera.fx,
                                ((camera.height - 1) * j / 4.0 - camera.cy) / camera.fy, 1.0);
      const Eigen::Vector3d p = origin + R * (ray * (max_len / ray.norm()));
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  const double pad = 0.05 * max_len + res;
  lo.array() -= pad;
  hi.array() += pad;
  if (!lo.allFinite() || !hi.allFinite()) return;
  // Clipped to the window (in double first: a huge box would overflow the int indices).
  lo = lo.cwiseMax(geometry_.windowMin());
  hi = hi.cwiseMin(geometry_.windowMax() - Eigen::Vector3d::Constant(1e-6 * res));
  if ((lo.array() > hi.array()).any()) return;
  const Eigen::Vector3i ilo = geometry_.indexOf(lo), ihi = geometry_.indexOf(hi);

  const uint32_t mark_free = frame_ << 1, mark_hit = mark_free | 1u;
  const Eigen::Matrix3d Rt = R.transpose();
  const Eigen::Vector3d step_x = Rt * Eigen::Vector3d(res, 0.0, 0.0);
  const double max_len2 = max_len * max_len;
  const int w = camera.width, h = camera.height;
  // A pixel's depth when it is a valid measurement (no return: +inf); NaN otherwise.
  auto measured = [&](int u, int v) {
    const double d = image.depthAt(u, v);
    if (std::isnan(d) || d <= 0.0) return std::numeric_limits<double>::quiet_NaN();
    if (std::isinf(d)) return d;
    const double x = (u - camera.cx) / camera.fx, y = (v - camera.cy) / camera.fy;
    return d * std::sqrt(x * x + y * y + 1.0) < min_len ? std::numeric_limits<double>::quiet_NaN() : d;
  };
  Eigen::Vector3i i;
  for (i.z() = ilo.z(); i.z() <= ihi.z(); ++i.z())
    for (i.y() = ilo.y(); i.y() <= ihi.y(); ++i.y()) {
      i.x() = ilo.x();
      const Eigen::Vector3d pc0 = Rt * (geometry_.centerOf(i) - origin);  // voxel centre, camera frame
      // The row's voxels k = 0, 1, ... at pc0 + k step_x: the image's four edges and the depth's
      // sign are linear in k (A + B k >= 0), so the ones in view are an interval.
      double k_lo = 0.0, k_hi = ihi.x() - ilo.x();
      auto keep = [&](double A, double B) {
        if (std::abs(B) < 1e-12) {
          if (A < 0.0) k_hi = -1.0;
        } else if (B > 0.0) {
          k_lo = std::max(k_lo, -A / B);
        } else {
          k_hi = std::min(k_hi, -A / B);
        }
      };
      keep(pc0.z() - 1e-6, step_x.z());
      keep(camera.fx * pc0.x() + camera.cx * pc0.z(), camera.fx * step_x.x() + camera.cx * step_x.z());
      keep(-(camera.fx * pc0.x() + (camera.cx - (w - 1)) * pc0.z()),
           -(camera.fx * step_x.x() + (camera.cx - (w - 1)) * step_x.z()));
      keep(camera.fy * pc0.y() + camera.cy * pc0.z(), camera.fy * step_x.y() + camera.cy * step_x.z());
      keep(-(camera.fy * pc0.y() + (camera.cy - (h - 1)) * pc0.z()),
           -(camera.fy * step_x.y() + (camera.cy - (h - 1)) * step_x.z()));
      if (!(k_lo <= k_hi)) continue;
      const int k0 = std::max(0, int(std::ceil(k_lo)) - 1), k1 = std::min(ihi.x() - ilo.x(), int(std::floor(k_hi)) + 1);
      i.x() = ilo.x() + k0;
      Eigen::Vector3d pc = pc0 + double(k0) * step_x;
      for (; i.x() <= ilo.x() + k1; ++i.x(), pc += step_x) {
        if (pc.z() <= 1e-6 || pc.squaredNorm() > max_len2) continue;
        const double uf = camera.fx * pc.x() / pc.z() + camera.cx, vf = camera.fy * pc.y() / pc.z() + camera.cy;
        if (!(uf >= 0.0 && uf <= w - 1 && vf >= 0.0 && vf <= h - 1)) continue;
        // The nearest surface on the (up to) four pixels around the projection (a voxel on an
        // edge's near side is not freed by the background seen past it), at least half a voxel
        // behind the centre (a voxel a surface runs through, seen too obliquely for a hit in it,
        // is not freed either).
        const int u0 = int(uf), v0 = int(vf), u1 = std::min(u0 + 1, w - 1), v1 = std::min(v0 + 1, h - 1);
        double nearest = INFINITY;
        bool any = false;
        for (const double d : {measured(u0, v0), measured(u1, v0), measured(u0, v1), measured(u1, v1)})
          if (!std::isnan(d)) {
            any = true;
            nearest = std::min(nearest, d);
          }
        if (!any || pc.z() > nearest - 0.5 * res) continue;
        const size_t addr = geometry_.address(i);
        uint32_t& s = stamp_[addr];
        if (s == mark_free || s == mark_hit) continue;  // once a frame; hits win
        s = mark_free;
        touched_.push_back({addr, i});
      }
    }
}

FusionResult OccupancyMap::fusePointCloud(const std::vector<Eigen::Vector3d>& points_world,
                                          const Eigen::Vector3d& sensor_origin) {
  FusionResult result;
  if (!sensor_origin.allFinite()) {
    result.status = MapStatus::kInvalidPose;
    return result;
  }
  beginFrame();
  int valid = 0;
  for (const Eigen::Vector3d& p : points_world) {
    if (!p.allFinite()) {
      ++result.invalid;
      continue;
    }
    const Eigen::Vector3d d = p - sensor_origin;
    const double length = d.norm();
    if (length < config_.min_ray_length_m) {
      ++result.invalid;
      continue;
    }
    ++valid;
    if (length <= config_.max_ray_length_m) {
      castRay(sensor_origin, p, true, &result);
    } else {
      castRay(sensor_origin, sensor_origin + d * (config_.max_ray_length_m / length), false, &result);
    }
  }
  if (valid == 0 || result.rays == 0) {
    touched_.clear();
    result.status = valid == 0 ? MapStatus::kNoValidData : MapStatus::kOutOfMap;
    return result;
  }
  applyFrame(&result);
  return result;
}

}  // namespace topo_planner
