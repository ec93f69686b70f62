// make demo (until the closed-loop simulation lands): maps a forest_gen forest from scratch with a
// simulated 640 x 480 depth camera flying a circle through it, keeps the ESDF up to date after every
// frame, and compares the result with the ground truth. Prints a line per frame, a report, and writes
// results/map_demo_esdf.png (ESDF slice at the flight height with the mapped obstacles and the path).
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>

#include "topo_planner/plan_env/timing.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/map_io.h"
#include "voxel_depth_renderer.h"

using namespace topo_planner;

int main(int argc, char** argv) {
  std::string map_path, out_dir = "results";
  int frames = 72;
  double height = 1.5, radius = 3.5;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--map")) map_path = argv[i + 1];
    if (!std::strcmp(argv[i], "--out")) out_dir = argv[i + 1];
    if (!std::strcmp(argv[i], "--frames")) frames = std::max(4, std::atoi(argv[i + 1]));
  }
  if (map_path.empty()) {
    std::fprintf(stderr, "usage: map_demo --map FILE.bt|FILE.pcd [--out DIR] [--frames N]\n");
    return 2;
  }
  MapFile file;
  std::string err;
  if (readMapFile(map_path, &file, &err) != MapStatus::kSuccess) {
    std::fprintf(stderr, "map_demo: %s\n", err.c_str());
    return 1;
  }
  OccupancyMap::Config oc = configFittingMapFile(file, OccupancyMap::Config(), 0.0);
  auto truth = std::shared_ptr<OccupancyMap>(OccupancyMap::create(oc, &err));
  auto online = std::shared_ptr<OccupancyMap>(OccupancyMap::create(oc, &err));
  if (!truth || !online) {
    std::fprintf(stderr, "map_demo: %s\n", err.c_str());
    return 1;
  }
  insertMapFile(file, truth.get());
  auto esdf = EsdfMap::create(EsdfMap::Config(), online, &err);
  esdf->updateAll();
  const Eigen::Vector3d centre = 0.5 * (truth->geometry().windowMin() + truth->geometry().windowMax());
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  std::printf("map_demo: %s, %d x %d x %d voxels, camera 640x480 circling r=%.1f m at z=%.1f m, %d frames\n",
              map_path.c_str(), oc.size_m.x() > 0 ? truth->geometry().size().x() : 0, truth->geometry().size().y(),
              truth->geometry().size().z(), radius, height, frames);

  // Camera positions on the circle, moved in or out to the nearest point with 0.6 m clearance.
  auto truth_esdf = EsdfMap::create(EsdfMap::Config(), truth, &err);
  truth_esdf->updateAll();
  auto clearPoint = [&](double a) {
    for (double dr = 0.0; dr < 3.0; dr += 0.05)
      for (double sign : {1.0, -1.0}) {
        const double r = radius + sign * dr;
        const Eigen::Vector3d p(centre.x() + r * std::cos(a), centre.y() + r * std::sin(a), height);
        const DistanceQuery q = truth_esdf->query(p);
        if ((q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown) && q.distance > 0.6) return p;
      }
    return Eigen::Vector3d(centre.x() + radius * std::cos(a), centre.y() + radius * std::sin(a), height);
  };

  const PinholeCamera cam;
  int skipped = 0;
  std::vector<double> fuse_ms, esdf_ms;
  std::vector<Eigen::Vector3d> path;
  for (int f = 0; f < frames; ++f) {
    const double a = 2.0 * M_PI * f / frames;
    const Eigen::Vector3d p = clearPoint(a);
    // Look along the circle, turned 30 degrees inwards.
    const double yaw = a + M_PI / 2 + M_PI / 6;
    const Eigen::Isometry3d T = cameraLookingAt(p, Eigen::Vector3d(std::cos(yaw), std::sin(yaw), -0.1));
    path.push_back(p);
    const std::vector<float> depth = renderDepth(*truth, cam, T, 6.0);
    const double t0 = nowMs();
    const FusionResult r = online->fuseDepthImage(depthView(depth, cam), cam, T);
    const double t1 = nowMs();
    const EsdfUpdateStats s = esdf->update(r.changed_box);
    const double t2 = nowMs();
    fuse_ms.push_back(t1 - t0);
    esdf_ms.push_back(t2 - t1);
    if (r.status != MapStatus::kSuccess) {  // e.g. a wall closer than the minimum range: map unchanged
      std::printf("frame %3d  skipped: %s\n", f, toString(r.status));
      ++skipped;
      continue;
    }
    std::printf("frame %3d  pos (%5.2f, %5.2f, %4.2f)  rays %6d  voxels updated %6d  fuse %6.2f ms  esdf %6.2f ms "
                "(%lld voxels)\n",
                f, p.x(), p.y(), p.z(), r.rays, r.voxels_updated, t1 - t0, t2 - t1,
                static_cast<long long>(s.written_box.volume()));
  }

  // Agreement with the ground truth, and the ESDF against a full recompute.
  size_t true_pos = 0, false_pos = 0, missed_seen = 0, known = 0;
  const VoxelBox w = truth->geometry().windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        const VoxelState m = online->state(i), t = truth->state(i);
        if (m == VoxelState::kUnknown) continue;
        ++known;
        if (m == VoxelState::kOccupied) (t == VoxelState::kOccupied ? true_pos : false_pos)++;
        if (m == VoxelState::kFree && t == VoxelState::kOccupied) ++missed_seen;
      }
  auto full = EsdfMap::create(EsdfMap::Config(), online, &err);
  full->updateAll();
  const bool esdf_exact = full->distances() == esdf->distances();
  const double precision = true_pos + false_pos ? double(true_pos) / double(true_pos + false_pos) : 0.0;

  // Picture: ESDF slice at the flight height, obstacles black, path white.
  const int nx = w.size().x(), ny = w.size().y(), scale = 6;
  cv::Mat img(ny * scale, nx * scale, CV_8UC3);
  const int zi = truth->geometry().indexOf(Eigen::Vector3d(0, 0, height)).z();
  for (int y = 0; y < ny; ++y)
    for (int x = 0; x < nx; ++x) {
      const Eigen::Vector3i v(w.min.x() + x, w.min.y() + y, zi);
      double d = 0.0;
      const QueryStatus qs = esdf->distance(v, &d);
      cv::Vec3b colour(60, 60, 60);  // unknown: grey
      if (online->state(v) == VoxelState::kOccupied) {
        colour = cv::Vec3b(0, 0, 0);
      } else if (qs == QueryStatus::kOk) {
        cv::Mat one(1, 1, CV_8UC1, cv::Scalar(int(255.0 * std::min(1.0, d / esdf->config().max_distance_m))));
        cv::Mat c;
        cv::applyColorMap(one, c, cv::COLORMAP_JET);
        colour = c.at<cv::Vec3b>(0, 0);
      }
      cv::rectangle(img, cv::Rect(x * scale, (ny - 1 - y) * scale, scale, scale), cv::Scalar(colour), cv::FILLED);
    }
  for (size_t k = 0; k < path.size(); ++k) {
    const Eigen::Vector3i v = truth->geometry().indexOf(path[k]) - w.min;
    cv::circle(img, cv::Point(v.x() * scale + scale / 2, (ny - 1 - v.y()) * scale + scale / 2), 3,
               cv::Scalar(255, 255, 255), cv::FILLED);
  }
  const std::string png = out_dir + "/map_demo_esdf.png";
  const bool wrote = cv::imwrite(png, img);

  std::printf("\n== map_demo report ==\n");
  std::printf("frames                 %d (%d skipped)\n", frames, skipped);
  std::printf("fusion                 median %.2f ms, p95 %.2f ms per 640x480 frame (pixel skip %d)\n",
              percentile(fuse_ms, 0.5), percentile(fuse_ms, 0.95), oc.depth_pixel_skip);
  std::printf("incremental ESDF       median %.2f ms, p95 %.2f ms per frame\n", percentile(esdf_ms, 0.5),
              percentile(esdf_ms, 0.95));
  std::printf("known voxels           %zu of %zu\n", known, truth->geometry().numVoxels());
  std::printf("occupied voxels        %zu mapped, %zu truly occupied (precision %.4f)\n", true_pos + false_pos,
              true_pos, precision);
  std::printf("ESDF after %d updates  %s a full recompute\n", frames, esdf_exact ? "equals" : "DIFFERS FROM");
  std::printf("picture                %s%s\n", png.c_str(), wrote ? "" : " (could not be written)");
  return (esdf_exact && precision > 0.95 && wrote && skipped < frames / 4) ? 0 : 1;
}
