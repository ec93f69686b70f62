// OctoMap and PCD round trips, and the forest_gen benchmark map.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <iterator>
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

// A hand-made OctoMap file holding one chain of inner nodes, `inner_levels` deep, that ends in one
// occupied leaf at depth inner_levels + 1 (child 0 at every level). octomap's trees are 16 deep,
// so 15 inner levels put the leaf at the finest depth and 16 put it below the tree.
std::string octomapChain(bool binary, int inner_levels, int drop_bytes = 0) {
  std::string s = binary ? "# Octomap OcTree binary file\n" : "# Octomap OcTree file\n";
  s += "id OcTree\nsize " + std::to_string(inner_levels + 2) + "\nres 0.1\ndata\n";
  if (binary) {
    for (int d = 0; d < inner_levels; ++d) s += std::string("\x03\x00", 2);  // child 0 inner
    s += std::string("\x02\x00", 2);                                         // child 0 an occupied leaf
  } else {
    const float log_odds = 3.5f;
    const std::string value(reinterpret_cast<const char*>(&log_odds), sizeof(log_odds));
    for (int d = 0; d <= inner_levels; ++d) s += value + '\x01';  // child 0 exists
    s += value + '\x00';                                          // the leaf
  }
  s.resize(s.size() - size_t(drop_bytes));
  return s;
}

MapStatus readBytes(const std::string& bytes, const std::string& ext, MapFile* file, std::string* err) {
  const std::string path = tempPath("handmade." + ext);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << bytes;
  }
  const MapStatus status = readMapFile(path, file, err);
  std::remove(path.c_str());
  return status;
}

TEST(MapIo, OctomapNodeStreamAtTheTreeDepthLoads) {
  for (const bool binary : {true, false}) {
    MapFile file;
    std::string err;
    ASSERT_EQ(readBytes(octomapChain(binary, 15), binary ? "bt" : "ot", &file, &err), MapStatus::kSuccess) << err;
    ASSERT_EQ(file.cells.size(), 1u);
    EXPECT_TRUE(file.cells[0].occupied);
    EXPECT_NEAR(file.cells[0].size_m, 0.1, 1e-6);  // a leaf of the finest depth
    // Child 0 at every depth: the lowest key, centre (0 - 2^15 + 0.5) * 0.1 on each axis.
    EXPECT_NEAR(file.cells[0].center.x(), (0.5 - 32768.0) * 0.1, 1e-2);
  }
}

// octomap's readers recurse once per inner node and follow the child flags past the tree depth
// (found by the octomap fuzz harness as a stack overflow): such a file is refused before.
TEST(MapIo, OctomapNodeStreamBelowTheTreeDepthIsRefused) {
  for (const bool binary : {true, false}) {
    for (const int levels : {16, 40, 20000}) {
      MapFile file;
      std::string err;
      EXPECT_EQ(readBytes(octomapChain(binary, levels), binary ? "bt" : "ot", &file, &err), MapStatus::kParseError)
          << (binary ? ".bt " : ".ot ") << levels << " levels";
      EXPECT_NE(err.find("below the tree depth of 16"), std::string::npos) << err;
      EXPECT_TRUE(file.cells.empty());
    }
  }
}

// A stream that ends early made octomap decode bytes it never read (and recurse on them).
TEST(MapIo, OctomapTruncatedNodeStreamIsRefused) {
  for (const bool binary : {true, false}) {
    MapFile file;
    std::string err;
    EXPECT_EQ(readBytes(octomapChain(binary, 10, 1), binary ? "bt" : "ot", &file, &err), MapStatus::kParseError);
    EXPECT_NE(err.find("ends inside its node stream"), std::string::npos) << err;
    // A header whose node count differs from the stream's.
    std::string wrong = octomapChain(binary, 10);
    wrong.replace(wrong.find("size 12"), 7, "size 13");
    EXPECT_EQ(readBytes(wrong, binary ? "bt" : "ot", &file, &err), MapStatus::kParseError);
    EXPECT_NE(err.find("declares 13 nodes"), std::string::npos) << err;
  }
}

// A PCD file whose ASCII body PCL keeps in fewer bytes than its WIDTH x HEIGHT points (found by the
// pcd fuzz harness: pcl::fromPCLPointCloud2 read past the buffer) is refused, not read as points.
TEST(MapIo, PcdWithFewerBytesThanPointsIsRefused) {
  const std::string path =
      std::string(TOPO_PLANNER_TEST_DATA_DIR) + "/../fuzz/regressions/pcd/ascii_body_shorter_than_points";
  std::ifstream in(path, std::ios::binary);
  ASSERT_TRUE(in.good()) << path;
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  MapFile file;
  std::string err;
  ASSERT_EQ(readBytes(bytes, "pcd", &file, &err), MapStatus::kParseError);
  EXPECT_NE(err.find("holds fewer bytes than its 4 x 1 points"), std::string::npos) << err;
  EXPECT_TRUE(file.cells.empty());
}

// x, y, z must be floats inside a point (a field past the point's end was read past the data).
TEST(MapIo, PcdFieldsOutsideAPointOrNotFloatAreRefused) {
  const std::string body = "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n";
  MapFile file;
  std::string err;
  EXPECT_EQ(readBytes("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n" + body, "pcd", &file, &err),
            MapStatus::kSuccess) << err;
  EXPECT_EQ(file.cells.size(), 2u);
  EXPECT_EQ(file.cells[1].center, Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(readBytes("VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n" + body, "pcd", &file, &err),
            MapStatus::kParseError);
  EXPECT_NE(err.find("is not a float inside a point"), std::string::npos) << err;
}

// PCL allocates the points a header declares before reading them (pcd fuzz harness: 4 GB for a
// small file): a header declaring more points than the data can hold is refused first.
TEST(MapIo, PcdDeclaringMorePointsThanItsDataIsRefused) {
  const std::string head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  for (const std::string& body : {std::string("WIDTH 1000000000\nHEIGHT 4\nVIEWPOINT 0 0 0 1 0 0 0\n"
                                              "POINTS 4000000000\nDATA binary\n") + std::string(24, '\0'),
                                  std::string("WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n1 2\n")}) {
    MapFile file;
    std::string err;
    EXPECT_EQ(readBytes(head + body, "pcd", &file, &err), MapStatus::kParseError);
    EXPECT_NE(err.find("bytes of data hold"), std::string::npos) << err;
  }
  // binary_compressed: the uncompressed size written in the data must be the declared points'.
  std::ifstream in(std::string(TOPO_PLANNER_TEST_DATA_DIR) + "/../fuzz/corpus/pcd/binary_compressed", std::ios::binary);
  std::string compressed((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  MapFile file;
  std::string err;
  ASSERT_EQ(readBytes(compressed, "pcd", &file, &err), MapStatus::kSuccess) << err;  // written by PCL
  EXPECT_FALSE(file.cells.empty());
  const size_t data = compressed.find("DATA binary_compressed\n") + 23;
  ASSERT_LT(data + 8, compressed.size());
  compressed.replace(data + 4, 4, std::string("\xff\xff\xff\xff", 4));  // uncompressed size 4 GB
  EXPECT_EQ(readBytes(compressed, "pcd", &file, &err), MapStatus::kParseError);
  EXPECT_NE(err.find("compressed data of the wrong size"), std::string::npos) << err;
}

}  // namespace
}  // namespace topo_planner
