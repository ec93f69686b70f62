#pragma once
// The true map of the closed-loop simulation: the obstacle points of the map generator (the centres
// of its occupied voxels) as an all-known voxel map (every other voxel free) with its ESDF. The
// simulated depth camera renders it, the quadrotor simulator checks the body for collisions against
// it, and the flight monitor measures clearance on it.
//
// Window: the bounding box of the obstacle points and of `include_points` (start, goals: where the
// vehicle will be, since the depth camera sees nothing from outside the window), plus margin_m on
// every side. Every obstacle lies inside, so a point outside the window is at least its distance to
// the window from any obstacle.
//
// Thread safety: immutable after build(); share it as std::shared_ptr<const TruthMap>.

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/occupancy_map.h"

namespace topo_planner {

class TruthMap {
 public:
  struct Config {
    double resolution_m = 0.1;                    ///< voxel edge (/sim/map_resolution_m) [m]
    double margin_m = 1.5;                        ///< free space around the points' bounding box [m]
    std::vector<Eigen::Vector3d> include_points;  ///< points the window must contain (start, goals) [m]
    EsdfMap::Config esdf;           ///< ESDF truncation and threads (2 m: long sphere-tracing steps for the camera)
    double max_memory_mb = 2048.0;  ///< refuse windows larger than this (e.g. a stray point far away) [MB]

    bool validate(std::string* why) const;
  };
  struct BuildStats {
    size_t points = 0;           ///< points given
    size_t invalid_points = 0;   ///< NaN/inf points, skipped
    size_t occupied_voxels = 0;  ///< distinct occupied voxels
    double build_ms = 0.0;       ///< wall time of the build, ESDF included [ms]
  };

  /// nullptr with a reason if the config is invalid or the window does not fit max_memory_mb.
  /// An empty point set gives an obstacle-free map around the include points (or the origin).
  static std::shared_ptr<const TruthMap> build(const std::vector<Eigen::Vector3d>& obstacle_points,
                                               const Config& config, std::string* error, BuildStats* stats = nullptr);

  const OccupancyMap& occupancy() const { return *occupancy_; }
  const EsdfMap& esdf() const { return *esdf_; }
  std::shared_ptr<const OccupancyMap> occupancyPtr() const { return occupancy_; }
  const GridGeometry& geometry() const { return occupancy_->geometry(); }
  size_t numOccupied() const { return occupied_; }

  /// Distance from p to the nearest occupied voxel (the solid cube, 0 inside one) [m]. A result
  /// below exact_within_m is exact; a result r >= exact_within_m only says the true distance is at
  /// least r. NaN for a non-finite p.
  ///
  /// Broad phase on the ESDF: if the voxel holding p has centre c at distance d from the nearest
  /// occupied voxel centre, every occupied centre is at least d - |p - c| from p, and every point of
  /// an occupied cube at least d - |p - c| - sqrt(3)/2 res. When that bound reaches exact_within_m
  /// (the usual case, a few operations) it is returned; otherwise the narrow phase measures the
  /// exact point-to-cube distance to every occupied voxel within exact_within_m of p.
  double obstacleDistance(const Eigen::Vector3d& p, double exact_within_m) const;
  /// True when a sphere of radius_m centred at p overlaps an occupied voxel (exact). Fills the
  /// distance of obstacleDistance(p, radius_m) if asked.
  bool sphereInCollision(const Eigen::Vector3d& p, double radius_m, double* distance_m = nullptr) const;

 private:
  TruthMap() = default;
  std::shared_ptr<OccupancyMap> occupancy_;
  std::unique_ptr<EsdfMap> esdf_;
  size_t occupied_ = 0;
};

/// Counts a body's contacts with the world from its clearance, with hysteresis: a contact begins when
/// the clearance falls below radius_m and ends only once it is back above radius_m + release_m. A body
/// resting at a surface (its clearance jittering around the radius by the controller's sub-millimetre
/// corrections) is one contact, not one per crossing; leaving by release_m and entering again is two.
/// A NaN clearance (no position) changes nothing.
class ContactCounter {
 public:
  ContactCounter(double radius_m, double release_m) : radius_m_(radius_m), release_m_(release_m) {}
  /// True when this clearance begins a new contact.
  bool update(double clearance_m) {
    if (std::isnan(clearance_m)) return false;
    if (!in_contact_) return in_contact_ = clearance_m < radius_m_;
    if (clearance_m > radius_m_ + release_m_) in_contact_ = false;
    return false;
  }
  bool inContact() const { return in_contact_; }
  /// The distance within which the clearance must be exact to decide (TruthMap::obstacleDistance).
  double exactWithin() const { return radius_m_ + release_m_; }

 private:
  double radius_m_, release_m_;
  bool in_contact_ = false;
};

}  // namespace topo_planner
