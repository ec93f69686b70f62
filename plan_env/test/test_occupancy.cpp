// Depth and point-cloud fusion on a rendered box scene, the DDA, and the scrolling window.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "topo_planner/plan_env/raycast.h"
#include "test_helpers.h"

namespace topo_planner {
namespace {

// Box whose faces lie in the middle of voxels (0.05 m off the grid) so no point is on a voxel border.
const Eigen::Vector3d kBoxLo(2.05, -0.45, 0.55), kBoxHi(2.65, 0.45, 1.45);
const Eigen::Vector3d kCamera(0.0, 0.0, 1.0);

std::shared_ptr<OccupancyMap> sceneMap(int pixel_skip = 1, bool projective = false) {
  OccupancyMap::Config c;
  c.project_free_space = projective;
  c.size_m = {6.0, 6.0, 3.0};
  c.origin_m = {-1.0, -3.0, -0.5};
  c.depth_pixel_skip = pixel_skip;
  std::string err;
  return std::shared_ptr<OccupancyMap>(OccupancyMap::create(c, &err));
}

// Global index of the voxel containing p.
Eigen::Vector3i vox(const OccupancyMap& m, const Eigen::Vector3d& p) { return m.geometry().indexOf(p); }

TEST(Raycast, VisitsAConnectedChainBetweenTheEndVoxels) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int trial = 0; trial < 500; ++trial) {
    const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    std::vector<Eigen::Vector3i> chain;
    traverseVoxels(a, b, 0.1, [&](const Eigen::Vector3i& i) {
      chain.push_back(i);
      return true;
    });
    ASSERT_EQ(chain.front(), Eigen::Vector3i((a / 0.1).array().floor().cast<int>()));
    ASSERT_EQ(chain.back(), Eigen::Vector3i((b / 0.1).array().floor().cast<int>()));
    for (size_t k = 1; k < chain.size(); ++k) ASSERT_EQ((chain[k] - chain[k - 1]).cwiseAbs().sum(), 1);
    // Every voxel that dense sampling of the segment meets is in the chain.
    std::set<std::tuple<int, int, int>> visited;
    for (const auto& i : chain) visited.insert({i.x(), i.y(), i.z()});
    for (int s = 0; s <= 4000; ++s) {
      const Eigen::Vector3i i = ((a + (b - a) * (s / 4000.0)) / 0.1).array().floor().cast<int>();
      const Eigen::Vector3d c = (i.cast<double>().array() + 0.5) * 0.1;
      const Eigen::Vector3d p = a + (b - a) * (s / 4000.0);
      // Skip samples within 1e-6 of a voxel face: the chain may legitimately pass the other side.
      if (((p - c).cwiseAbs().array() > 0.05 - 1e-6).any()) continue;
      ASSERT_TRUE(visited.count({i.x(), i.y(), i.z()})) << "trial " << trial;
    }
  }
}

TEST(Raycast, StopsWhenTheVisitorSaysSo) {
  int n = 0;
  const bool completed = traverseVoxels({0.05, 0.05, 0.05}, {1.05, 0.05, 0.05}, 0.1, [&](const Eigen::Vector3i&) {
    return ++n < 3;
  });
  EXPECT_FALSE(completed);
  EXPECT_EQ(n, 3);
}

TEST(DepthFusion, BoxFacesOccupiedRaysFreeBehindUnknown) {
  auto map = sceneMap();
  const PinholeCamera cam = test::smallCamera();
  const auto T = test::cameraLookingAlongX(kCamera);
  const auto depth = test::renderBox(cam, T, kBoxLo, kBoxHi);
  FusionResult r;
  for (int frame = 0; frame < 3; ++frame) {
    r = map->fuseDepthImage(test::viewOf(depth, cam), cam, T);
    ASSERT_EQ(r.status, MapStatus::kSuccess) << toString(r.status);
  }
  // The visible face x = 2.05 lies in voxel x = 20: every voxel of it is occupied.
  for (int iy = -4; iy <= 3; ++iy)
    for (int iz = 6; iz <= 13; ++iz) EXPECT_EQ(map->state(Eigen::Vector3i(20, iy, iz)), VoxelState::kOccupied);
  // Free along the optical axis up to the face; the box's inside and the space behind it unknown.
  for (double x = 0.15; x < 1.95; x += 0.1) EXPECT_EQ(map->state(Eigen::Vector3d(x, 0.01, 1.01)), VoxelState::kFree) << x;
  EXPECT_EQ(map->state(Eigen::Vector3d(2.35, 0.01, 1.01)), VoxelState::kUnknown);
  EXPECT_EQ(map->state(Eigen::Vector3d(3.5, 0.01, 1.01)), VoxelState::kUnknown);
  // Nothing but the box face is occupied.
  map->forEachOccupied([&](const Eigen::Vector3i& i) {
    EXPECT_EQ(i.x(), 20);
    EXPECT_TRUE(i.y() >= -5 && i.y() <= 4 && i.z() >= 5 && i.z() <= 14) << i.transpose();
  });
  // Rays that miss the box are cut at max range and free space up to it.
  EXPECT_EQ(map->state(Eigen::Vector3d(3.5, 2.0, 1.01)), VoxelState::kFree);
  // The touched box holds every update, and it is bounded by the camera's reach.
  EXPECT_TRUE(r.touched_box.contains(Eigen::Vector3i(20, 0, 10)));
  EXPECT_LE(r.touched_box.max.x(), 45);
}

// One frame of open space from a hover: every voxel wholly in view and in range is seen. Merged
// rays (project_free_space false, the ray casting point clouds keep) left a third to a half of them
// unknown, the same ones every frame: a vehicle at rest waited on space it had in view.
TEST(DepthFusion, OneFrameSeesEveryVoxelInView) {
  const PinholeCamera cam;  // 640 x 480, as the simulated and the real camera
  Eigen::Isometry3d T = test::cameraLookingAlongX({0.013, 0.027, 1.004});
  const std::vector<float> open(size_t(cam.width) * cam.height, INFINITY);
  for (const bool projective : {true, false}) {
    OccupancyMap::Config c;
    c.size_m = {8.0, 10.0, 5.0};
    c.origin_m = {-1.0, -5.0, -1.5};
    c.project_free_space = projective;
    std::string err;
    auto map = OccupancyMap::create(c, &err);
    ASSERT_TRUE(map) << err;
    ASSERT_EQ(map->fuseDepthImage(test::viewOf(open, cam), cam, T).status, MapStatus::kSuccess);
    int in_view = 0, unknown = 0;
    const double half = 0.5 * c.resolution_m;
    for (double x = -0.95; x < 7.0; x += 0.1)
      for (double y = -4.95; y < 5.0; y += 0.1)
        for (double z = -1.45; z < 3.5; z += 0.1) {
          bool inside = true;
          for (int k = 0; k < 8 && inside; ++k) {
            const Eigen::Vector3d corner(x + (k & 1 ? half : -half), y + (k & 2 ? half : -half), z + (k & 4 ? half : -half));
            const Eigen::Vector3d p = T.inverse() * corner;
            const double u = cam.fx * p.x() / p.z() + cam.cx, v = cam.fy * p.y() / p.z() + cam.cy;
            inside = p.z() > 0.05 && p.norm() < c.max_ray_length_m - 0.1 && u > 1 && u < cam.width - 2 && v > 1 &&
                     v < cam.height - 2;
          }
          if (!inside) continue;
          ++in_view;
          unknown += map->state(Eigen::Vector3d(x, y, z)) == VoxelState::kUnknown;
        }
    ASSERT_GT(in_view, 20000);
    if (projective) {
      EXPECT_EQ(unknown, 0) << "of " << in_view;
    } else {
      EXPECT_GT(unknown, in_view / 5) << "merged rays: " << unknown << " of " << in_view << " unknown";
    }
  }
}

// Free space by projection frees no voxel of a surface's far side: not the box's inside, not its
// shadow, not the voxels along its edges where the background is seen past it (the nearest surface
// of the pixels around a voxel's projection decides).
TEST(DepthFusion, ProjectionFreesNothingBehindASurface) {
  for (const int skip : {1, 2}) {
    auto map = sceneMap(skip, true);
    const PinholeCamera cam = test::smallCamera();
    const Eigen::Vector3d poses[2] = {kCamera, Eigen::Vector3d(0.3, 0.62, 1.37)};
    for (const Eigen::Vector3d& at : poses) {
      const auto T = test::cameraLookingAlongX(at);
      const auto depth = test::renderBox(cam, T, kBoxLo, kBoxHi);
      // (Three frames: one hit on an unknown voxel leaves it below prob_occupied.)
      for (int frame = 0; frame < 3; ++frame)
        ASSERT_EQ(map->fuseDepthImage(test::viewOf(depth, cam), cam, T).status, MapStatus::kSuccess);
    }
    int free = 0;
    const double half = 0.05;
    for (double x = -0.95; x < 5.0; x += 0.1)
      for (double y = -2.95; y < 3.0; y += 0.1)
        for (double z = -0.45; z < 2.5; z += 0.1) {
          if (map->state(Eigen::Vector3d(x, y, z)) != VoxelState::kFree) continue;
          ++free;
          // The voxel's cube and the box's inside (its faces lie mid-voxel) do not meet.
          const bool meets = x + half > kBoxLo.x() && x - half < kBoxHi.x() && y + half > kBoxLo.y() &&
                             y - half < kBoxHi.y() && z + half > kBoxLo.z() && z - half < kBoxHi.z();
          EXPECT_FALSE(meets) << "free voxel at " << x << " " << y << " " << z << " (skip " << skip << ")";
          // Nor does it lie in the box's shadow from both poses (well inside it: 0.05 m off its edges).
          auto shadowed = [&](const Eigen::Vector3d& from) {
            const Eigen::Vector3d d = Eigen::Vector3d(x, y, z) - from;
            const Eigen::Vector3d at_face = from + d * ((kBoxLo.x() - from.x()) / d.x());
            return std::abs(at_face.y()) < 0.4 && std::abs(at_face.z() - 1.0) < 0.4;
          };
          if (x > kBoxHi.x()) {
            EXPECT_FALSE(shadowed(poses[0]) && shadowed(poses[1]))
                << "free voxel in the shadow at " << x << " " << y << " " << z;
          }
        }
    EXPECT_GT(free, 1000);
  }
}

TEST(DepthFusion, RepeatedFramesConverge) {
  auto map = sceneMap(2);
  const PinholeCamera cam = test::smallCamera();
  const auto T = test::cameraLookingAlongX(kCamera);
  const auto depth = test::renderBox(cam, T, kBoxLo, kBoxHi);
  FusionResult r;
  for (int frame = 0; frame < 12; ++frame) r = map->fuseDepthImage(test::viewOf(depth, cam), cam, T);
  EXPECT_TRUE(r.changed_box.empty());  // nothing changes state any more
  EXPECT_NEAR(map->probability(Eigen::Vector3i(20, 0, 10)), map->config().prob_max, 1e-5);
  EXPECT_NEAR(map->probability(vox(*map, {1.0, 0.01, 1.01})), map->config().prob_min, 1e-5);
  const std::vector<float> before = map->logOdds();
  r = map->fuseDepthImage(test::viewOf(depth, cam), cam, T);
  EXPECT_EQ(before, map->logOdds());  // a fixed point
  EXPECT_GT(r.voxels_updated, 0);
}

TEST(DepthFusion, MaxRangeRaysFreeSpaceAndMarkNothingOccupied) {
  auto map = sceneMap();
  const PinholeCamera cam = test::smallCamera();
  const auto T = test::cameraLookingAlongX(kCamera);
  // Everything 10 m away (beyond the 4.5 m max range), plus a few +inf "no return" pixels.
  std::vector<float> depth(size_t(cam.width) * cam.height, 10.0f);
  for (size_t k = 0; k < depth.size(); k += 7) depth[k] = INFINITY;
  const FusionResult r = map->fuseDepthImage(test::viewOf(depth, cam), cam, T);
  ASSERT_EQ(r.status, MapStatus::kSuccess);
  EXPECT_EQ(map->countState(VoxelState::kOccupied), 0u);
  EXPECT_EQ(r.voxels_hit, 0);
  EXPECT_EQ(map->state(Eigen::Vector3d(4.0, 0.01, 1.01)), VoxelState::kFree);     // 4 m: within range
  EXPECT_EQ(map->state(Eigen::Vector3d(4.85, 0.01, 1.01)), VoxelState::kUnknown);  // 4.85 m: beyond
}

TEST(DepthFusion, MillimetreImageGivesTheSameMap) {
  auto metres = sceneMap(), millimetres = sceneMap();
  const PinholeCamera cam = test::smallCamera();
  const auto T = test::cameraLookingAlongX(kCamera);
  const auto depth = test::renderBox(cam, T, kBoxLo, kBoxHi);
  std::vector<uint16_t> mm(depth.size());
  for (size_t k = 0; k < depth.size(); ++k) mm[k] = std::isinf(depth[k]) ? 0 : uint16_t(std::lround(depth[k] * 1000.0));
  DepthImageView view;
  view.data = reinterpret_cast<const uint8_t*>(mm.data());
  view.width = cam.width;
  view.height = cam.height;
  view.row_step_bytes = size_t(cam.width) * 2;
  view.encoding = DepthEncoding::kUInt16;
  view.depth_scale = 0.001;
  for (int f = 0; f < 2; ++f) {
    ASSERT_EQ(millimetres->fuseDepthImage(view, cam, T).status, MapStatus::kSuccess);
    ASSERT_EQ(metres->fuseDepthImage(test::viewOf(depth, cam), cam, T).status, MapStatus::kSuccess);
  }
  // 0 = no return in 16UC1: those rays are skipped rather than freeing space, so compare the hits.
  std::vector<Eigen::Vector3i> a, b;
  metres->forEachOccupied([&](const Eigen::Vector3i& i) { a.push_back(i); });
  millimetres->forEachOccupied([&](const Eigen::Vector3i& i) { b.push_back(i); });
  EXPECT_EQ(a, b);
  EXPECT_GT(a.size(), 50u);
}

TEST(DepthFusion, RowStepPaddingIsHonoured) {
  auto packed = sceneMap(), padded = sceneMap();
  const PinholeCamera cam = test::smallCamera();
  const auto T = test::cameraLookingAlongX(kCamera);
  const auto depth = test::renderBox(cam, T, kBoxLo, kBoxHi);
  const int stride = cam.width + 13;  // floats per padded row
  std::vector<float> rows(size_t(stride) * cam.height, -1.0f);
  for (int v = 0; v < cam.height; ++v)
    std::copy(depth.begin() + v * cam.width, depth.begin() + (v + 1) * cam.width, rows.begin() + v * stride);
  DepthImageView view = test::viewOf(depth, cam);
  view.data = reinterpret_cast<const uint8_t*>(rows.data());
  view.row_step_bytes = size_t(stride) * sizeof(float);
  packed->fuseDepthImage(test::viewOf(depth, cam), cam, T);
  padded->fuseDepthImage(view, cam, T);
  EXPECT_EQ(packed->logOdds(), padded->logOdds());
}

TEST(PointCloudFusion, PointsOnAFaceBecomeOccupied) {
  auto map = sceneMap();
  std::vector<Eigen::Vector3d> points;
  for (double y = -0.4; y <= 0.4; y += 0.02)
    for (double z = 0.6; z <= 1.4; z += 0.02) points.emplace_back(2.05, y, z);
  points.emplace_back(NAN, 0.0, 0.0);
  FusionResult r;
  for (int f = 0; f < 2; ++f) r = map->fusePointCloud(points, kCamera);
  ASSERT_EQ(r.status, MapStatus::kSuccess);
  EXPECT_EQ(r.invalid, 1);
  EXPECT_EQ(map->state(Eigen::Vector3d(2.05, 0.01, 1.01)), VoxelState::kOccupied);
  EXPECT_EQ(map->state(Eigen::Vector3d(1.0, 0.01, 1.01)), VoxelState::kFree);
  EXPECT_EQ(map->state(Eigen::Vector3d(2.35, 0.01, 1.01)), VoxelState::kUnknown);
}

TEST(PointCloudFusion, RayLeavingTheWindowFreesOnlyTheInsidePart) {
  auto map = sceneMap();
  // A return 1 m beyond the +x border of the window (x max = 5.0).
  const FusionResult r = map->fusePointCloud({{4.0 + 2.0, 0.01, 1.01}}, {2.0, 0.01, 1.01});
  ASSERT_EQ(r.status, MapStatus::kSuccess);
  EXPECT_EQ(map->countState(VoxelState::kOccupied), 0u);
  EXPECT_EQ(map->state(Eigen::Vector3d(4.95, 0.01, 1.01)), VoxelState::kFree);
}

TEST(ScrollingWindow, KeepsWhatStaysAndForgetsWhatLeaves) {
  auto map = sceneMap();
  ASSERT_TRUE(map->setState(vox(*map, {0.0, 0.0, 1.0}), VoxelState::kOccupied));
  ASSERT_TRUE(map->setState(vox(*map, {-0.95, 0.0, 1.0}), VoxelState::kOccupied));
  ASSERT_TRUE(map->setState(vox(*map, {4.95, 2.95, 2.45}), VoxelState::kFree));
  // Move 1 m along +x: the voxel at x = -0.95 leaves, the one at x = 0 stays.
  const Eigen::Vector3i old_origin = map->geometry().originIndex();
  map->setOriginIndex(old_origin + Eigen::Vector3i(10, 0, 0));
  EXPECT_EQ(map->state(Eigen::Vector3d(0.0, 0.0, 1.0)), VoxelState::kOccupied);
  EXPECT_EQ(map->state(Eigen::Vector3d(-0.95, 0.0, 1.0)), VoxelState::kOutOfMap);
  EXPECT_EQ(map->state(Eigen::Vector3d(4.95, 2.95, 2.45)), VoxelState::kFree);
  // The entering slab (x in [5, 6)) reuses the leaving slots and starts unknown.
  for (double y = -2.95; y < 3.0; y += 0.5) EXPECT_EQ(map->state(Eigen::Vector3d(5.55, y, 1.0)), VoxelState::kUnknown);
  EXPECT_EQ(map->countState(VoxelState::kOccupied), 1u);
  // Coming back: the voxel that left is forgotten, the one that stayed is kept.
  map->setOriginIndex(old_origin);
  EXPECT_EQ(map->state(Eigen::Vector3d(-0.95, 0.0, 1.0)), VoxelState::kUnknown);
  EXPECT_EQ(map->state(Eigen::Vector3d(0.0, 0.0, 1.0)), VoxelState::kOccupied);
  // A jump larger than the window forgets everything.
  map->recenter({100.0, 100.0, 1.0});
  EXPECT_EQ(map->countState(VoxelState::kOccupied), 0u);
  EXPECT_EQ(map->countState(VoxelState::kFree), 0u);
  EXPECT_TRUE(map->geometry().inWindow(Eigen::Vector3d(100.0, 100.0, 1.0)));
}

TEST(ScrollingWindow, FusionAfterScrollMatchesAFreshMapAtThatWindow) {
  auto scrolled = sceneMap();
  scrolled->setOriginIndex(scrolled->geometry().originIndex() + Eigen::Vector3i(-7, 4, 1));
  OccupancyMap::Config c = scrolled->config();
  c.origin_m = scrolled->geometry().windowMin();
  std::string err;
  auto fresh = OccupancyMap::create(c, &err);
  const PinholeCamera cam = test::smallCamera();
  const auto T = test::cameraLookingAlongX(kCamera);
  const auto depth = test::renderBox(cam, T, kBoxLo, kBoxHi);
  scrolled->fuseDepthImage(test::viewOf(depth, cam), cam, T);
  fresh->fuseDepthImage(test::viewOf(depth, cam), cam, T);
  const VoxelBox w = fresh->geometry().windowBox();
  ASSERT_EQ(w, scrolled->geometry().windowBox());
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) ASSERT_EQ(scrolled->state(i), fresh->state(i));
}

TEST(OccupancyMap, KnownWithinARadiusMeansNoUnobservedVoxelTouchesTheBall) {
  auto map = sceneMap();
  // One observed slab (x in [0, 2)) but for one voxel in it; the rest of the window unknown.
  const VoxelBox w = map->geometry().windowBox();
  const Eigen::Vector3i hole = vox(*map, {1.05, 0.05, 1.05});
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        const double cx = map->geometry().centerOf(i).x();
        if (cx > 0.0 && cx < 2.0 && i != hole) {
          ASSERT_TRUE(map->setState(i, VoxelState::kFree));
        }
      }
  ASSERT_EQ(map->state(hole), VoxelState::kUnknown);
  // Brute force over the window: a ball touches an unknown voxel's cube.
  const double half = 0.5 * map->geometry().resolution();
  auto brute = [&](const Eigen::Vector3d& p, double r) {
    Eigen::Vector3i j;
    for (j.z() = w.min.z(); j.z() <= w.max.z(); ++j.z())
      for (j.y() = w.min.y(); j.y() <= w.max.y(); ++j.y())
        for (j.x() = w.min.x(); j.x() <= w.max.x(); ++j.x()) {
          if (map->state(j) != VoxelState::kUnknown) continue;
          const Eigen::Vector3d gap =
              ((p - map->geometry().centerOf(j)).cwiseAbs().array() - half).max(0.0).matrix();
          if (gap.norm() < r || j == map->geometry().indexOf(p)) return false;
        }
    return true;
  };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> x(-0.4, 2.4), yz(0.3, 1.7), rad(0.0, 0.45);
  int known = 0, unknown = 0;
  for (int k = 0; k < 400; ++k) {
    const Eigen::Vector3d p(x(rng), yz(rng) - 1.0 + 0.05, yz(rng));
    const double r = k % 4 == 0 ? 0.0 : rad(rng);
    const bool expect = brute(p, r);
    ASSERT_EQ(map->isKnownWithin(p, r), expect) << p.transpose() << " r " << r;
    (expect ? known : unknown)++;
  }
  EXPECT_GT(known, 50);
  EXPECT_GT(unknown, 50);
  // Beside the hole: a point 0.15 m from its face is known within 0.1 m, not within 0.2 m.
  EXPECT_TRUE(map->isKnownWithin({1.05, 0.05, 1.25}, 0.1));
  EXPECT_FALSE(map->isKnownWithin({1.05, 0.05, 1.25}, 0.2));
  // Unknown voxels exempted by the caller's predicate (by centre) count as known.
  EXPECT_TRUE(map->isKnownWithin({1.05, 0.05, 1.25}, 0.2, [&](const Eigen::Vector3d& c) {
    return (c - map->geometry().centerOf(hole)).norm() < 1e-9;
  }));
  EXPECT_FALSE(map->isKnownWithin({1.05, 0.05, 1.25}, 0.2, [](const Eigen::Vector3d&) { return false; }));
  // Refused: out of the window, NaN, a negative or too large radius.
  EXPECT_FALSE(map->isKnownWithin({50.0, 0.0, 1.0}, 0.1));
  EXPECT_FALSE(map->isKnownWithin({std::nan(""), 0.0, 1.0}, 0.1));
  EXPECT_FALSE(map->isKnownWithin({1.5, 1.0, 1.0}, -0.1));
  EXPECT_FALSE(map->isKnownWithin({1.5, 1.0, 1.0}, OccupancyMap::kMaxKnownRadius + 0.1));
}

TEST(OccupancyMap, MemoryStaysSmallForALargeMap) {
  OccupancyMap::Config c;
  c.size_m = {40.0, 20.0, 5.0};
  std::string err;
  auto map = OccupancyMap::create(c, &err);
  ASSERT_TRUE(map) << err;
  const size_t bytes = map->logOdds().capacity() * sizeof(float) + map->geometry().numVoxels() * sizeof(uint32_t);
  EXPECT_EQ(map->geometry().numVoxels(), 400u * 200u * 50u);
  EXPECT_LT(bytes, 40u * 1024u * 1024u);  // 8 bytes a voxel: 32 MB for 4M voxels
}

}  // namespace
}  // namespace topo_planner
