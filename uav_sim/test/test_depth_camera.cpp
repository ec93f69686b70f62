#include <gtest/gtest.h>

#include <memory>

#include "plan_env/map_generator.h"
#include "plan_env/synthetic_scene.h"
#include "uav_sim/depth_camera.h"

namespace topo_planner {
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

TEST(DepthCamera, BoxAtTheRightDepthWithOcclusion) {
  SyntheticScene w({8.0, 6.0, 3.0}, 0.1, {-1.0, -3.0, 0.0});
  // Bounds 1 cm beyond the voxel centres they mean to include (centres lie on a 0.1 m grid).
  w.box({2.04, -0.46, 0.54}, {2.66, 0.46, 1.46});   // near box, 1 m x 1 m face at x = 2.0
  w.box({4.04, -1.96, 0.04}, {4.36, 1.96, 2.96});   // a wall behind it: face at x = 4.0
  DepthCamera cam(smallCamera(), w.finish());
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

TEST(DepthCamera, AgreesWithAFineRayMarchInAForest) {
  SyntheticScene w({10.0, 10.0, 3.0}, 0.1, {0.0, 0.0, 0.0});
  generateForest(ForestConfig::preset(ObstacleDensity::kHigh), 3, w.occupancy.get());
  const EsdfMap& map = w.finish();
  DepthCamera::Config c = smallCamera();
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

TEST(DepthCamera, RangeLimitsNoiseAndMillimetres) {
  SyntheticScene w({8.0, 6.0, 3.0}, 0.1, {-1.0, -3.0, 0.0});
  w.box({0.04, -2.96, 0.04}, {0.16, 2.96, 2.96});  // a wall whose face is at x = 0
  DepthCamera::Config c = smallCamera();
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

}  // namespace
}  // namespace topo_planner
