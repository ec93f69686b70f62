#pragma once
// MapGeneratorServer: the true world of the simulation. Builds the obstacle map once at start, either
// a seeded random forest (plan_env/map_generator.h: pillars and floating boxes, optionally walls and
// rings) over the forest area with free space kept around the start and every goal, or a map file
// (.bt/.ot/.pcd via plan_env/map_io.h), and publishes its occupied voxel centres latched. The node
// `map_generator_node` runs one.
//
// Topics
//   Published   ~global_cloud  sensor_msgs/PointCloud2, latched, frame_id, FLOAT32 x y z = centres of
//                              the occupied voxels at /sim/map_resolution_m (/map_generator/global_cloud
//                              for a node named map_generator)
//
// Parameters (private unless absolute; defaults are the Config defaults below)
//   /sim/start_m, /sim/goals_m, /sim/map_resolution_m   the scenario (uav_sim/ros/truth_map.h)
//   map_file             ""        .bt/.ot/.pcd to load instead of generating; unreadable -> exit
//   density              "medium"  low | medium | high: the benchmark presets of plan_env
//   pillars_per_m2       preset    explicit density, overrides the preset [1/m^2]
//   floating_per_m2      preset    explicit density of floating boxes [1/m^2]
//   style                "forest"  forest | walls | rings | mixed: walls (0.02 per m^2), rings (0.02)
//                                  or both (0.01 each) added to the density's obstacles
//   walls_per_m2         style     walls (thin slabs on the ground, random heading) [1/m^2]
//   rings_per_m2         style     floating vertical rings (gates) [1/m^2]
//   seed                 1         random seed (>= 0)
//   area_min_m, area_max_m  [-12, -10, 0], [12, 10, 3]  the forest area; obstacles stand from
//                                  area_min_m.z to area_max_m.z [m]
//   keep_free_radius_m   1.5       no obstacle within this of the start and the goals [m]
//   pillar_radius_min_m/max_m, box_size_min_m/max_m, box_z_min_m/max_m, wall_length_min_m/max_m,
//   wall_thickness_m, ring_radius_min_m/max_m, ring_tube_radius_m, ring_z_min_m/max_m
//                                  obstacle sizes (plan_env ForestConfig) [m]
//   frame_id             "world"   frame of the cloud
//   save_file            ""        also write the map there (.bt OctoMap or .pcd by extension)
//
// Invalid parameters or an unreadable map file stop the node with a ROS_ERROR saying why.

#include <ros/ros.h>

#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_env/map_generator.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/uav_sim/ros/truth_map.h"

namespace topo_planner {

class MapGeneratorServer {
 public:
  struct Config {
    SimScenario scenario;            ///< start, goals and resolution (/sim/*)
    std::string map_file;            ///< load this instead of generating; empty = generate
    std::string density = "medium";
    /// forest (pillars and floating boxes) | walls (+ 0.02 walls per m^2) | rings (+ 0.02 rings per
    /// m^2) | mixed (+ 0.01 of each)
    std::string style = "forest";  ///< low | medium | high preset (overridden by explicit densities)
    ForestConfig forest = ForestConfig::preset(ObstacleDensity::kMedium);  ///< densities and sizes
    uint32_t seed = 1;                                                     ///< random seed of the forest
    Eigen::Vector3d area_min_m{-12.0, -10.0, 0.0};                         ///< lower corner of the forest area [m]
    Eigen::Vector3d area_max_m{12.0, 10.0, 3.0};  ///< upper corner; obstacles reach its height [m]
    double keep_free_radius_m = 1.5;              ///< obstacle-free radius around start and goals [m]
    std::string frame_id = "world";               ///< frame of the published cloud
    std::string save_file;                        ///< also save the map (.bt or .pcd); empty = no

    bool validate(std::string* why) const;
  };

  /// Builds the map and publishes it latched on ~global_cloud of `nh` (the private handle). nullptr
  /// with a reason if it cannot be built.
  static std::unique_ptr<MapGeneratorServer> create(const ros::NodeHandle& nh, const Config& config,
                                                    std::string* error);

  /// Occupied voxel centres of the map (what ~global_cloud carries).
  const std::vector<Eigen::Vector3d>& obstaclePoints() const { return points_; }

 private:
  MapGeneratorServer(const ros::NodeHandle& nh, const Config& config) : nh_(nh), config_(config) {}
  bool generate(std::string* error);
  bool load(std::string* error);
  void warnIfBlocked() const;

  ros::NodeHandle nh_;
  Config config_;
  std::unique_ptr<OccupancyMap> map_;
  std::vector<Eigen::Vector3d> points_;
  ros::Publisher cloud_pub_;
};

/// Reads the parameters into *config (defaults: the values already there); false with a ROS_ERROR
/// when any is invalid.
bool readMapGeneratorParams(const ros::NodeHandle& nh, MapGeneratorServer::Config* config);

}  // namespace topo_planner
