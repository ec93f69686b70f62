#pragma once
// Map files at the edge of the mapping core: OctoMap (.bt binary, .ot full) and PCD point clouds.
//
// Reading is separate from inserting so that a file that does not parse never touches the map.
// OctoMap leaves of any size are expanded to the grid: every voxel whose centre lies in the leaf
// takes its state (a leaf smaller than a voxel sets the voxel holding its centre). PCD points mark
// the voxel that contains them occupied. Library exceptions are caught here and become a status.

#include <string>
#include <vector>

#include "topo_planner/plan_env/occupancy_map.h"

namespace topo_planner {

/// An axis-aligned cube of known state read from a map file (edge 0 for a point).
struct MapCell {
  Eigen::Vector3d center;
  double size_m = 0.0;
  bool occupied = true;
};

struct MapFile {
  std::vector<MapCell> cells;
  double resolution_m = 0.0;  ///< of the source octree; 0 for point clouds
  Eigen::Vector3d min = Eigen::Vector3d::Zero();  ///< bounds of all cells [m]
  Eigen::Vector3d max = Eigen::Vector3d::Zero();
  size_t numOccupied() const;
};

/// Reads .bt, .ot or .pcd, chosen by the file extension.
MapStatus readMapFile(const std::string& path, MapFile* out, std::string* error);
MapStatus readOctomapFile(const std::string& path, MapFile* out, std::string* error);
MapStatus readPcdFile(const std::string& path, MapFile* out, std::string* error);

struct MapInsertStats {
  size_t occupied_voxels = 0;  ///< voxels set occupied
  size_t free_voxels = 0;      ///< voxels set free
  size_t clipped_cells = 0;    ///< cells that lie (partly) outside the window
  VoxelBox changed_box;        ///< feed to EsdfMap::update
};

/// Writes the cells into the map: free cells first, then occupied ones (occupied wins).
MapInsertStats insertMapFile(const MapFile& file, OccupancyMap* map);

/// `base` with origin and size set to the file's bounds plus `margin_m` on every side.
OccupancyMap::Config configFittingMapFile(const MapFile& file, const OccupancyMap::Config& base, double margin_m);

/// Saves known voxels (occupied and free) as an OctoMap binary tree at the map's resolution.
MapStatus saveOctomapFile(const OccupancyMap& map, const std::string& path, std::string* error);
/// Saves occupied voxel centres as a binary PCD (pcl::PointXYZ).
MapStatus savePcdFile(const OccupancyMap& map, const std::string& path, std::string* error);

}  // namespace topo_planner
