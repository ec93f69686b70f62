// Every bad input gets its status and leaves the map as it was.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <limits>

#include "topo_planner/plan_env/map_io.h"
#include "test_helpers.h"

namespace topo_planner {
namespace {

class BadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    OccupancyMap::Config c;
    c.size_m = {6.0, 6.0, 3.0};
    c.origin_m = {-1.0, -3.0, -0.5};
    c.max_image_pixels = 400 * 300;
    c.depth_pixel_skip = 1;
    std::string err;
    map_ = std::shared_ptr<OccupancyMap>(OccupancyMap::create(c, &err));
    cam_ = test::smallCamera();
    T_ = test::cameraLookingAlongX({0.0, 0.0, 1.0});
    depth_ = test::renderBox(cam_, T_, {2.05, -0.45, 0.55}, {2.65, 0.45, 1.45});
    // A map with content, so "unchanged" means something.
    ASSERT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), cam_, T_).status, MapStatus::kSuccess);
    before_ = map_->logOdds();
  }
  void expectUnchanged() { EXPECT_EQ(before_, map_->logOdds()); }

  std::shared_ptr<OccupancyMap> map_;
  PinholeCamera cam_;
  Eigen::Isometry3d T_;
  std::vector<float> depth_;
  std::vector<float> before_;
};

TEST_F(BadInput, NonFinitePoses) {
  for (double bad : {double(NAN), double(INFINITY), -double(INFINITY)}) {
    Eigen::Isometry3d T = T_;
    T.translation().y() = bad;
    EXPECT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), cam_, T).status, MapStatus::kInvalidPose);
    T = T_;
    T.linear()(1, 2) = bad;
    EXPECT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), cam_, T).status, MapStatus::kInvalidPose);
  }
  Eigen::Isometry3d scaled = T_;
  scaled.linear() *= 2.0;  // not a rotation
  EXPECT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), cam_, scaled).status, MapStatus::kInvalidPose);
  Eigen::Isometry3d mirrored = T_;
  mirrored.linear().col(0) *= -1.0;  // orthonormal but a reflection
  EXPECT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), cam_, mirrored).status, MapStatus::kInvalidPose);
  EXPECT_EQ(map_->fusePointCloud({{1.0, 0.0, 1.0}}, {NAN, 0.0, 0.0}).status, MapStatus::kInvalidPose);
  expectUnchanged();
}

TEST_F(BadInput, NonFiniteDepthsAreSkipped) {
  std::vector<float> bad(depth_.size(), NAN);
  for (size_t k = 0; k < bad.size(); k += 3) bad[k] = -INFINITY;
  for (size_t k = 1; k < bad.size(); k += 5) bad[k] = 0.0f;
  for (size_t k = 2; k < bad.size(); k += 11) bad[k] = -1.5f;
  FusionResult r = map_->fuseDepthImage(test::viewOf(bad, cam_), cam_, T_);
  EXPECT_EQ(r.status, MapStatus::kNoValidData);
  EXPECT_EQ(r.invalid, cam_.width * cam_.height);
  expectUnchanged();
  // Mixed: the valid pixels are fused, the rest counted.
  std::vector<float> mixed = depth_;
  for (size_t k = 0; k < mixed.size(); k += 2) mixed[k] = NAN;
  r = map_->fuseDepthImage(test::viewOf(mixed, cam_), cam_, T_);
  EXPECT_EQ(r.status, MapStatus::kSuccess);
  EXPECT_EQ(r.invalid, cam_.width * cam_.height / 2);
  for (float l : map_->logOdds()) ASSERT_TRUE(std::isfinite(l));
}

TEST_F(BadInput, EmptyMismatchedOrOversizedImages) {
  DepthImageView v = test::viewOf(depth_, cam_);
  DepthImageView empty = v;
  empty.width = 0;
  EXPECT_EQ(map_->fuseDepthImage(empty, cam_, T_).status, MapStatus::kEmptyImage);
  DepthImageView null = v;
  null.data = nullptr;
  EXPECT_EQ(map_->fuseDepthImage(null, cam_, T_).status, MapStatus::kEmptyImage);
  DepthImageView narrow = v;
  narrow.width = cam_.width - 1;
  EXPECT_EQ(map_->fuseDepthImage(narrow, cam_, T_).status, MapStatus::kImageSizeMismatch);
  DepthImageView short_step = v;
  short_step.row_step_bytes = size_t(cam_.width) * 4 - 1;
  EXPECT_EQ(map_->fuseDepthImage(short_step, cam_, T_).status, MapStatus::kImageSizeMismatch);
  PinholeCamera big = cam_;
  big.width = 800;
  big.height = 600;
  std::vector<float> big_depth(size_t(big.width) * big.height, 1.0f);
  EXPECT_EQ(map_->fuseDepthImage(test::viewOf(big_depth, big), big, T_).status, MapStatus::kImageTooLarge);
  DepthImageView bad_scale = v;
  bad_scale.depth_scale = NAN;
  EXPECT_EQ(map_->fuseDepthImage(bad_scale, cam_, T_).status, MapStatus::kInvalidIntrinsics);
  expectUnchanged();
}

TEST_F(BadInput, InvalidIntrinsics) {
  for (int k = 0; k < 4; ++k) {
    PinholeCamera c = cam_;
    if (k == 0) c.fx = 0.0;
    if (k == 1) c.fy = -10.0;
    if (k == 2) c.cx = NAN;
    if (k == 3) c.cy = INFINITY;
    EXPECT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), c, T_).status, MapStatus::kInvalidIntrinsics) << k;
  }
  expectUnchanged();
}

// Focal lengths that are positive and finite but so small that (u - cx) / fx overflows: every ray
// of infinite depth (max range) then ends at NaN (infinity times zero). Such rays carry nothing
// (found by the depth_image fuzz harness, an undefined NaN-to-int cast; the clipping let them
// through as the whole window).
TEST_F(BadInput, RaysThatEndAtNaNAreIgnored) {
  PinholeCamera c = cam_;
  c.fx = c.fy = 1e-310;
  c.cx += 0.25;  // no pixel on the optical axis
  c.cy += 0.25;
  std::vector<float> far(depth_.size(), std::numeric_limits<float>::infinity());
  const FusionResult r = map_->fuseDepthImage(test::viewOf(far, c), c, T_);
  EXPECT_EQ(r.status, MapStatus::kOutOfMap);
  EXPECT_EQ(r.rays, 0);
  expectUnchanged();
}

// Points far beyond the int range of voxel indices, within a long max range: the ray is clipped to
// the window like any other (pointcloud2 fuzz harness: the end's index was cast to int first).
TEST(BadPoints, FarPointsAreClippedToTheWindow) {
  OccupancyMap::Config c;
  c.size_m = {2.0, 2.0, 2.0};
  c.origin_m = {-1.0, -1.0, -1.0};
  c.max_ray_length_m = 1e308;
  std::string err;
  auto map = OccupancyMap::create(c, &err);
  ASSERT_TRUE(map) << err;
  const FusionResult r = map->fusePointCloud({{-1e150, 0.05, 0.05}}, {0.05, 0.05, 0.05});
  EXPECT_EQ(r.status, MapStatus::kSuccess);
  EXPECT_EQ(r.rays, 1);
  // The free part inside the window, from the sensor to the border, and no hit.
  EXPECT_EQ(map->state(map->geometry().indexOf({-0.95, 0.05, 0.05})), VoxelState::kFree);
  EXPECT_EQ(map->countState(VoxelState::kOccupied), 0u);
}

TEST_F(BadInput, SensorOutsideTheMapLookingAway) {
  const auto T = test::cameraLookingAlongX({50.0, 0.0, 1.0});
  EXPECT_EQ(map_->fuseDepthImage(test::viewOf(depth_, cam_), cam_, T).status, MapStatus::kOutOfMap);
  EXPECT_EQ(map_->fusePointCloud({{NAN, 0, 0}, {INFINITY, 1, 1}}, {0, 0, 1}).status, MapStatus::kNoValidData);
  EXPECT_EQ(map_->fusePointCloud({}, {0, 0, 1}).status, MapStatus::kNoValidData);
  expectUnchanged();
}

TEST_F(BadInput, OutOfMapAndNonFiniteQueries) {
  EXPECT_EQ(map_->state(Eigen::Vector3d(NAN, 0, 0)), VoxelState::kOutOfMap);
  EXPECT_EQ(map_->state(Eigen::Vector3d(1e300, 0, 0)), VoxelState::kOutOfMap);
  EXPECT_EQ(map_->state(Eigen::Vector3i(10000, 0, 0)), VoxelState::kOutOfMap);
  EXPECT_FALSE(map_->setState(Eigen::Vector3i(10000, 0, 0), VoxelState::kOccupied));
  EXPECT_TRUE(std::isnan(map_->probability(Eigen::Vector3i(10000, 0, 0))));
  const Eigen::Vector3i origin = map_->geometry().originIndex();
  EXPECT_TRUE(map_->recenter({NAN, 0, 0}).empty());
  EXPECT_TRUE(map_->recenter({1e12, 0, 0}).empty());  // finite but beyond any int index
  EXPECT_TRUE(map_->recenter({0, -1e300, 0}).empty());
  EXPECT_TRUE(map_->setOriginIndex(Eigen::Vector3i(std::numeric_limits<int>::max() - 5, 0, 0)).empty());
  EXPECT_EQ(map_->geometry().originIndex(), origin);
  expectUnchanged();
}

TEST(BadConfig, RefusedWithAReason) {
  std::string err;
  OccupancyMap::Config c;
  c.resolution_m = 0.0;
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  EXPECT_NE(err.find("resolution_m"), std::string::npos) << err;
  c = OccupancyMap::Config();
  c.size_m.x() = -1.0;
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  c = OccupancyMap::Config();
  c.prob_hit = 1.5;
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  c = OccupancyMap::Config();
  c.origin_m.z() = NAN;
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  c = OccupancyMap::Config();
  c.origin_m.x() = 1e12;  // finite, but no int voxel index reaches it
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  c = OccupancyMap::Config();
  c.max_ray_length_m = 0.05;
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  // Too large for memory: 1 km x 1 km x 100 m at 5 cm.
  c = OccupancyMap::Config();
  c.size_m = {1000.0, 1000.0, 100.0};
  c.resolution_m = 0.05;
  EXPECT_FALSE(OccupancyMap::create(c, &err));
  EXPECT_NE(err.find("max_memory_mb"), std::string::npos) << err;

  auto occ = test::makeMap({1, 1, 1}, {0, 0, 0});
  EsdfMap::Config e;
  e.max_distance_m = -1.0;
  EXPECT_FALSE(EsdfMap::create(e, occ, &err));
  e = EsdfMap::Config();
  e.inflate_radius_m = 5.0;  // above max_distance_m
  EXPECT_FALSE(EsdfMap::create(e, occ, &err));
  e = EsdfMap::Config();
  e.max_distance_m = 1e4;  // 100,000 voxels: would overflow the squared distances
  e.inflate_radius_m = 0.2;
  EXPECT_FALSE(EsdfMap::create(e, occ, &err));
  e = EsdfMap::Config();
  e.num_threads = 0;
  EXPECT_FALSE(EsdfMap::create(e, occ, &err));
  EXPECT_FALSE(EsdfMap::create(EsdfMap::Config(), nullptr, &err));
}

TEST(BadFiles, MissingGarbageAndTruncatedFiles) {
  MapFile file;
  file.cells.push_back({Eigen::Vector3d(1, 2, 3), 0.1, true});
  const MapFile untouched = file;
  std::string err;
  EXPECT_EQ(readMapFile("/nonexistent/forest.bt", &file, &err), MapStatus::kFileNotFound);
  EXPECT_EQ(readMapFile("/nonexistent/forest.pcd", &file, &err), MapStatus::kFileNotFound);
  const std::string garbage = ::testing::TempDir() + "topo_planner_garbage";
  for (const std::string ext : {".bt", ".pcd", ".ot", ".xyz"}) {
    std::ofstream(garbage + ext) << "this is not a map\n\x01\x02\x03";
    EXPECT_EQ(readMapFile(garbage + ext, &file, &err), MapStatus::kParseError) << ext;
    EXPECT_FALSE(err.empty());
    std::remove((garbage + ext).c_str());
  }
  // A forest_gen map cut in half.
  std::ifstream in(std::string(TOPO_PLANNER_TEST_DATA_DIR) + "/forest0.bt", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 1000u);
  const std::string truncated = ::testing::TempDir() + "topo_planner_truncated.bt";
  std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  EXPECT_EQ(readMapFile(truncated, &file, &err), MapStatus::kParseError);
  std::remove(truncated.c_str());
  ASSERT_EQ(file.cells.size(), untouched.cells.size());  // the output is untouched on failure
  EXPECT_EQ(file.cells[0].center, untouched.cells[0].center);
  auto map = test::makeMap({1, 1, 1}, {0, 0, 0});
  EXPECT_EQ(saveOctomapFile(*map, "/nonexistent/dir/out.bt", &err), MapStatus::kWriteError);
  EXPECT_EQ(savePcdFile(*map, "/nonexistent/dir/out.pcd", &err), MapStatus::kWriteError);
}

}  // namespace
}  // namespace topo_planner
