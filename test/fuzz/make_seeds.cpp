// Writes the seed corpora of the fuzz harnesses (test/fuzz/corpus/<name>/) from the project's own
// data and code: a window of test/data/forest0.bt saved by the project's map writers (.bt, .ot, PCD
// binary, ASCII and compressed), depth images rendered by the simulated depth camera in that map
// (16UC1 and 32FC1, either byte order, padded rows), clouds of its occupied voxels made by
// pointsToPointCloud2, a B-spline message made by toMsg, goal and path messages, rows of the
// forest_gen tasks file, and the default configs. The message seeds use the harnesses' field layout
// (fuzz_input.h). Usage: fuzz_make_seeds TEST_DATA_DIR CORPUS_DIR [TASKS_CSV]
#include <octomap/OcTree.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "fuzz_input.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/map_io.h"
#include "topo_planner/plan_manage/ros_conversions.h"
#include "topo_planner/plan_manage/trajectory_conversions.h"
#include "topo_planner/uav_sim/depth_camera.h"

namespace {

using namespace topo_planner;
namespace fs = std::filesystem;

void writeFile(const fs::path& path, const std::vector<uint8_t>& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

std::vector<uint8_t> readFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// octomap_fuzz: one selector byte (0 .bt, 1 .ot), then the file.
void octomapSeed(const fs::path& file, uint8_t selector, const fs::path& out) {
  std::vector<uint8_t> bytes{selector};
  const std::vector<uint8_t> body = readFile(file);
  bytes.insert(bytes.end(), body.begin(), body.end());
  writeFile(out, bytes);
}

void imageSeed(const std::vector<float>& depth, int w, int h, bool uint16, bool big_endian, uint32_t pad,
               const fs::path& out) {
  fuzz::FuzzOutput o;
  o.choice(uint16 ? 0 : 1);  // "16UC1" or "32FC1"
  o.integer<uint32_t>(uint32_t(w));
  o.integer<uint32_t>(uint32_t(h));
  const uint32_t bpp = uint16 ? 2 : 4;
  const uint32_t step = uint32_t(w) * bpp + pad;
  o.integer<uint32_t>(step);
  o.flag(big_endian);
  o.flag(false);  // no CameraInfo
  for (int i = 0; i < 7; ++i) o.byte(0);  // default pose
  std::vector<uint16_t> mm;
  DepthCamera::toMillimetres(depth, &mm);
  std::vector<uint8_t> data(size_t(step) * size_t(h), 0);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      uint8_t* px = data.data() + size_t(v) * step + size_t(u) * bpp;
      if (uint16)
        std::memcpy(px, &mm[size_t(v * w + u)], 2);
      else
        std::memcpy(px, &depth[size_t(v * w + u)], 4);
      if (big_endian) std::reverse(px, px + bpp);
    }
  o.append(data);
  writeFile(out, o.bytes());
}

void cloudSeed(const sensor_msgs::PointCloud2& cloud, const fs::path& out) {
  fuzz::FuzzOutput o;
  o.byte(uint8_t(cloud.fields.size()));
  const std::vector<std::string> names{"x", "y", "z", "intensity", "rgb"};
  for (const auto& f : cloud.fields) {
    o.choice(size_t(std::find(names.begin(), names.end(), f.name) - names.begin()));
    o.integer<uint8_t>(f.datatype);
    o.integer<uint32_t>(f.offset);
    o.integer<uint32_t>(f.count);
  }
  o.integer<uint32_t>(cloud.point_step);
  o.integer<uint32_t>(cloud.width);
  o.integer<uint32_t>(cloud.height);
  o.integer<uint32_t>(cloud.row_step);
  o.flag(cloud.is_bigendian);
  for (int i = 0; i < 3; ++i) o.byte(0);  // default sensor origin
  o.append(cloud.data);
  writeFile(out, o.bytes());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: fuzz_make_seeds TEST_DATA_DIR CORPUS_DIR [TASKS_CSV]\n");
    return 2;
  }
  const fs::path data_dir = argv[1], corpus = argv[2];
  const fs::path tmp = fs::temp_directory_path() / "topo_planner_fuzz_seeds";
  fs::create_directories(tmp);

  // A 6 x 6 x 2.5 m window of the forest_gen map at 0.2 m.
  MapFile file;
  std::string why;
  if (readMapFile((data_dir / "forest0.bt").string(), &file, &why) != MapStatus::kSuccess) {
    std::fprintf(stderr, "fuzz_make_seeds: %s\n", why.c_str());
    return 1;
  }
  OccupancyMap::Config mc;
  mc.resolution_m = 0.2;
  mc.size_m = Eigen::Vector3d(6.0, 6.0, 2.5);
  mc.origin_m = Eigen::Vector3d(-3.0, -3.0, -0.5);
  std::shared_ptr<OccupancyMap> map(OccupancyMap::create(mc, &why));
  insertMapFile(file, map.get());

  // Map files.
  const fs::path bt = tmp / "window.bt", ot = tmp / "window.ot", pcd = tmp / "window.pcd";
  saveOctomapFile(*map, bt.string(), &why);
  octomapSeed(bt, 0, corpus / "octomap" / "window_bt");
  {
    octomap::OcTree tree(0.2);
    std::ifstream in(bt, std::ios::binary);
    tree.readBinary(in);
    tree.write(ot.string());
  }
  octomapSeed(ot, 1, corpus / "octomap" / "window_ot");
  {
    octomap::OcTree tiny(0.5);
    tiny.updateNode(octomap::point3d(0.2f, 0.1f, 1.0f), true);
    tiny.updateNode(octomap::point3d(-1.0f, 0.5f, 0.5f), false);
    tiny.writeBinary((tmp / "tiny.bt").string());
    tiny.write((tmp / "tiny.ot").string());
    octomapSeed(tmp / "tiny.bt", 0, corpus / "octomap" / "tiny_bt");
    octomapSeed(tmp / "tiny.ot", 1, corpus / "octomap" / "tiny_ot");
  }
  savePcdFile(*map, pcd.string(), &why);
  writeFile(corpus / "pcd" / "window_binary", readFile(pcd));
  {
    pcl::PointCloud<pcl::PointXYZ> cloud;
    pcl::io::loadPCDFile(pcd.string(), cloud);
    cloud.resize(std::min<size_t>(cloud.size(), 40));
    cloud.width = uint32_t(cloud.size());
    cloud.height = 1;
    pcl::io::savePCDFileASCII((tmp / "a.pcd").string(), cloud);
    writeFile(corpus / "pcd" / "ascii", readFile(tmp / "a.pcd"));
    pcl::io::savePCDFileBinaryCompressed((tmp / "c.pcd").string(), cloud);
    writeFile(corpus / "pcd" / "binary_compressed", readFile(tmp / "c.pcd"));
    pcl::PointCloud<pcl::PointXYZ> empty;
    pcl::io::savePCDFileASCII((tmp / "e.pcd").string(), empty);
    writeFile(corpus / "pcd" / "empty_ascii", readFile(tmp / "e.pcd"));
  }

  // Depth images rendered by the simulated camera, looking along +x from (-2.5, 0, 1).
  EsdfMap::Config ec;
  ec.num_threads = 1;
  std::unique_ptr<EsdfMap> esdf = EsdfMap::create(ec, map, &why);
  esdf->updateAll();
  DepthCamera::Config cc;
  cc.camera.width = 24;
  cc.camera.height = 16;
  cc.camera.fx = cc.camera.fy = 13.0;
  cc.camera.cx = 12.0;
  cc.camera.cy = 8.0;
  DepthCamera camera(cc, *esdf);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  T.translation() = Eigen::Vector3d(-2.0, 0.0, 1.0);
  std::vector<float> depth;
  camera.render(T, &depth);
  imageSeed(depth, 24, 16, true, false, 0, corpus / "depth_image" / "uint16_le");
  imageSeed(depth, 24, 16, false, false, 0, corpus / "depth_image" / "float32_le");
  imageSeed(depth, 24, 16, true, true, 6, corpus / "depth_image" / "uint16_be_padded");
  imageSeed(depth, 24, 16, false, true, 8, corpus / "depth_image" / "float32_be_padded");

  // Clouds of the occupied voxels (the mapping node's ~occupancy), with and without intensity.
  std::vector<Eigen::Vector3d> points;
  map->forEachOccupied([&](const Eigen::Vector3i& i) {
    if (points.size() < 24) points.push_back(map->geometry().centerOf(i));
  });
  sensor_msgs::PointCloud2 cloud;
  pointsToPointCloud2(points, "world", ros::Time(1.0), &cloud);
  cloudSeed(cloud, corpus / "pointcloud2" / "xyz");
  pointsToPointCloud2(points, std::vector<float>(points.size(), 0.5f), "world", ros::Time(1.0), &cloud);
  cloudSeed(cloud, corpus / "pointcloud2" / "xyz_intensity");

  // Trajectory messages: a cubic B-spline along x as the planner publishes it, a goal, waypoints.
  {
    ExecTrajectory t;
    Eigen::MatrixX3d q(8, 3);
    for (int i = 0; i < 8; ++i) q.row(i) << 0.3 * i, 0.05 * i * i, 1.0;
    t.spline = UniformBspline(q, 3, 0.2);
    t.start_time_s = 100.0;
    t.id = 3;
    t.has_heading_target = true;
    t.heading_target = Eigen::Vector3d(5.0, 0.0, 1.0);
    const Bspline msg = toMsg(t, "world", 7);
    fuzz::FuzzOutput o;
    o.byte(0);
    o.choice(0);
    o.integer<uint64_t>(msg.planner_session);
    o.integer<int64_t>(msg.trajectory_id);
    o.integer<uint32_t>(msg.start_time.sec);
    o.integer<uint32_t>(msg.start_time.nsec);
    o.integer<int32_t>(msg.order);
    o.number(msg.knot_span_s);
    o.flag(msg.has_heading_target);
    o.number(msg.heading_target.x);
    o.number(msg.heading_target.y);
    o.number(msg.heading_target.z);
    o.flag(msg.reanchor);
    o.integer<uint16_t>(uint16_t(msg.control_points.size()));
    for (const auto& p : msg.control_points) o.number(p.x), o.number(p.y), o.number(p.z);
    writeFile(corpus / "trajectory_msgs" / "bspline", o.bytes());
  }
  writeFile(corpus / "trajectory_msgs" / "goal", {1, 0});
  writeFile(corpus / "trajectory_msgs" / "path", {2, 0});

  // Default configs of the four kinds, and one map of 0.1 m voxels.
  writeFile(corpus / "params" / "mapping_defaults", {0});
  writeFile(corpus / "params" / "planner_defaults", {1});
  writeFile(corpus / "params" / "setpoints_defaults", {2});
  writeFile(corpus / "params" / "planner_node_defaults", {3});
  {
    fuzz::FuzzOutput o;
    o.byte(0);
    o.number(0.1);
    writeFile(corpus / "params" / "mapping_0.1m", o.bytes());
  }

  // Tasks: the first rows of forest_gen's file when given, and rows the bench would skip.
  std::ostringstream tasks;
  if (argc > 3) {
    std::ifstream in(argv[3]);
    std::string line;
    for (int i = 0; i < 6 && std::getline(in, line); ++i) tasks << line << "\n";
  } else {
    tasks << "#trial,map_id,start_x,start_y,start_z,end_x,end_y,end_z\n0,0,-1.7,-4.1,1.0,3.2,0.27,1.0\n";
  }
  const std::string t = tasks.str();
  writeFile(corpus / "tasks_csv" / "forest_gen_rows", std::vector<uint8_t>(t.begin(), t.end()));
  const std::string bad = "#trial,map_id\n1,0,nan,0,1,2,2,1\n2,0,1,2\n\n3,1,0,0,1,1e308,0,1\r\n";
  writeFile(corpus / "tasks_csv" / "bad_rows", std::vector<uint8_t>(bad.begin(), bad.end()));

  fs::remove_all(tmp);
  std::printf("fuzz_make_seeds: corpora written to %s\n", corpus.c_str());
  return 0;
}
