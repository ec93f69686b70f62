#include "topo_planner/plan_env/map_io.h"

#include <octomap/OcTree.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <fstream>
#include <memory>

namespace topo_planner {

namespace {

bool fileReadable(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return f.good();
}

std::string extensionOf(const std::string& path) {
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos) return "";
  std::string ext = path.substr(dot + 1);
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

void computeBounds(MapFile* f) {
  if (f->cells.empty()) {
    f->min = f->max = Eigen::Vector3d::Zero();
    return;
  }
  f->min = Eigen::Vector3d::Constant(INFINITY);
  f->max = Eigen::Vector3d::Constant(-INFINITY);
  for (const MapCell& c : f->cells) {
    const Eigen::Vector3d h = Eigen::Vector3d::Constant(0.5 * c.size_m);
    f->min = f->min.cwiseMin(c.center - h);
    f->max = f->max.cwiseMax(c.center + h);
  }
}

MapStatus fail(MapStatus s, const std::string& msg, std::string* error) {
  if (error) *error = msg;
  return s;
}

}  // namespace

size_t MapFile::numOccupied() const {
  size_t n = 0;
  for (const MapCell& c : cells) n += c.occupied;
  return n;
}

MapStatus readMapFile(const std::string& path, MapFile* out, std::string* error) {
  const std::string ext = extensionOf(path);
  if (ext == "bt" || ext == "ot") return readOctomapFile(path, out, error);
  if (ext == "pcd") return readPcdFile(path, out, error);
  if (!fileReadable(path)) return fail(MapStatus::kFileNotFound, "cannot open '" + path + "'", error);
  return fail(MapStatus::kParseError, "unknown map file type '" + path + "' (expected .bt, .ot or .pcd)", error);
}

MapStatus readOctomapFile(const std::string& path, MapFile* out, std::string* error) {
  if (!fileReadable(path)) return fail(MapStatus::kFileNotFound, "cannot open '" + path + "'", error);
  std::unique_ptr<octomap::OcTree> tree;
  try {
    if (extensionOf(path) == "ot") {
      std::unique_ptr<octomap::AbstractOcTree> abstract(octomap::AbstractOcTree::read(path));
      auto* t = dynamic_cast<octomap::OcTree*>(abstract.get());
      if (t) {
        abstract.release();
        tree.reset(t);
      }
    } else {
      tree = std::make_unique<octomap::OcTree>(0.1);
      std::ifstream in(path, std::ios::binary);
      if (!tree->readBinary(in) || in.bad()) tree.reset();
    }
  } catch (const std::exception& e) {
    return fail(MapStatus::kParseError, "OctoMap could not read '" + path + "': " + e.what(), error);
  }
  if (!tree) return fail(MapStatus::kParseError, "'" + path + "' is not a readable OctoMap OcTree", error);

  MapFile file;
  file.resolution_m = tree->getResolution();
  if (!(std::isfinite(file.resolution_m) && file.resolution_m > 0.0))
    return fail(MapStatus::kParseError, "'" + path + "' has an invalid resolution", error);
  for (auto it = tree->begin_leafs(), end = tree->end_leafs(); it != end; ++it) {
    const octomap::point3d c = it.getCoordinate();
    MapCell cell;
    cell.center = Eigen::Vector3d(c.x(), c.y(), c.z());
    cell.size_m = it.getSize();
    cell.occupied = tree->isNodeOccupied(*it);
    if (!cell.center.allFinite()) return fail(MapStatus::kParseError, "'" + path + "' holds non-finite leaves", error);
    file.cells.push_back(cell);
  }
  computeBounds(&file);
  *out = std::move(file);
  return MapStatus::kSuccess;
}

MapStatus readPcdFile(const std::string& path, MapFile* out, std::string* error) {
  if (!fileReadable(path)) return fail(MapStatus::kFileNotFound, "cannot open '" + path + "'", error);
  pcl::PointCloud<pcl::PointXYZ> cloud;
  try {
    // PCL 1.13 reads past the end on files without a valid header (it crashes on garbage), so
    // the header is checked first: it must declare x, y and z fields.
    pcl::PCDReader reader;
    pcl::PCLPointCloud2 header;
    Eigen::Vector4f origin;
    Eigen::Quaternionf orientation;
    int version = 0, data_type = 0;
    unsigned int data_index = 0;
    if (reader.readHeader(path, header, origin, orientation, version, data_type, data_index) < 0)
      return fail(MapStatus::kParseError, "'" + path + "' has no readable PCD header", error);
    int xyz = 0;
    for (const auto& field : header.fields) xyz += field.name == "x" || field.name == "y" || field.name == "z";
    if (xyz != 3) return fail(MapStatus::kParseError, "'" + path + "' has no x, y, z fields", error);
    if (size_t(header.width) * header.height > 0 && reader.read(path, cloud) < 0)
      return fail(MapStatus::kParseError, "'" + path + "' is not a readable PCD file", error);
  } catch (const std::exception& e) {
    return fail(MapStatus::kParseError, "PCL could not read '" + path + "': " + e.what(), error);
  }
  MapFile file;
  file.cells.reserve(cloud.size());
  for (const pcl::PointXYZ& p : cloud) {
    const Eigen::Vector3d c(p.x, p.y, p.z);
    if (c.allFinite()) file.cells.push_back({c, 0.0, true});
  }
  computeBounds(&file);
  *out = std::move(file);
  return MapStatus::kSuccess;
}

MapInsertStats insertMapFile(const MapFile& file, OccupancyMap* map) {
  MapInsertStats stats;
  const GridGeometry& g = map->geometry();
  const VoxelBox window = g.windowBox();
  for (int pass = 0; pass < 2; ++pass) {
    const bool occupied_pass = pass == 1;
    for (const MapCell& cell : file.cells) {
      if (cell.occupied != occupied_pass) continue;
      // Voxels whose centre lies in [center - size/2, center + size/2).
      // The index range in doubles first: a file's coordinates may lie far beyond the int range of
      // voxel indices (casting those is undefined), so the range is clipped to the window before.
      const Eigen::Vector3d h = Eigen::Vector3d::Constant(0.5 * cell.size_m);
      Eigen::Array3d lo = (((cell.center - h) * g.inverseResolution()).array() - 0.5).ceil();
      Eigen::Array3d hi = (((cell.center + h) * g.inverseResolution()).array() - (0.5 + 1e-9)).floor();
      const Eigen::Array3d own = (cell.center * g.inverseResolution()).array().floor();
      for (int a = 0; a < 3; ++a)
        if (lo[a] > hi[a]) lo[a] = hi[a] = own[a];
      const Eigen::Array3d wmin = window.min.cast<double>().array(), wmax = window.max.cast<double>().array();
      const bool clipped = (lo < wmin).any() || (hi > wmax).any();
      if (clipped) ++stats.clipped_cells;
      if ((hi < wmin).any() || (lo > wmax).any() || !(lo.allFinite() && hi.allFinite())) continue;
      const VoxelBox inside = VoxelBox::fromCorners(lo.max(wmin).cast<int>().matrix(), hi.min(wmax).cast<int>().matrix());
      if (inside.empty()) continue;
      Eigen::Vector3i i;
      for (i.z() = inside.min.z(); i.z() <= inside.max.z(); ++i.z())
        for (i.y() = inside.min.y(); i.y() <= inside.max.y(); ++i.y())
          for (i.x() = inside.min.x(); i.x() <= inside.max.x(); ++i.x())
            map->setState(i, occupied_pass ? VoxelState::kOccupied : VoxelState::kFree);
      const size_t n = size_t(inside.volume());
      (occupied_pass ? stats.occupied_voxels : stats.free_voxels) += n;
      stats.changed_box.merge(inside);
    }
  }
  return stats;
}

OccupancyMap::Config configFittingMapFile(const MapFile& file, const OccupancyMap::Config& base, double margin_m) {
  OccupancyMap::Config c = base;
  c.origin_m = file.min.array() - margin_m;
  c.size_m = (file.max - file.min).array() + 2.0 * margin_m;
  c.size_m = c.size_m.cwiseMax(Eigen::Vector3d::Constant(base.resolution_m));
  return c;
}

MapStatus saveOctomapFile(const OccupancyMap& map, const std::string& path, std::string* error) {
  const GridGeometry& g = map.geometry();
  try {
    octomap::OcTree tree(g.resolution());
    const VoxelBox w = g.windowBox();
    Eigen::Vector3i i;
    for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
      for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
        for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
          const VoxelState s = map.state(i);
          if (s != VoxelState::kOccupied && s != VoxelState::kFree) continue;
          const Eigen::Vector3d c = g.centerOf(i);
          octomap::OcTreeNode* node = tree.updateNode(octomap::point3d(float(c.x()), float(c.y()), float(c.z())),
                                                      s == VoxelState::kOccupied, true);
          if (node) node->setLogOdds(s == VoxelState::kOccupied ? tree.getClampingThresMaxLog()
                                                                 : tree.getClampingThresMinLog());
        }
    tree.updateInnerOccupancy();
    tree.prune();
    if (!tree.writeBinary(path)) return fail(MapStatus::kWriteError, "cannot write '" + path + "'", error);
  } catch (const std::exception& e) {
    return fail(MapStatus::kWriteError, "OctoMap could not write '" + path + "': " + e.what(), error);
  }
  return MapStatus::kSuccess;
}

MapStatus savePcdFile(const OccupancyMap& map, const std::string& path, std::string* error) {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  map.forEachOccupied([&](const Eigen::Vector3i& i) {
    const Eigen::Vector3d c = map.geometry().centerOf(i);
    cloud.push_back(pcl::PointXYZ(float(c.x()), float(c.y()), float(c.z())));
  });
  try {
    if (cloud.empty()) {
      // PCL refuses to write an empty binary cloud; an ASCII file with zero points is valid PCD.
      if (pcl::io::savePCDFileASCII(path, cloud) < 0) return fail(MapStatus::kWriteError, "cannot write '" + path + "'", error);
    } else if (pcl::io::savePCDFileBinary(path, cloud) < 0) {
      return fail(MapStatus::kWriteError, "cannot write '" + path + "'", error);
    }
  } catch (const std::exception& e) {
    return fail(MapStatus::kWriteError, "PCL could not write '" + path + "': " + e.what(), error);
  }
  return MapStatus::kSuccess;
}

}  // namespace topo_planner
