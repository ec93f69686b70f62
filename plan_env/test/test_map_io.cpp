// OctoMap and PCD round trips, and the forest_gen benchmark map.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "topo_planner/plan_env/map_io.h"
#include "test_helpers.h"

namespace topo_planner {
namespace {

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "topo_planner_" + name; }

std::vector<VoxelState> states(const OccupancyMap& m) {
  std::vector<VoxelState> out;
  const VoxelBox w = m.geometry().windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) out.push_back(m.state(i));
  return out;
}

TEST(MapIo, OctomapRoundTripKeepsEveryVoxelState) {
  std::mt19937 rng(21);
  auto map = test::makeMap({2.0, 1.6, 1.2}, {-1.0, -0.3, 0.0});
  test::randomFill(map.get(), 0.15, &rng, 0.3);  // occupied, free and unknown
  const std::string path = tempPath("roundtrip.bt");
  std::string err;
  ASSERT_EQ(saveOctomapFile(*map, path, &err), MapStatus::kSuccess) << err;
  MapFile file;
  ASSERT_EQ(readMapFile(path, &file, &err), MapStatus::kSuccess) << err;
  EXPECT_NEAR(file.resolution_m, 0.1, 1e-9);
  auto loaded = test::makeMap({2.0, 1.6, 1.2}, {-1.0, -0.3, 0.0});
  const MapInsertStats stats = insertMapFile(file, loaded.get());
  EXPECT_EQ(stats.clipped_cells, 0u);
  EXPECT_EQ(stats.occupied_voxels, map->countState(VoxelState::kOccupied));
  EXPECT_EQ(states(*map), states(*loaded));
  std::remove(path.c_str());
}

TEST(MapIo, PcdRoundTripKeepsOccupiedVoxels) {
  std::mt19937 rng(22);
  auto map = test::makeMap({2.0, 1.6, 1.2}, {3.0, -7.3, -2.0});
  test::randomFill(map.get(), 0.2, &rng);
  const std::string path = tempPath("roundtrip.pcd");
  std::string err;
  ASSERT_EQ(savePcdFile(*map, path, &err), MapStatus::kSuccess) << err;
  MapFile file;
  ASSERT_EQ(readMapFile(path, &file, &err), MapStatus::kSuccess) << err;
  EXPECT_EQ(file.cells.size(), map->countState(VoxelState::kOccupied));
  auto loaded = test::makeMap({2.0, 1.6, 1.2}, {3.0, -7.3, -2.0});
  insertMapFile(file, loaded.get());
  std::vector<Eigen::Vector3i> a, b;
  map->forEachOccupied([&](const Eigen::Vector3i& i) { a.push_back(i); });
  loaded->forEachOccupied([&](const Eigen::Vector3i& i) { b.push_back(i); });
  EXPECT_EQ(a, b);
  std::remove(path.c_str());
}

TEST(MapIo, EmptyMapSavesAndLoads) {
  auto map = test::makeMap({1.0, 1.0, 1.0}, {0, 0, 0});
  std::string err;
  const std::string pcd = tempPath("empty.pcd");
  ASSERT_EQ(savePcdFile(*map, pcd, &err), MapStatus::kSuccess) << err;
  MapFile file;
  ASSERT_EQ(readMapFile(pcd, &file, &err), MapStatus::kSuccess) << err;
  EXPECT_TRUE(file.cells.empty());
  std::remove(pcd.c_str());
}

TEST(MapIo, ForestGenMapLoadsWithItsBounds) {
  MapFile file;
  std::string err;
  ASSERT_EQ(readMapFile(std::string(TOPO_PLANNER_TEST_DATA_DIR) + "/forest0.bt", &file, &err), MapStatus::kSuccess)
      << err;
  // forest_gen: 10 m x 10 m x 5 m, x and y in [-5, 5], z in [0, 5], 0.1 m resolution.
  EXPECT_NEAR(file.resolution_m, 0.1, 1e-6);
  EXPECT_NEAR(file.min.x(), -5.0, 0.21);
  EXPECT_NEAR(file.min.y(), -5.0, 0.21);
  EXPECT_NEAR(file.max.x(), 5.0, 0.21);
  EXPECT_NEAR(file.max.y(), 5.0, 0.21);
  EXPECT_GT(file.min.z(), -0.21);
  EXPECT_LT(file.max.z(), 5.21);
  EXPECT_GT(file.numOccupied(), 1000u);

  OccupancyMap::Config base;
  const OccupancyMap::Config c = configFittingMapFile(file, base, 0.0);
  auto map = std::shared_ptr<OccupancyMap>(OccupancyMap::create(c, &err));
  ASSERT_TRUE(map) << err;
  const MapInsertStats stats = insertMapFile(file, map.get());
  EXPECT_EQ(stats.clipped_cells, 0u);
  EXPECT_EQ(map->countState(VoxelState::kOccupied), stats.occupied_voxels);
  EXPECT_GT(map->countState(VoxelState::kFree), map->countState(VoxelState::kOccupied));
  // Trees stand on the ground: some obstacle near z = 0.5 m and near the top half.
  auto esdf = test::makeEsdf(map, 2.0);
  esdf->updateAll();
  int negative = 0;
  for (float d : esdf->distances()) negative += d < 0.0f;
  EXPECT_EQ(size_t(negative), stats.occupied_voxels);
}

}  // namespace
}  // namespace topo_planner
