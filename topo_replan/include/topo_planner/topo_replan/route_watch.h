#pragma once
// The route check of a moving vehicle (ReplanFsm::Config::route_check_length_m): is the mission's
// global route ahead newly blocked on the map, by a wall the local planner cannot get round?
//
// The route is sampled at the map's resolution when it is searched, and each sample already within
// the safety clearance of a known obstacle then is noted (never news later). A check finds the
// vehicle on the route (the nearest sample within 20 m on from the last one found: a route that
// doubles back round a wall is not short-cut to its later part) and looks from 1 m ahead (the
// local planner's) up to check_length_m for a sample now within the safety clearance. Such a sample
// blocks the route only when no way past it lies within the local search's reach (kBypassM): no
// point of the obstacle's face (the plane through the sample across the distance field's gradient
// in front of it, i.e. along a wall however the route crosses it) within kBypassM of it, inside the
// height band and the map, at the route's clearance from every known obstacle. A tree, a pillar or
// a window near the route is the local planner's; a wall across the way needs a new route.
//
// Not thread-safe: the FSM calls it under its mutex.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

class RouteWatch {
 public:
  /// How far across an obstacle on the route the check looks for a way past it (the local search's
  /// reach: its sampling box extends 3.5 m to each side of the local segment) [m].
  static constexpr double kBypassM = 3.0;

  struct Config {
    double safety_clearance_m = 0.2;  ///< a sample within this of a known obstacle is blocked [m]
    double route_clearance_m = 0.4;   ///< a way past keeps the route's clearance [m]
    double min_z_m = -1e9;            ///< the route's height band [m] ...
    double max_z_m = 1e9;             ///< ... [m]
    double check_length_m = 12.0;     ///< how far along the route ahead it looks [m]
  };

  /// Where the route ahead is blocked.
  struct Blocked {
    double ahead_m = 0.0;  ///< along the route from the vehicle [m]
    Eigen::Vector3d where = Eigen::Vector3d::Zero();
    double distance_m = 0.0;  ///< the map's distance there [m]
  };

  explicit RouteWatch(const Config& config) : config_(config) {}
  void setConfig(const Config& config) { config_ = config; }

  /// A new route (empty: none), searched on `map`: sampled, and its samples already blocked noted.
  void reset(const Path& route, const EsdfMap& map);
  bool empty() const { return samples_.empty(); }

  /// The vehicle at `here` on `map`: the first sample ahead newly blocked with no way past; nullopt
  /// when the route ahead is clear (or passable by the local planner).
  std::optional<Blocked> check(const Eigen::Vector3d& here, const EsdfMap& map);

 private:
  bool blockedAt(const Eigen::Vector3d& p, const EsdfMap& map, double* distance) const;
  bool bypassed(size_t i, const EsdfMap& map) const;

  Config config_;
  std::vector<Eigen::Vector3d> samples_;
  std::vector<uint8_t> blocked_when_searched_;
  size_t at_ = 0;  // the sample the vehicle was last found nearest to
};

}  // namespace topo_planner
