#include "topo_planner/plan_manage/flight_oracle.h"

#include <cmath>

#include "topo_planner/path_searching/global_router.h"
#include "topo_planner/topo_replan/path_speed_profile.h"

namespace topo_planner {

bool FlightOracle::Config::validate(std::string* why) const {
  std::string e;
  if (!(std::isfinite(clearance_m) && clearance_m >= 0.0)) e += "clearance_m must be >= 0; ";
  if (!(std::isfinite(min_z_m) && std::isfinite(max_z_m) && min_z_m < max_z_m)) e += "min_z_m must be below max_z_m; ";
  if (!(std::isfinite(max_vel_mps) && max_vel_mps > 0.0)) e += "max_vel_mps must be positive; ";
  if (!(std::isfinite(max_acc_mps2) && max_acc_mps2 > 0.0)) e += "max_acc_mps2 must be positive; ";
  if (max_expansions < 1) e += "max_expansions must be positive; ";
  if (why) *why = e.empty() ? "" : e.substr(0, e.size() - 2);
  return e.empty();
}

FlightOracle::Result FlightOracle::compute(const EsdfMap& truth, const Eigen::Vector3d& start,
                                           const std::vector<Eigen::Vector3d>& goals, const Config& config) {
  Result r;
  std::string why;
  if (!config.validate(&why)) {
    r.why = "invalid config: " + why;
    return r;
  }
  if (goals.empty()) {
    r.why = "no goals";
    return r;
  }
  GlobalRouter::Config rc;
  rc.clearance_m = config.clearance_m;
  rc.unknown_is_free = false;
  rc.clearance_weight = 0.0;  // length alone
  rc.heuristic_weight = 1.0;
  rc.min_z_m = config.min_z_m;
  rc.max_z_m = config.max_z_m;
  rc.max_expansions = config.max_expansions;
  if (!rc.validate(&why)) {
    r.why = "invalid route config: " + why;
    return r;
  }
  GlobalRouter router(rc);
  PathSpeedProfile::Config pc;
  pc.max_vel_mps = config.max_vel_mps;
  pc.max_acc_mps2 = config.max_acc_mps2;
  pc.step_m = 0.02;

  Eigen::Vector3d from = start;
  std::vector<Eigen::Vector3d> through;  // pass_through: the whole path
  std::vector<size_t> goal_index;        // ... and the index of each goal in it
  for (size_t i = 0; i < goals.size(); ++i) {
    const GlobalRouter::Result route = router.route(truth, from, goals[i]);
    if (route.status != SearchStatus::kSuccess) {
      r.why = "no route to goal " + std::to_string(i + 1) + ": " + toString(route.status);
      return r;
    }
    r.routes.push_back(route.path);
    if (config.pass_through) {
      for (const Eigen::Vector3d& p : route.path)
        if (through.empty() || (p - through.back()).norm() > 1e-6) through.push_back(p);
      goal_index.push_back(through.size() - 1);
    } else {
      const auto profile = PathSpeedProfile::compute(route.path, pc, 0.0, 0.0, &why);
      if (!profile) {
        r.why = "no speed profile to goal " + std::to_string(i + 1) + ": " + why;
        return r;
      }
      r.length_m.push_back(profile->length());
      r.time_s.push_back(profile->duration());
      r.total_s += profile->duration();
    }
    from = goals[i];
  }
  if (config.pass_through) {
    const auto profile = PathSpeedProfile::compute(through, pc, 0.0, 0.0, &why);
    if (!profile) {
      r.why = "no speed profile: " + why;
      return r;
    }
    // Distinct waypoints only: the profile's waypoint times follow `through` one to one.
    double t_prev = 0.0;
    for (const size_t k : goal_index) {
      const double t = profile->waypointTimes()[k];
      r.time_s.push_back(t - t_prev);
      r.length_m.push_back(NAN);
      t_prev = t;
    }
    r.total_s = profile->duration();
  }
  r.ok = true;
  return r;
}

FlightOracle::Result FlightOracle::computeInWindow(const OccupancyMap& truth, const Eigen::Vector3d& window_origin_m,
                                                   const Eigen::Vector3d& window_size_m, const Eigen::Vector3d& start,
                                                   const std::vector<Eigen::Vector3d>& goals, const Config& config) {
  Result r;
  OccupancyMap::Config mc;
  mc.resolution_m = truth.geometry().resolution();
  mc.origin_m = window_origin_m;
  mc.size_m = window_size_m;
  std::string why;
  std::shared_ptr<OccupancyMap> map(OccupancyMap::create(mc, &why));
  if (!map) {
    r.why = "oracle window: " + why;
    return r;
  }
  const GridGeometry& g = map->geometry();
  const VoxelBox box = g.windowBox();
  Eigen::Vector3i i;
  for (i.z() = box.min.z(); i.z() <= box.max.z(); ++i.z())
    for (i.y() = box.min.y(); i.y() <= box.max.y(); ++i.y())
      for (i.x() = box.min.x(); i.x() <= box.max.x(); ++i.x()) map->setState(i, VoxelState::kFree);
  truth.forEachOccupied([&](const Eigen::Vector3i& j) {
    const Eigen::Vector3d p = truth.geometry().centerOf(j);
    if (g.inWindow(p)) map->setState(g.indexOf(p), VoxelState::kOccupied);
  });
  EsdfMap::Config ec;
  ec.max_distance_m = 2.0;
  std::unique_ptr<EsdfMap> esdf = EsdfMap::create(ec, map, &why);
  if (!esdf) {
    r.why = "oracle window: " + why;
    return r;
  }
  esdf->updateAll();
  return compute(*esdf, start, goals, config);
}

}  // namespace topo_planner
