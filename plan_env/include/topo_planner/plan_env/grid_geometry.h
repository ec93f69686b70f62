#pragma once
// Voxel indexing shared by every layer of the map.
//
// Voxels are addressed by *global* integer indices: voxel i spans [i*res, (i+1)*res) on each axis,
// so its centre is (i + 0.5) * res, the same convention as OctoMap keys. The map holds a window of
// size() voxels whose lowest voxel is originIndex(). Storage is a 3-D ring buffer (as in Ewok,
// Usenko et al. IROS 2017): a global index lives at address (index mod size) per axis, so moving
// the window (setOriginIndex) never moves memory; only the voxels that enter must be reset.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace topo_planner {

/// Inclusive box of global voxel indices. Empty when min > max on any axis.
struct VoxelBox {
  Eigen::Vector3i min = Eigen::Vector3i::Constant(1);
  Eigen::Vector3i max = Eigen::Vector3i::Constant(0);

  static VoxelBox fromCorners(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi) {
    VoxelBox b;
    b.min = lo;
    b.max = hi;
    return b;
  }
  bool empty() const { return (min.array() > max.array()).any(); }
  bool contains(const Eigen::Vector3i& i) const {
    return (i.array() >= min.array()).all() && (i.array() <= max.array()).all();
  }
  Eigen::Vector3i size() const {
    return empty() ? Eigen::Vector3i::Zero() : Eigen::Vector3i(max - min + Eigen::Vector3i::Ones());
  }
  int64_t volume() const {
    const Eigen::Vector3i s = size();
    return int64_t(s.x()) * s.y() * s.z();
  }
  /// Grows the box to contain voxel i.
  void extend(const Eigen::Vector3i& i) {
    if (empty()) {
      min = max = i;
    } else {
      min = min.cwiseMin(i);
      max = max.cwiseMax(i);
    }
  }
  void merge(const VoxelBox& o) {
    if (o.empty()) return;
    if (empty()) {
      *this = o;
    } else {
      min = min.cwiseMin(o.min);
      max = max.cwiseMax(o.max);
    }
  }
  VoxelBox inflated(int margin) const {
    if (empty()) return *this;
    return fromCorners(min - Eigen::Vector3i::Constant(margin), max + Eigen::Vector3i::Constant(margin));
  }
  VoxelBox intersection(const VoxelBox& o) const {
    return fromCorners(min.cwiseMax(o.min), max.cwiseMin(o.max));
  }
  bool operator==(const VoxelBox& o) const {
    return (empty() && o.empty()) || (min == o.min && max == o.max);
  }
};

/// Resolution, window and ring-buffer addressing of a voxel grid. Plain value; cheap to copy.
class GridGeometry {
 public:
  GridGeometry() = default;
  GridGeometry(double resolution_m, const Eigen::Vector3i& size_voxels, const Eigen::Vector3i& origin_index);

  double resolution() const { return resolution_; }
  double inverseResolution() const { return inv_resolution_; }
  const Eigen::Vector3i& size() const { return size_; }
  const Eigen::Vector3i& originIndex() const { return origin_; }
  size_t numVoxels() const { return size_t(size_.x()) * size_.y() * size_.z(); }

  /// Global index of the voxel containing p.
  Eigen::Vector3i indexOf(const Eigen::Vector3d& p) const {
    return (p * inv_resolution_).array().floor().cast<int>();
  }
  Eigen::Vector3d centerOf(const Eigen::Vector3i& i) const {
    return (i.cast<double>().array() + 0.5).matrix() * resolution_;
  }
  VoxelBox windowBox() const { return VoxelBox::fromCorners(origin_, origin_ + size_ - Eigen::Vector3i::Ones()); }
  /// Metric bounds of the window (lower corner of the first voxel, upper corner of the last).
  Eigen::Vector3d windowMin() const { return origin_.cast<double>() * resolution_; }
  Eigen::Vector3d windowMax() const { return (origin_ + size_).cast<double>() * resolution_; }

  bool inWindow(const Eigen::Vector3i& i) const {
    const Eigen::Vector3i l = i - origin_;
    return (l.array() >= 0).all() && (l.array() < size_.array()).all();
  }
  /// False for NaN/inf points as well as points outside the window.
  bool inWindow(const Eigen::Vector3d& p) const {
    if (!p.allFinite()) return false;
    const Eigen::Vector3d q = p * inv_resolution_;
    if ((q.array() < -1e9).any() || (q.array() > 1e9).any()) return false;
    return inWindow(indexOf(p));
  }

  /// Storage address of a global index. Precondition: inWindow(i).
  size_t address(const Eigen::Vector3i& i) const {
    return size_t(wrap(i.x(), 0)) + size_t(size_.x()) * (size_t(wrap(i.y(), 1)) + size_t(size_.y()) * wrap(i.z(), 2));
  }

  /// Moves the window. Storage slots of voxels that leave are reused by the voxels that enter;
  /// the owner of the data must reset them (OccupancyMap::setOriginIndex does).
  void setOriginIndex(const Eigen::Vector3i& origin_index);

 private:
  // Ring-buffer coordinate of global index g on axis a, without a division: local + offset, wrapped once.
  int wrap(int g, int a) const {
    int s = g - origin_[a] + offset_[a];
    return s >= size_[a] ? s - size_[a] : s;
  }

  double resolution_ = 0.1;
  double inv_resolution_ = 10.0;
  Eigen::Vector3i size_ = Eigen::Vector3i::Zero();
  Eigen::Vector3i origin_ = Eigen::Vector3i::Zero();
  Eigen::Vector3i offset_ = Eigen::Vector3i::Zero();  // origin mod size, in [0, size)
};

}  // namespace topo_planner
