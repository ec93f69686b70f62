#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <ostream>
#include <random>
#include <string>

#include "topo_planner/plan_env/map_generator.h"
#include "topo_planner/plan_env/synthetic_scene.h"
#include "topo_planner/uav_sim/depth_camera.h"

namespace topo_planner {

// Names the renderer in gtest's messages.
void PrintTo(DepthCamera::Method method, std::ostream* os) { *os << DepthCamera::toString(method); }

namespace {

Eigen::Isometry3d lookingAlongX(const Eigen::Vector3d& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  T.translation() = p;
  return T;
}

DepthCamera::Config smallCamera() {
  DepthCamera::Config c;
  c.camera.width = 80;
  c.camera.height = 60;
  c.camera.fx = c.camera.fy = 50.0;
  c.camera.cx = 39.5;
  c.camera.cy = 29.5;
  return c;
}

class DepthCameraMethods : public ::testing::TestWithParam<DepthCamera::Method> {
 protected:
  DepthCamera::Config smallCameraWithMethod() const {
    DepthCamera::Config c = smallCamera();
    c.method = GetParam();
    return c;
  }
};

TEST_P(DepthCameraMethods, BoxAtTheRightDepthWithOcclusion) {
  SyntheticScene w({8.0, 6.0, 3.0}, 0.1, {-1.0, -3.0, 0.0});
  // Bounds 1 cm beyond the voxel centres they mean to include (centres lie on a 0.1 m grid).
  w.box({2.04, -0.46, 0.54}, {2.66, 0.46, 1.46});   // near box, 1 m x 1 m face at x = 2.0
  w.box({4.04, -1.96, 0.04}, {4.36, 1.96, 2.96});   // a wall behind it: face at x = 4.0
  DepthCamera cam(smallCameraWithMethod(), w.finish());
  std::vector<float> depth;
  ASSERT_TRUE(cam.render(lookingAlongX({0.0, 0.0, 1.0}), &depth));
  const PinholeCamera& k = cam.config().camera;
  auto at = [&](int u, int v) { return depth[size_t(v) * k.width + u]; };
  EXPECT_NEAR(at(40, 30), 2.0, 1e-6);  // the box occludes the wall
  EXPECT_NEAR(at(40, 25), 2.0, 1e-6);  // the face is perpendicular to the optical axis: same depth
  EXPECT_NEAR(at(20, 30), 4.0, 1e-6);  // beside the box: the wall (1.56 m to the side at 4 m)
  int box = 0, wall = 0;
  for (float d : depth) {
    box += std::abs(d - 2.0f) < 1e-4f;
    wall += std::abs(d - 4.0f) < 1e-4f;
  }
  // The box spans 1 m x 1 m at 2 m: about (50 * 1 / 2)^2 = 625 pixels.
  EXPECT_NEAR(box, 625, 60);
  EXPECT_GT(wall, 1000);
  EXPECT_FALSE(cam.render(lookingAlongX({NAN, 0.0, 1.0}), &depth));
}

TEST_P(DepthCameraMethods, AgreesWithAFineRayMarchInAForest) {
  SyntheticScene w({10.0, 10.0, 3.0}, 0.1, {0.0, 0.0, 0.0});
  generateForest(ForestConfig::preset(ObstacleDensity::kHigh), 3, w.occupancy.get());
  const EsdfMap& map = w.finish();
  DepthCamera::Config c = smallCameraWithMethod();
  DepthCamera cam(c, map);
  Eigen::Isometry3d T = lookingAlongX({0.5, 5.0, 1.5});
  T.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()) * T.linear();
  std::vector<float> depth;
  ASSERT_TRUE(cam.render(T, &depth));
  int compared = 0, agree = 0, hits = 0;
  for (int v = 0; v < c.camera.height; v += 3)
    for (int u = 0; u < c.camera.width; u += 3) {
      const Eigen::Vector3d ray((u - c.camera.cx) / c.camera.fx, (v - c.camera.cy) / c.camera.fy, 1.0);
      const Eigen::Vector3d dir = T.linear() * ray.normalized();
      double expected = INFINITY;
      for (double t = 0.0; t <= c.max_range_m; t += 0.002) {
        const VoxelState s = w.occupancy->state(Eigen::Vector3d(T.translation() + dir * t));
        if (s == VoxelState::kOutOfMap) break;
        if (s == VoxelState::kOccupied) {
          expected = t / ray.norm();
          break;
        }
      }
      const float got = depth[size_t(v) * c.camera.width + u];
      ++compared;
      hits += std::isfinite(expected);
      agree += (std::isinf(expected) && std::isinf(got)) || std::abs(got - expected) < 0.003;
    }
  EXPECT_GT(hits, compared / 4);
  EXPECT_GE(agree, compared - 2) << agree << " of " << compared;  // grazing rays may differ
}

TEST_P(DepthCameraMethods, RangeLimitsNoiseAndMillimetres) {
  SyntheticScene w({8.0, 6.0, 3.0}, 0.1, {-1.0, -3.0, 0.0});
  w.box({0.04, -2.96, 0.04}, {0.16, 2.96, 2.96});  // a wall whose face is at x = 0
  DepthCamera::Config c = smallCameraWithMethod();
  c.min_range_m = 0.1;
  DepthCamera near_cam(c, w.finish());
  std::vector<float> depth;
  near_cam.render(lookingAlongX({-0.01, 0.0, 1.0}), &depth);
  EXPECT_TRUE(std::isnan(depth[size_t(30) * 80 + 40]));  // closer than min range
  near_cam.render(lookingAlongX({-0.95, 0.0, 1.0}), &depth);
  EXPECT_NEAR(depth[size_t(30) * 80 + 40], 0.95, 1e-6);
  DepthCamera::Config far_c = c;
  far_c.max_range_m = 0.5;
  DepthCamera far_cam(far_c, *w.esdf);
  far_cam.render(lookingAlongX({-0.95, 0.0, 1.0}), &depth);
  EXPECT_TRUE(std::isinf(depth[size_t(30) * 80 + 40]));  // beyond max range: no return
  std::vector<uint16_t> mm;
  DepthCamera::toMillimetres({1.2345f, INFINITY, NAN, 100.0f, -1.0f}, &mm);
  EXPECT_EQ(mm, (std::vector<uint16_t>{1235, 0, 0, 65535, 0}));
  // Noise: seeded, about sigma * z^2.
  DepthCamera::Config noisy = c;
  noisy.noise_stddev_at_1m = 0.01;
  DepthCamera a(noisy, *w.esdf), b(noisy, *w.esdf);
  std::vector<float> da, db;
  a.render(lookingAlongX({-0.95, 0.0, 1.0}), &da);
  b.render(lookingAlongX({-0.95, 0.0, 1.0}), &db);
  EXPECT_EQ(da, db);
  double sum_sq = 0.0;
  int n = 0;
  for (float d : da)
    if (std::isfinite(d)) {
      sum_sq += (d - 0.95) * (d - 0.95);
      ++n;
    }
  EXPECT_NEAR(std::sqrt(sum_sq / n), 0.01 * 0.95 * 0.95, 0.003);
}

// The depth of every pixel seeing a plane at a known distance, from a tilted camera: exact per pixel
// (1/z is affine over a planar face), not only on the optical axis.
TEST_P(DepthCameraMethods, ExactDepthOnATiltedView) {
  SyntheticScene w({8.0, 6.0, 3.0}, 0.1, {-1.0, -3.0, 0.0});
  w.box({2.04, -2.46, 0.04}, {2.36, 2.46, 2.96});  // a wall whose face is at x = 2.0, |y| <= 2.5, z in [0, 3]
  DepthCamera::Config c = smallCameraWithMethod();
  DepthCamera cam(c, w.finish());
  Eigen::Isometry3d T = lookingAlongX({0.13, 0.07, 1.21});
  T.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()) *
               T.linear();
  std::vector<float> depth;
  ASSERT_TRUE(cam.render(T, &depth));
  int checked = 0;
  for (int v = 0; v < c.camera.height; ++v)
    for (int u = 0; u < c.camera.width; ++u) {
      const Eigen::Vector3d dir = T.linear() * Eigen::Vector3d((u - c.camera.cx) / c.camera.fx, (v - c.camera.cy) / c.camera.fy, 1.0);
      const double z = (2.0 - T.translation().x()) / dir.x();  // dir has unit optical z: z is the depth
      const Eigen::Vector3d hit = T.translation() + z * dir;
      if (!(z > 0.0) || std::abs(hit.y()) > 2.49 || hit.z() < 0.01 || hit.z() > 2.99) continue;
      ++checked;
      ASSERT_NEAR(depth[size_t(v) * c.camera.width + u], z, 2e-5) << u << ", " << v;
    }
  EXPECT_GT(checked, c.camera.width * c.camera.height / 2);
}

TEST_P(DepthCameraMethods, OccludedBoxIsNotSeen) {
  auto scene = [](bool with_front_box) {
    auto w = std::make_unique<SyntheticScene>(Eigen::Vector3d(8.0, 6.0, 3.0), 0.1, Eigen::Vector3d(-1.0, -3.0, 0.0));
    if (with_front_box) w->box({2.04, -0.76, 0.24}, {2.36, 0.76, 1.76});  // 1.6 m square face at x = 2
    w->box({3.04, -0.26, 0.74}, {3.36, 0.26, 1.26});                      // 0.6 m box behind it, face at x = 3
    w->finish();
    return w;
  };
  auto count_at = [](const std::vector<float>& depth, float z) {
    return std::count_if(depth.begin(), depth.end(), [z](float d) { return std::abs(d - z) < 1e-3f; });
  };
  std::vector<float> depth;
  const auto alone = scene(false);
  DepthCamera see(smallCameraWithMethod(), *alone->esdf);
  ASSERT_TRUE(see.render(lookingAlongX({0.0, 0.0, 1.0}), &depth));
  EXPECT_NEAR(count_at(depth, 3.0f), (50 * 0.6 / 3) * (50 * 0.6 / 3), 25);  // seen when nothing is in front
  const auto hidden = scene(true);
  DepthCamera occluded(smallCameraWithMethod(), *hidden->esdf);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.0, 0.0, 1.0), Eigen::Vector3d(0.4, 0.2, 0.9)}) {
    ASSERT_TRUE(occluded.render(lookingAlongX(p), &depth));
    EXPECT_EQ(count_at(depth, 3.0f - float(p.x())), 0);
    EXPECT_GT(count_at(depth, 2.0f - float(p.x())), 900);
  }
}

TEST_P(DepthCameraMethods, InvalidPosesAndDegenerateViewpoints) {
  SyntheticScene w({4.0, 4.0, 3.0}, 0.1, {-1.0, -2.0, 0.0});
  w.box({1.04, -0.46, 0.54}, {1.36, 0.46, 1.46});
  DepthCamera cam(smallCameraWithMethod(), w.finish());
  const std::vector<float> untouched(7, 42.0f);
  std::vector<float> depth = untouched;
  EXPECT_FALSE(cam.render(lookingAlongX({NAN, 0.0, 1.0}), &depth));
  EXPECT_FALSE(cam.render(lookingAlongX({0.0, INFINITY, 1.0}), &depth));
  Eigen::Isometry3d bad_rotation = lookingAlongX({0.0, 0.0, 1.0});
  bad_rotation.linear()(1, 2) = NAN;
  EXPECT_FALSE(cam.render(bad_rotation, &depth));
  EXPECT_EQ(depth, untouched);
  // Outside the map: nothing seen. Inside an obstacle: depth 0, below the minimum range.
  ASSERT_TRUE(cam.render(lookingAlongX({-5.0, 0.0, 1.0}), &depth));
  EXPECT_TRUE(std::all_of(depth.begin(), depth.end(), [](float d) { return std::isinf(d) && d > 0.0f; }));
  ASSERT_TRUE(cam.render(lookingAlongX({1.2, 0.0, 1.0}), &depth));
  EXPECT_TRUE(std::all_of(depth.begin(), depth.end(), [](float d) { return std::isnan(d); }));
  EXPECT_EQ(depth.size(), size_t(80 * 60));
}

// Every pixel centre on a voxel corner (the wall at 5 m, 50 px focal length, principal point on a
// pixel: rays every 0.1 m on the wall): the faces sharing an edge cover it from both sides, so no
// pixel falls between them and sees through.
TEST_P(DepthCameraMethods, WatertightWherePixelsFallOnVoxelEdges) {
  SyntheticScene w({8.0, 10.0, 6.0}, 0.1, {-1.0, -5.0, -2.0});
  w.box({5.04, -4.46, -1.46}, {5.36, 4.46, 3.46});  // face at x = 5, y in [-4.5, 4.5], z in [-1.5, 3.5]
  DepthCamera::Config c = smallCameraWithMethod();
  c.camera.cx = 40.0;
  c.camera.cy = 30.0;
  c.max_range_m = 10.0;
  DepthCamera cam(c, w.finish());
  std::vector<float> depth;
  ASSERT_TRUE(cam.render(lookingAlongX({0.0, 0.0, 1.0}), &depth));
  int checked = 0;
  for (int v = 0; v < c.camera.height; ++v)
    for (int u = 0; u < c.camera.width; ++u) {
      // The wall's own silhouette (a grazing ray along its outer edge) is not a seam: skip it.
      if (std::abs(u - 40) >= 45 || v <= 5 || v >= 55) continue;
      ++checked;
      ASSERT_NEAR(depth[size_t(v) * c.camera.width + u], 5.0, 1e-5) << u << ", " << v;
    }
  EXPECT_EQ(checked, 80 * 49);
}

INSTANTIATE_TEST_SUITE_P(Renderers, DepthCameraMethods,
                         ::testing::Values(DepthCamera::Method::kRasterize, DepthCamera::Method::kRaycast),
                         [](const ::testing::TestParamInfo<DepthCamera::Method>& info) {
                           return std::string(DepthCamera::toString(info.param));
                         });

// The rasteriser against the raycast (the oracle) in a seeded forest, from seeded random poses in
// free space. Not every pixel agrees exactly: a pixel centre that lies (to rounding) on a voxel edge
// or corner may be given to either voxel by the raycast's voxel walk and to the nearer face by the
// rasteriser, and a hit within rounding of the maximum range may fall on either side of it. Those
// pixels are a small fraction; none may see through an obstacle.
TEST(DepthCamera, RasterMatchesTheRaycastInAForest) {
  SyntheticScene w({10.0, 10.0, 3.0}, 0.1, {0.0, 0.0, 0.0});
  generateForest(ForestConfig::preset(ObstacleDensity::kHigh), 7, w.occupancy.get());
  const EsdfMap& map = w.finish();
  DepthCamera::Config c;  // the default intrinsics at half resolution (same field of view)
  c.camera.width = 320;
  c.camera.height = 240;
  c.camera.fx /= 2.0;
  c.camera.fy /= 2.0;
  c.camera.cx = (c.camera.cx + 0.5) / 2.0 - 0.5;
  c.camera.cy = (c.camera.cy + 0.5) / 2.0 - 0.5;
  DepthCamera::Config oracle_config = c;
  oracle_config.method = DepthCamera::Method::kRaycast;
  DepthCamera raster(c, map), oracle(oracle_config, map);
  EXPECT_GT(raster.numSurfaceFaces(), 10000u);

  std::mt19937 rng(11);
  std::uniform_real_distribution<double> xy(0.5, 9.5), height(0.3, 2.7), angle(-M_PI, M_PI), tilt(-0.4, 0.4);
  int poses = 0;
  size_t pixels = 0, agree = 0, exact = 0, oracle_hits = 0, see_through = 0, faces_drawn = 0;
  while (poses < 8) {
    Eigen::Isometry3d T = lookingAlongX({xy(rng), xy(rng), height(rng)});
    T.linear() = (Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(tilt(rng), Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(tilt(rng), Eigen::Vector3d::UnitX()))
                     .toRotationMatrix() *
                 T.linear();
    if (w.occupancy->state(Eigen::Vector3d(T.translation())) != VoxelState::kFree) continue;
    ++poses;
    std::vector<float> got, expected;
    ASSERT_TRUE(raster.render(T, &got));
    ASSERT_TRUE(oracle.render(T, &expected));
    faces_drawn += raster.lastRenderStats().faces_drawn;
    for (size_t i = 0; i < got.size(); ++i) {
      const float r = got[i], e = expected[i];
      ++pixels;
      const bool same = (std::isinf(r) && std::isinf(e)) || (std::isnan(r) && std::isnan(e)) ||
                        (std::isfinite(r) && std::isfinite(e) && std::abs(r - e) <= 0.1f);
      agree += same;
      exact += same && !(std::abs(r - e) > 1e-3f);
      if (std::isfinite(e)) {
        ++oracle_hits;
        // Seeing through: no return, or a return more than a voxel behind the oracle's.
        see_through += !(r <= e + 0.1f) && !std::isnan(r);
      }
    }
  }
  EXPECT_GT(oracle_hits, pixels / 5);
  EXPECT_GT(faces_drawn, 1000u);
  EXPECT_GE(double(agree), 0.99 * double(pixels)) << agree << " of " << pixels;
  EXPECT_EQ(see_through, 0u) << "of " << oracle_hits << " oracle hits";
  // Both compute the exact entry depth, so nearly all agree to rounding (all but 1 of 614400 pixels
  // agree within 0.1 mm when written).
  EXPECT_GE(double(exact), 0.999 * double(pixels)) << exact << " of " << pixels << " within 1 mm";
}

}  // namespace
}  // namespace topo_planner
