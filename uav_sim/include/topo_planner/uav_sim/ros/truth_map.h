#pragma once
// The simulation's shared ROS plumbing around the true map (uav_sim/truth_map.h): the scenario
// parameters every node reads (/sim/*), the conversion of the map generator's global cloud into a
// TruthMap, and a subscriber that keeps the latest one. Used by the depth camera and the quadrotor
// simulator, and meant for any other consumer of the true map (e.g. the flight monitor):
//
//   SimScenario scenario;
//   if (!readSimScenario(&scenario, &why)) ...;
//   TruthMapSubscriber truth(nh, "/map_generator/global_cloud", truthMapConfig(scenario), "monitor");
//   ... if (auto map = truth.map()) map->obstacleDistance(p, 1.0);

#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "topo_planner/uav_sim/truth_map.h"

namespace topo_planner {

/// The scenario of a closed-loop flight: global parameters set once by the launch file.
struct SimScenario {
  Eigen::Vector3d start_m{-15.0, 0.0, 1.0};  ///< /sim/start_m: the quadrotor starts hovering here [m]
  std::vector<Eigen::Vector3d> goals_m{{15.0, 5.0, 1.0}, {-15.0, -5.0, 1.0}, {15.0, -4.0, 1.0}};  ///< /sim/goals_m [m]
  double map_resolution_m = 0.1;  ///< /sim/map_resolution_m: voxel edge of the true map [m]

  bool validate(std::string* why) const;
};

/// Reads /sim/start_m [x, y, z], /sim/goals_m [x1, y1, z1, x2, ...] and /sim/map_resolution_m;
/// missing ones keep the defaults above. False with the reason for wrong types or invalid values.
bool readSimScenario(SimScenario* scenario, std::string* why);

/// TruthMap config for the scenario: its resolution, the start and the goals kept inside the window,
/// margin_m around everything, and the given ESDF truncation [m].
TruthMap::Config truthMapConfig(const SimScenario& scenario, double margin_m = 1.5, double esdf_max_distance_m = 2.0);

/// Global cloud (FLOAT32 x, y, z: centres of occupied voxels) -> TruthMap. An empty cloud gives an
/// obstacle-free map. False (map untouched) with the reason for a malformed cloud or a window that
/// does not fit config.max_memory_mb.
bool truthMapFromCloud(const sensor_msgs::PointCloud2& cloud, const TruthMap::Config& config,
                       std::shared_ptr<const TruthMap>* map, std::string* error, TruthMap::BuildStats* stats = nullptr);

/// Keeps the TruthMap of the latest cloud on a topic (the map generator publishes it latched, so it
/// arrives once at start). The build (an ESDF over the window, about a second for the default
/// scenario) runs in the callback: give `nh` its own callback queue if that must not block others.
/// Thread safety: map() may be called from any thread.
class TruthMapSubscriber {
 public:
  /// on_map (optional) is called from the callback thread after each new map.
  TruthMapSubscriber(ros::NodeHandle nh, const std::string& topic, const TruthMap::Config& config,
                     const std::string& node_name,
                     std::function<void(const std::shared_ptr<const TruthMap>&)> on_map = nullptr);
  /// The latest map; nullptr until the first valid cloud.
  std::shared_ptr<const TruthMap> map() const;

 private:
  void callback(const sensor_msgs::PointCloud2ConstPtr& msg);

  TruthMap::Config config_;
  std::string node_name_;
  std::function<void(const std::shared_ptr<const TruthMap>&)> on_map_;
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::shared_ptr<const TruthMap> map_;
};

}  // namespace topo_planner
