// make bench-env: the mapping core against octomap's DynamicEDT3D on the same forest_gen grid.
//   full ESDF of a 10 x 10 x 4 m, 0.1 m map (400k voxels) from forest0.bt: ours (1 and 2 threads,
//   both signs) vs DynamicEDTOctomap (unsigned) built from the same octree;
//   incremental ESDF and depth fusion (pixel skip 1 and 2) for 640 x 480 frames of that forest.
// DynamicEDT3D is optional (TOPO_PLANNER_HAVE_DYNAMICEDT3D, found at configure time): without it
// its row is skipped with a message and its RESULT keys are left out.
#ifdef TOPO_PLANNER_HAVE_DYNAMICEDT3D
#include <dynamicEDT3D/dynamicEDTOctomap.h>
#endif
#include <octomap/OcTree.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "topo_planner/plan_env/timing.h"
#include "../tools/voxel_depth_renderer.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/map_io.h"

using namespace topo_planner;

namespace {

struct Stats {
  double median, p95, min;
};
Stats summarize(const std::vector<double>& v) { return {percentile(v, 0.5), percentile(v, 0.95), percentile(v, 0.0)}; }

void row(const char* name, const char* what, const std::vector<double>& samples) {
  const Stats s = summarize(samples);
  std::printf("| %-34s | %-30s | %9.3f | %9.3f | %5zu |\n", name, what, s.median, s.p95, samples.size());
}

}  // namespace

int main(int argc, char** argv) {
  std::string map_path = std::string(TOPO_PLANNER_TEST_DATA_DIR) + "/forest0.bt";
  int reps = 30;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--map")) map_path = argv[i + 1];
    if (!std::strcmp(argv[i], "--reps")) reps = std::max(3, std::atoi(argv[i + 1]));
  }
  const double max_distance = 2.0;

  // The grid: 10 x 10 x 4 m at 0.1 m over the forest.
  MapFile file;
  std::string err;
  if (readMapFile(map_path, &file, &err) != MapStatus::kSuccess) {
    std::fprintf(stderr, "bench_env: %s\n", err.c_str());
    return 1;
  }
  OccupancyMap::Config oc;
  oc.resolution_m = 0.1;
  oc.size_m = {10.0, 10.0, 4.0};
  oc.origin_m = {-5.0, -5.0, 0.0};
  auto truth = std::shared_ptr<OccupancyMap>(OccupancyMap::create(oc, &err));
  insertMapFile(file, truth.get());
  const size_t voxels = truth->geometry().numVoxels();

  std::printf("# bench_env: %s, grid %d x %d x %d = %zu voxels at %.2f m, %zu occupied, truncation %.1f m\n\n",
              map_path.c_str(), truth->geometry().size().x(), truth->geometry().size().y(),
              truth->geometry().size().z(), voxels, oc.resolution_m, truth->countState(VoxelState::kOccupied),
              max_distance);
  std::printf("| %-34s | %-30s | %9s | %9s | %5s |\n", "method", "operation", "median ms", "p95 ms", "runs");
  std::printf("|%s|%s|%s|%s|%s|\n", std::string(36, '-').c_str(), std::string(32, '-').c_str(),
              std::string(11, '-').c_str(), std::string(11, '-').c_str(), std::string(7, '-').c_str());

  // Full signed ESDF, ours.
  std::vector<double> ours1, ours2;
  std::unique_ptr<EsdfMap> esdf2;
  for (int threads : {1, 2}) {
    EsdfMap::Config ec;
    ec.max_distance_m = max_distance;
    ec.num_threads = threads;
    auto esdf = EsdfMap::create(ec, truth, &err);
    esdf->updateAll();  // warm-up (allocates the scratch)
    for (int r = 0; r < reps; ++r) {
      const double t0 = nowMs();
      esdf->updateAll();
      (threads == 1 ? ours1 : ours2).push_back(nowMs() - t0);
    }
    if (threads == 2) esdf2 = std::move(esdf);
  }
  row("ours, signed ESDF, 1 thread", "full ESDF (both signs)", ours1);
  row("ours, signed ESDF, 2 threads", "full ESDF (both signs)", ours2);

  std::vector<double> dyn;
  double max_abs_diff = 0.0;
  size_t compared = 0, agree = 0;
#ifdef TOPO_PLANNER_HAVE_DYNAMICEDT3D
  // DynamicEDT3D from the same octree, same box, same maximum distance.
  octomap::OcTree tree(0.1);
  if (!tree.readBinary(map_path)) {
    std::fprintf(stderr, "bench_env: octomap cannot read %s\n", map_path.c_str());
    return 1;
  }
  const octomap::point3d bmin(-5.0f + 0.001f, -5.0f + 0.001f, 0.001f), bmax(5.0f - 0.001f, 5.0f - 0.001f, 4.0f - 0.001f);
  const int dyn_reps = std::max(3, reps / 6);
  for (int r = 0; r < dyn_reps; ++r) {
    const double t0 = nowMs();
    DynamicEDTOctomap edt(float(max_distance), &tree, bmin, bmax, false);
    edt.update();
    dyn.push_back(nowMs() - t0);
    if (r == 0) {  // agreement of the positive field at free voxel centres
      const GridGeometry& g = truth->geometry();
      const VoxelBox w = g.windowBox();
      Eigen::Vector3i i;
      for (i.z() = w.min.z(); i.z() <= w.max.z(); i.z() += 3)
        for (i.y() = w.min.y(); i.y() <= w.max.y(); i.y() += 3)
          for (i.x() = w.min.x(); i.x() <= w.max.x(); i.x() += 3) {
            if (truth->state(i) != VoxelState::kFree) continue;
            const Eigen::Vector3d c = g.centerOf(i);
            const float theirs = edt.getDistance(octomap::point3d(float(c.x()), float(c.y()), float(c.z())));
            if (theirs < 0.0f) continue;  // outside their box
            double ours = 0.0;
            esdf2->distance(i, &ours);
            const double diff = std::abs(std::min(double(theirs), max_distance) - ours);
            max_abs_diff = std::max(max_abs_diff, diff);
            agree += diff < 1e-3;
            ++compared;
          }
    }
  }
  row("DynamicEDT3D (octomap), unsigned", "build + update() from .bt", dyn);
#else
  std::printf("| %-34s | %-30s | %9s | %9s | %5d |\n", "DynamicEDT3D (octomap), unsigned", "skipped: not built with it", "-", "-", 0);
  std::fprintf(stderr, "bench_env: built without DynamicEDT3D (libdynamicedt3d-dev): its row is skipped\n");
#endif

  // Online mapping of the same forest from scratch: 640 x 480 frames along a sweep.
  PinholeCamera cam;  // 640 x 480 defaults
  std::vector<Eigen::Isometry3d> poses;
  const int frames = std::max(10, reps);
  for (int f = 0; f < frames; ++f) {
    const double s = double(f) / (frames - 1);
    const Eigen::Vector3d p(-4.6, -4.0 + 8.0 * s, 1.5);
    const double yaw = -0.6 + 1.2 * s;
    poses.push_back(cameraLookingAt(p, Eigen::Vector3d(std::cos(yaw), std::sin(yaw), -0.05)));
  }
  std::vector<std::vector<float>> images;
  for (const auto& T : poses) images.push_back(renderDepth(*truth, cam, T, 6.0));

  std::vector<double> fuse1, fuse2, incr, incr_volume;
  for (int skip : {1, 2}) {
    OccupancyMap::Config mc = oc;
    mc.depth_pixel_skip = skip;
    mc.max_ray_length_m = 4.5;
    auto online = std::shared_ptr<OccupancyMap>(OccupancyMap::create(mc, &err));
    EsdfMap::Config ec;
    ec.max_distance_m = max_distance;
    auto esdf = EsdfMap::create(ec, online, &err);
    esdf->updateAll();
    for (size_t f = 0; f < poses.size(); ++f) {
      const double t0 = nowMs();
      const FusionResult res = online->fuseDepthImage(depthView(images[f], cam), cam, poses[f]);
      const double t1 = nowMs();
      (skip == 1 ? fuse1 : fuse2).push_back(t1 - t0);
      if (skip == 2) {
        const EsdfUpdateStats st = esdf->update(res.changed_box);
        incr.push_back(nowMs() - t1);
        incr_volume.push_back(double(st.written_box.volume()) / double(voxels));
      }
    }
  }
  row("ours, depth fusion", "640x480 frame, pixel skip 1", fuse1);
  row("ours, depth fusion", "640x480 frame, pixel skip 2", fuse2);
  row("ours, incremental ESDF", "after one frame (skip 2)", incr);

  const double full_ms = summarize(ours2).median, dyn_ms = dyn.empty() ? NAN : summarize(dyn).median;
  if (!dyn.empty())
    std::printf("\nDynamicEDT3D agreement at %zu sampled free voxels: %.2f%% within 1 mm, max |diff| %.4f m\n", compared,
                compared ? 100.0 * agree / compared : 0.0, max_abs_diff);
  std::printf("incremental ESDF rewrote %.0f%% of the window per frame (median)\n",
              100.0 * summarize(incr_volume).median);
  std::printf("\nRESULT esdf_full_ms=%.3f esdf_full_1thread_ms=%.3f", full_ms, summarize(ours1).median);
  if (!dyn.empty()) std::printf(" dynedt_full_ms=%.3f esdf_speedup=%.1f", dyn_ms, dyn_ms / full_ms);
  std::printf(" esdf_incremental_ms=%.3f fuse_skip1_ms=%.3f fuse_skip2_ms=%.3f\n", summarize(incr).median,
              summarize(fuse1).median, summarize(fuse2).median);
  return 0;
}
