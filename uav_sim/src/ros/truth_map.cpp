#include "topo_planner/uav_sim/ros/truth_map.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "topo_planner/uav_sim/ros/conversions.h"

namespace topo_planner {

bool SimScenario::validate(std::string* why) const {
  std::ostringstream err;
  if (!start_m.allFinite()) err << "/sim/start_m must be finite; ";
  for (const Eigen::Vector3d& g : goals_m)
    if (!g.allFinite()) {
      err << "/sim/goals_m must be finite; ";
      break;
    }
  if (!(std::isfinite(map_resolution_m) && map_resolution_m >= 0.01 && map_resolution_m <= 10.0))
    err << "/sim/map_resolution_m must be in [0.01, 10]; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readSimScenario(SimScenario* scenario, std::string* why) {
  SimScenario s = *scenario;
  std::ostringstream err;
  auto readList = [&](const std::string& name, std::vector<double>* values) {
    if (!ros::param::has(name)) return false;
    if (!ros::param::get(name, *values)) {
      err << name << " must be a list of numbers; ";
      return false;
    }
    return true;
  };
  std::vector<double> v;
  if (readList("/sim/start_m", &v)) {
    if (v.size() == 3)
      s.start_m = Eigen::Vector3d(v[0], v[1], v[2]);
    else
      err << "/sim/start_m must hold 3 numbers; ";
  }
  if (readList("/sim/goals_m", &v)) {
    if (v.size() % 3 == 0) {
      s.goals_m.clear();
      for (size_t i = 0; i + 2 < v.size(); i += 3) s.goals_m.emplace_back(v[i], v[i + 1], v[i + 2]);
    } else {
      err << "/sim/goals_m must hold 3 numbers per goal; ";
    }
  }
  if (ros::param::has("/sim/map_resolution_m") && !ros::param::get("/sim/map_resolution_m", s.map_resolution_m))
    err << "/sim/map_resolution_m must be a number; ";
  std::string range;
  if (!s.validate(&range)) err << range << "; ";
  const std::string e = err.str();
  if (!e.empty()) {
    if (why) *why = e.substr(0, e.size() - 2);
    return false;
  }
  *scenario = s;
  return true;
}

TruthMap::Config truthMapConfig(const SimScenario& scenario, double margin_m, double esdf_max_distance_m) {
  TruthMap::Config c;
  c.resolution_m = scenario.map_resolution_m;
  c.margin_m = margin_m;
  c.include_points = scenario.goals_m;
  c.include_points.push_back(scenario.start_m);
  c.esdf.max_distance_m = esdf_max_distance_m;
  c.esdf.inflate_radius_m = std::min(c.esdf.inflate_radius_m, 0.5 * esdf_max_distance_m);
  return c;
}

bool truthMapFromCloud(const sensor_msgs::PointCloud2& cloud, const TruthMap::Config& config,
                       std::shared_ptr<const TruthMap>* map, std::string* error, TruthMap::BuildStats* stats) {
  std::vector<Eigen::Vector3d> points;
  std::string why;
  if (!cloudToPoints(cloud, &points, &why)) {
    if (error) *error = why;
    return false;
  }
  std::shared_ptr<const TruthMap> built = TruthMap::build(points, config, error, stats);
  if (!built) return false;
  *map = std::move(built);
  return true;
}

TruthMapSubscriber::TruthMapSubscriber(ros::NodeHandle nh, const std::string& topic, const TruthMap::Config& config,
                                       const std::string& node_name,
                                       std::function<void(const std::shared_ptr<const TruthMap>&)> on_map)
    : config_(config), node_name_(node_name), on_map_(std::move(on_map)) {
  sub_ = nh.subscribe(topic, 1, &TruthMapSubscriber::callback, this);
}

std::shared_ptr<const TruthMap> TruthMapSubscriber::map() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return map_;
}

void TruthMapSubscriber::callback(const sensor_msgs::PointCloud2ConstPtr& msg) {
  std::shared_ptr<const TruthMap> map;
  std::string error;
  TruthMap::BuildStats stats;
  if (!truthMapFromCloud(*msg, config_, &map, &error, &stats)) {
    ROS_ERROR("%s: cannot use the true map from %s: %s", node_name_.c_str(), sub_.getTopic().c_str(), error.c_str());
    return;
  }
  const GridGeometry& g = map->geometry();
  ROS_INFO("%s: true map: %zu occupied voxels of %.2f m, window [%.1f %.1f %.1f] - [%.1f %.1f %.1f], built in %.0f ms",
           node_name_.c_str(), stats.occupied_voxels, g.resolution(), g.windowMin().x(), g.windowMin().y(),
           g.windowMin().z(), g.windowMax().x(), g.windowMax().y(), g.windowMax().z(), stats.build_ms);
  if (stats.invalid_points > 0)
    ROS_WARN("%s: skipped %zu NaN/inf points of the global cloud", node_name_.c_str(), stats.invalid_points);
  if (stats.occupied_voxels == 0) ROS_WARN("%s: the global cloud is empty: no obstacles", node_name_.c_str());
  {
    std::lock_guard<std::mutex> lock(mutex_);
    map_ = map;
  }
  if (on_map_) on_map_(map);
}

}  // namespace topo_planner
