#include "topo_planner/uav_sim/ros/map_generator_server.h"

#include <sensor_msgs/PointCloud2.h>

#include <chrono>
#include <cmath>
#include <map>
#include <sstream>

#include "topo_planner/plan_env/map_io.h"
#include "topo_planner/uav_sim/ros/conversions.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

namespace {
bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}
}  // namespace

bool MapGeneratorServer::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string core;
  if (!scenario.validate(&core)) err << core << "; ";
  if (map_file.empty()) {
    if (!forest.validate(&core)) err << core << "; ";
    if (!(area_min_m.allFinite() && area_max_m.allFinite() && (area_max_m - area_min_m).minCoeff() > 0.0))
      err << "area_min_m must be below area_max_m on every axis; ";
    else if ((area_max_m - area_min_m).maxCoeff() > 1e4)
      err << "the area is larger than 10 km; ";
  }
  if (!(std::isfinite(keep_free_radius_m) && keep_free_radius_m >= 0.0)) err << "keep_free_radius_m must be >= 0; ";
  if (frame_id.empty()) err << "frame_id must not be empty; ";
  if (!save_file.empty() && !endsWith(save_file, ".bt") && !endsWith(save_file, ".pcd"))
    err << "save_file must end in .bt or .pcd; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readMapGeneratorParams(const ros::NodeHandle& nh, MapGeneratorServer::Config* config) {
  MapGeneratorServer::Config& c = *config;
  ParamReader r(nh);
  std::string scenario_error;
  if (!readSimScenario(&c.scenario, &scenario_error)) r.errors() << scenario_error << "; ";
  r.read("map_file", c.map_file);
  r.read("density", c.density);
  if (c.density == "low") {
    c.forest = ForestConfig::preset(ObstacleDensity::kLow);
  } else if (c.density == "medium") {
    c.forest = ForestConfig::preset(ObstacleDensity::kMedium);
  } else if (c.density == "high") {
    c.forest = ForestConfig::preset(ObstacleDensity::kHigh);
  } else {
    r.errors() << "density must be low, medium or high, not '" << c.density << "'; ";
  }
  ForestConfig& f = c.forest;
  // The map style adds walls and/or rings to the density's pillars and floating boxes; explicit
  // walls_per_m2 / rings_per_m2 below override it.
  r.read("style", c.style);
  if (!f.applyStyle(c.style))
    r.errors() << "style must be forest, walls, rings, windows, boxes or mixed, not '" << c.style << "'; ";
  r.read("pillars_per_m2", f.pillars_per_m2);
  r.read("floating_per_m2", f.floating_per_m2);
  r.read("walls_per_m2", f.walls_per_m2);
  r.read("rings_per_m2", f.rings_per_m2);
  r.read("pillar_radius_min_m", f.pillar_radius_min_m);
  r.read("pillar_radius_max_m", f.pillar_radius_max_m);
  r.read("box_size_min_m", f.box_size_min_m);
  r.read("box_size_max_m", f.box_size_max_m);
  r.read("box_z_min_m", f.box_z_min_m);
  r.read("box_z_max_m", f.box_z_max_m);
  r.read("wall_length_min_m", f.wall_length_min_m);
  r.read("wall_length_max_m", f.wall_length_max_m);
  r.read("wall_thickness_m", f.wall_thickness_m);
  r.read("ring_radius_min_m", f.ring_radius_min_m);
  r.read("ring_radius_max_m", f.ring_radius_max_m);
  r.read("ring_tube_radius_m", f.ring_tube_radius_m);
  r.read("ring_z_min_m", f.ring_z_min_m);
  r.read("ring_z_max_m", f.ring_z_max_m);
  r.read("window_walls", f.window_walls);
  r.read("windows_min", f.windows_min);
  r.read("windows_max", f.windows_max);
  r.read("window_size_min_m", f.window_size_min_m);
  r.read("window_size_max_m", f.window_size_max_m);
  r.readUnsigned("seed", c.seed);
  r.readVector3("area_min_m", c.area_min_m);
  r.readVector3("area_max_m", c.area_max_m);
  r.read("keep_free_radius_m", c.keep_free_radius_m);
  r.read("frame_id", c.frame_id);
  r.read("save_file", c.save_file);
  // Obstacles stand on the area's floor and reach its ceiling; start and goals stay clear.
  f.ground_z_m = c.area_min_m.z();
  f.pillar_height_m = c.area_max_m.z() - c.area_min_m.z();
  f.keep_free = c.scenario.goals_m;
  f.keep_free.push_back(c.scenario.start_m);
  f.keep_free_radius_m = c.keep_free_radius_m;
  std::string range;
  c.validate(&range);
  return r.finish("map_generator", range);
}

std::unique_ptr<MapGeneratorServer> MapGeneratorServer::create(const ros::NodeHandle& nh, const Config& config,
                                                               std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid config: " + why;
    return nullptr;
  }
  std::unique_ptr<MapGeneratorServer> server(new MapGeneratorServer(nh, config));
  if (!(config.map_file.empty() ? server->generate(error) : server->load(error))) return nullptr;
  server->warnIfBlocked();
  if (!config.save_file.empty()) {
    const MapStatus status = endsWith(config.save_file, ".pcd")
                                 ? savePcdFile(*server->map_, config.save_file, &why)
                                 : saveOctomapFile(*server->map_, config.save_file, &why);
    if (status != MapStatus::kSuccess)
      ROS_ERROR("map_generator: cannot save %s: %s: %s", config.save_file.c_str(), toString(status), why.c_str());
    else
      ROS_INFO("map_generator: saved the map to %s", config.save_file.c_str());
  }
  sensor_msgs::PointCloud2 cloud;
  pointsToCloud(server->points_, config.frame_id, ros::Time::now(), &cloud);
  server->cloud_pub_ = server->nh_.advertise<sensor_msgs::PointCloud2>("global_cloud", 1, /*latch=*/true);
  server->cloud_pub_.publish(cloud);
  return server;
}

bool MapGeneratorServer::generate(std::string* error) {
  const auto t0 = std::chrono::steady_clock::now();
  OccupancyMap::Config mc;
  mc.resolution_m = config_.scenario.map_resolution_m;
  mc.origin_m = config_.area_min_m;
  mc.size_m = config_.area_max_m - config_.area_min_m;
  std::string why;
  map_ = OccupancyMap::create(mc, &why);
  if (!map_) {
    if (error) *error = "cannot create the forest window: " + why;
    return false;
  }
  std::vector<ForestObstacle> placed;
  generateForest(config_.forest, config_.seed, map_.get(), &placed);
  const GridGeometry& g = map_->geometry();
  map_->forEachOccupied([&](const Eigen::Vector3i& i) { points_.push_back(g.centerOf(i)); });
  std::map<ForestObstacle::Kind, int> count;
  for (const ForestObstacle& o : placed) ++count[o.kind];
  ROS_INFO(
      "map_generator: forest (%s, seed %u) over [%.1f %.1f %.1f] - [%.1f %.1f %.1f]: %d pillars, %d boxes, "
      "%d walls, %d rings, %zu occupied voxels of %.2f m, in %.0f ms",
      config_.density.c_str(), config_.seed, config_.area_min_m.x(), config_.area_min_m.y(), config_.area_min_m.z(),
      config_.area_max_m.x(), config_.area_max_m.y(), config_.area_max_m.z(), count[ForestObstacle::Kind::kPillar],
      count[ForestObstacle::Kind::kBox], count[ForestObstacle::Kind::kWall], count[ForestObstacle::Kind::kRing],
      points_.size(), g.resolution(),
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  return true;
}

bool MapGeneratorServer::load(std::string* error) {
  MapFile file;
  std::string why;
  const MapStatus status = readMapFile(config_.map_file, &file, &why);
  if (status != MapStatus::kSuccess) {
    if (error) *error = "cannot load map_file " + config_.map_file + ": " + toString(status) + ": " + why;
    return false;
  }
  OccupancyMap::Config base;
  base.resolution_m = config_.scenario.map_resolution_m;
  base.max_memory_mb = 2048.0;
  // One voxel of margin: a point on the bounds' upper faces lies in the voxel above them.
  map_ = OccupancyMap::create(configFittingMapFile(file, base, base.resolution_m), &why);
  if (!map_) {
    if (error) *error = "cannot hold map_file " + config_.map_file + ": " + why;
    return false;
  }
  const MapInsertStats ins = insertMapFile(file, map_.get());
  const GridGeometry& g = map_->geometry();
  map_->forEachOccupied([&](const Eigen::Vector3i& i) { points_.push_back(g.centerOf(i)); });
  ROS_INFO("map_generator: loaded %s: %zu occupied voxels of %.2f m over [%.1f %.1f %.1f] - [%.1f %.1f %.1f]",
           config_.map_file.c_str(), points_.size(), g.resolution(), g.windowMin().x(), g.windowMin().y(),
           g.windowMin().z(), g.windowMax().x(), g.windowMax().y(), g.windowMax().z());
  if (ins.clipped_cells > 0) ROS_WARN("map_generator: %zu cells were clipped", ins.clipped_cells);
  if (points_.empty()) ROS_WARN("map_generator: %s holds no occupied cell", config_.map_file.c_str());
  return true;
}

void MapGeneratorServer::warnIfBlocked() const {
  std::vector<std::pair<std::string, Eigen::Vector3d>> keep{{"start", config_.scenario.start_m}};
  for (size_t i = 0; i < config_.scenario.goals_m.size(); ++i)
    keep.emplace_back("goal " + std::to_string(i + 1), config_.scenario.goals_m[i]);
  // Voxel centres; the generator's boxes may reach one voxel beyond their nominal extent, hence
  // the one-voxel tolerance.
  const double tolerance = config_.scenario.map_resolution_m;
  for (const auto& k : keep) {
    double nearest = INFINITY;
    for (const Eigen::Vector3d& p : points_) nearest = std::min(nearest, (p - k.second).norm());
    if (nearest < config_.keep_free_radius_m - tolerance)
      ROS_WARN(
          "map_generator: an occupied voxel centre lies %.2f m from the %s (%.2f %.2f %.2f), closer than "
          "keep_free_radius_m = %.2f",
          nearest, k.first.c_str(), k.second.x(), k.second.y(), k.second.z(), config_.keep_free_radius_m);
  }
}

}  // namespace topo_planner
