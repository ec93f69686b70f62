// make bench-camera: the simulated depth camera at its default 640 x 480, one thread, rasteriser vs
// raycast side by side on the same frames: 100 poses along a path through the simulator's medium
// forest (24 x 20 m, obstacles 0..3 m high, 0.1 m voxels; the RESULT line) and a high-density one,
// the camera looking along the path with a yaw sway. Each frame is rendered by both; the table gives
// median and p95 ms per frame, frames/s and how many pixels of the rasterised image agree with the
// raycast within one voxel.
//   --frames N   frames along the path (default 100)
//   --seed S     forest seed (default 1)
#include <sched.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "topo_planner/plan_env/synthetic_scene.h"
#include "topo_planner/plan_env/timing.h"
#include "topo_planner/uav_sim/depth_camera.h"

using namespace topo_planner;

namespace {

std::string loadAverage() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

// Optical frame at p looking along the horizontal heading yaw (x right, y down, z forward).
Eigen::Isometry3d cameraPose(const Eigen::Vector3d& p, double yaw) {
  const Eigen::Vector3d z(std::cos(yaw), std::sin(yaw), 0.0), x(std::sin(yaw), -std::cos(yaw), 0.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = p;
  return T;
}

void row(const char* name, const std::vector<double>& ms, const char* extra) {
  const double median = percentile(ms, 0.5);
  std::printf("| %-40s | %9.3f | %9.3f | %9.3f | %8.1f | %s\n", name, median, percentile(ms, 0.95), percentile(ms, 1.0),
              1000.0 / median, extra);
}

struct SceneResult {
  std::vector<double> raster_ms, raycast_ms, noisy_ms, mm_ms, agree_pct, hits_pct, faces, fragments;
};

// Renders the path through a forest of the given density with every variant.
SceneResult runScene(ObstacleDensity density, uint32_t seed, const std::vector<Eigen::Vector3d>& path,
                     const std::vector<double>& yaw) {
  SyntheticScene world({24.0, 20.0, 4.0}, 0.1, {-12.0, -10.0, 0.0});
  ForestConfig forest = ForestConfig::preset(density);
  for (const Eigen::Vector3d& p : path) forest.keep_free.push_back(p);
  forest.keep_free_radius_m = 0.5;
  const int obstacles = generateForest(forest, seed, world.occupancy.get());
  const EsdfMap& map = world.finish();

  DepthCamera::Config raster_config;  // defaults: 640 x 480, 0.1 - 6 m, no noise
  DepthCamera::Config raycast_config = raster_config;
  raycast_config.method = DepthCamera::Method::kRaycast;
  DepthCamera::Config noisy_config = raster_config;
  noisy_config.noise_stddev_at_1m = 0.005;
  double t0 = nowMs();
  DepthCamera raster(raster_config, map);
  const double build_ms = nowMs() - t0;
  DepthCamera raycast(raycast_config, map), noisy(noisy_config, map);
  std::printf("# %s forest, seed %u: %d obstacles, %zu occupied voxels, %zu exposed faces (face list built in %.1f ms)\n",
              toString(density), seed, obstacles, world.occupancy->countState(VoxelState::kOccupied),
              raster.numSurfaceFaces(), build_ms);

  SceneResult r;
  std::vector<float> a, b, c;
  std::vector<uint16_t> mm;
  raster.render(cameraPose(path[0], yaw[0]), &a);  // warm-up (allocates the buffers)
  for (size_t i = 0; i < path.size(); ++i) {
    const Eigen::Isometry3d T = cameraPose(path[i], yaw[i]);
    t0 = nowMs();
    raster.render(T, &a);
    r.raster_ms.push_back(nowMs() - t0);
    r.faces.push_back(raster.lastRenderStats().faces_drawn);
    r.fragments.push_back(double(raster.lastRenderStats().fragments));
    t0 = nowMs();
    raycast.render(T, &b);
    r.raycast_ms.push_back(nowMs() - t0);
    t0 = nowMs();
    noisy.render(T, &c);
    r.noisy_ms.push_back(nowMs() - t0);
    t0 = nowMs();
    DepthCamera::toMillimetres(a, &mm);
    r.mm_ms.push_back(nowMs() - t0);
    size_t agree = 0, hits = 0;
    for (size_t k = 0; k < a.size(); ++k) {
      agree += (std::isinf(a[k]) && std::isinf(b[k])) || (std::isnan(a[k]) && std::isnan(b[k])) ||
               std::abs(a[k] - b[k]) <= 0.1f;
      hits += std::isfinite(b[k]);
    }
    r.agree_pct.push_back(100.0 * double(agree) / double(a.size()));
    r.hits_pct.push_back(100.0 * double(hits) / double(a.size()));
  }
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 100;
  uint32_t seed = 1;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--frames")) frames = std::max(2, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--seed")) seed = uint32_t(std::atoi(argv[i + 1]));
  }
  // One core: the camera is single-threaded; pinning keeps the scheduler from moving it mid-frame.
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(0, &one);
  const bool pinned = sched_setaffinity(0, sizeof(one), &one) == 0;

  // The path: x from -10 to 10, weaving in y and z, the camera looking along it with a yaw sway;
  // the forest keeps 0.5 m of clearance around it (as the planner would).
  std::vector<Eigen::Vector3d> path;
  std::vector<double> yaw;
  for (int i = 0; i < frames; ++i) {
    const double s = double(i) / (frames - 1);
    path.emplace_back(-10.0 + 20.0 * s, 4.0 * std::sin(2.0 * M_PI * s), 1.0 + 0.5 * std::sin(4.0 * M_PI * s));
    const double heading = std::atan2(4.0 * 2.0 * M_PI * std::cos(2.0 * M_PI * s), 20.0);
    yaw.push_back(heading + 0.35 * std::sin(6.0 * M_PI * s));
  }
  const DepthCamera::Config defaults;
  std::printf("# bench_camera: %d x %d, fx %.1f, range %.1f-%.1f m, %d frames per forest (24 x 20 x 4 m, 0.1 m), "
              "one thread%s\n",
              defaults.camera.width, defaults.camera.height, defaults.camera.fx, defaults.min_range_m,
              defaults.max_range_m, frames, pinned ? " pinned to cpu 0" : "");
  const std::string load_before = loadAverage();
  const SceneResult medium = runScene(ObstacleDensity::kMedium, seed, path, yaw);
  const SceneResult high = runScene(ObstacleDensity::kHigh, seed, path, yaw);
  std::printf("# load average (1, 5, 15 min) before: %s, after: %s\n\n", load_before.c_str(), loadAverage().c_str());

  std::printf("| %-40s | %9s | %9s | %9s | %8s | %s\n", "forest: renderer", "median ms", "p95 ms", "max ms", "fps", "notes");
  std::printf("|%s|%s|%s|%s|%s|%s\n", std::string(42, '-').c_str(), std::string(11, '-').c_str(),
              std::string(11, '-').c_str(), std::string(11, '-').c_str(), std::string(10, '-').c_str(),
              std::string(40, '-').c_str());
  const double pixels = double(defaults.camera.width) * defaults.camera.height;
  for (const auto& [name, r] : {std::pair<const char*, const SceneResult&>{"medium", medium}, {"high", high}}) {
    char label[64], note[200];
    std::snprintf(note, sizeof(note), "faces drawn median %.0f, fragments median %.0f (%.2f per pixel)",
                  percentile(r.faces, 0.5), percentile(r.fragments, 0.5), percentile(r.fragments, 0.5) / pixels);
    std::snprintf(label, sizeof(label), "%s: rasterize (z-buffer of faces)", name);
    row(label, r.raster_ms, note);
    std::snprintf(label, sizeof(label), "%s: rasterize + noise (5 mm at 1 m)", name);
    row(label, r.noisy_ms, "one Gaussian draw per valid pixel");
    std::snprintf(note, sizeof(note), "pixels with a return: median %.1f %%, p95 %.1f %%", percentile(r.hits_pct, 0.5),
                  percentile(r.hits_pct, 0.95));
    std::snprintf(label, sizeof(label), "%s: raycast (sphere tracing, oracle)", name);
    row(label, r.raycast_ms, note);
    std::snprintf(label, sizeof(label), "%s: 32FC1 -> 16UC1 millimetres", name);
    row(label, r.mm_ms, "");
  }
  std::printf("\n");
  for (const auto& [name, r] : {std::pair<const char*, const SceneResult&>{"medium", medium}, {"high", high}}) {
    const double raster_median = percentile(r.raster_ms, 0.5);
    std::printf("%-6s speedup raycast / rasterize (median) %.1fx; rasterize p95 uses %.1f %% of one core at 30 Hz; "
                "pixels agreeing with the raycast within one voxel: median %.3f %%, worst frame %.3f %%\n",
                name, percentile(r.raycast_ms, 0.5) / raster_median, 100.0 * percentile(r.raster_ms, 0.95) / (1000.0 / 30.0),
                percentile(r.agree_pct, 0.5), percentile(r.agree_pct, 0.0));
  }
  const double raster_median = percentile(medium.raster_ms, 0.5);
  std::printf("\nRESULT camera_raster_ms_median=%.3f camera_raster_ms_p95=%.3f camera_raycast_ms_median=%.3f "
              "fps_median=%.1f\n",
              raster_median, percentile(medium.raster_ms, 0.95), percentile(medium.raycast_ms, 0.5), 1000.0 / raster_median);
  return 0;
}
