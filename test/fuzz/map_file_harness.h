#pragma once
// Shared body of the map file harnesses (octomap_fuzz, pcd_fuzz): the fuzz bytes become a file with
// the given extension, read by readMapFile (plan_env/map_io.h) as the mapping node's map_file and the
// benchmarks' --map are, then inserted the two ways the project does: into a fixed window (the
// mapping node) and into a map fitted to the file (bench_replan, map_demo) under a small memory bound.

#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_input.h"
#include "topo_planner/plan_env/map_io.h"

namespace topo_planner {
namespace fuzz {

inline int fuzzMapFile(const uint8_t* data, size_t size, const std::string& ext) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("topo_planner_fuzz_" + std::to_string(::getpid()) + "." + ext)).string();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  }
  MapFile file;
  std::string why;
  const MapStatus status = readMapFile(path, &file, &why);
  std::filesystem::remove(path);
  if (status != MapStatus::kSuccess) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return 0;
  }
  TOPO_PLANNER_FUZZ_CHECK(file.numOccupied() <= file.cells.size());
  for (const MapCell& c : file.cells) TOPO_PLANNER_FUZZ_CHECK(c.center.allFinite() && std::isfinite(c.size_m));

  // The mapping node: a fixed window (config/mapping.yaml's resolution, a smaller extent).
  OccupancyMap::Config window;
  window.resolution_m = 0.1;
  window.size_m = Eigen::Vector3d(8.0, 8.0, 3.0);
  window.origin_m = Eigen::Vector3d(-4.0, -4.0, -0.5);
  std::unique_ptr<OccupancyMap> map = OccupancyMap::create(window, &why);
  TOPO_PLANNER_FUZZ_CHECK(map != nullptr);
  const MapInsertStats ins = insertMapFile(file, map.get());
  TOPO_PLANNER_FUZZ_CHECK(ins.occupied_voxels + ins.free_voxels <= size_t(map->geometry().windowBox().volume()) * 2);

  // The benchmarks: a map fitted to the file, refused when larger than max_memory_mb.
  OccupancyMap::Config base;
  base.resolution_m = 0.2;
  base.max_memory_mb = 16.0;
  std::unique_ptr<OccupancyMap> fitted = OccupancyMap::create(configFittingMapFile(file, base, 0.5), &why);
  if (fitted) insertMapFile(file, fitted.get());
  return 0;
}

}  // namespace fuzz
}  // namespace topo_planner
