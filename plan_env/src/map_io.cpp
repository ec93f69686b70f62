#include "topo_planner/plan_env/map_io.h"

#include <octomap/OcTree.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <bitset>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

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

// OctoMap's node readers (OcTreeBaseImpl::readNodesRecurs for .ot, OccupancyOcTreeBase::
// readBinaryNode for .bt) recurse once per inner node and never check the stream: child flags that
// claim inner nodes below the tree depth, or a file that ends inside the node stream (the reader
// then decodes bytes it never read), recurse until the stack overflows. So the file is parsed here
// first, without recursion: the header as octomap reads it, then the node stream walked with an
// explicit stack, bounded by the tree depth and by the bytes present. Only a stream that passes is
// handed to octomap, and only those bytes.
struct OctomapHeader {
  std::string id;
  unsigned size = 0;        ///< nodes in the stream (0: no stream)
  double resolution = 0.0;  ///< [m]
  size_t data_begin = 0;    ///< offset of the node stream in the file
};

const char kBinaryFirstLine[] = "# Octomap OcTree binary file";  // .bt (AbstractOccupancyOcTree)
const char kFullFirstLine[] = "# Octomap OcTree file";           // .ot (AbstractOcTree)

// The header of .bt/.ot files: a first line, then keyword lines ("id", "size", "res", "#" comments,
// unknown keywords skipped to the end of the line) up to "data" and the end of its line. A .bt
// file may instead start with the legacy binary header (int32 3, double resolution, uint32 size).
bool parseOctomapHeader(const std::string& bytes, bool binary, OctomapHeader* h, std::string* why) {
  std::istringstream s(bytes);
  std::string line;
  std::getline(s, line);
  const std::string first = binary ? kBinaryFirstLine : kFullFirstLine;
  if (line.compare(0, first.size(), first) != 0) {
    int32_t type = 0;
    if (!binary || bytes.size() < sizeof(type) + sizeof(h->resolution) + sizeof(h->size)) {
      *why = "does not start with '" + first + "'";
      return false;
    }
    std::memcpy(&type, bytes.data(), sizeof(type));
    std::memcpy(&h->resolution, bytes.data() + sizeof(type), sizeof(h->resolution));
    std::memcpy(&h->size, bytes.data() + sizeof(type) + sizeof(h->resolution), sizeof(h->size));
    if (type != 3) {
      *why = "has neither an OctoMap header nor the legacy binary one";
      return false;
    }
    h->id = "OcTree";
    h->data_begin = sizeof(type) + sizeof(h->resolution) + sizeof(h->size);
  } else {
    bool data = false;
    std::string token;
    while (!data && s >> token) {
      if (token == "id") {
        s >> h->id;
      } else if (token == "size") {
        s >> h->size;
      } else if (token == "res") {
        s >> h->resolution;
      } else {
        data = token == "data";  // "data", comments and unknown keywords end with their line
        s.ignore(std::numeric_limits<std::streamsize>::max(), '\n');
      }
    }
    if (!data) {
      *why = "has no complete header (id, size, res, data)";
      return false;
    }
    h->data_begin = s.eof() ? bytes.size() : size_t(s.tellg());
  }
  if (h->id == "1") h->id = "OcTree";  // the deprecated id octomap still accepts
  if (h->id.empty()) {
    *why = "has no tree id in its header";
    return false;
  }
  if (!binary && h->id != "OcTree") {
    *why = "holds a '" + h->id + "', not an OcTree";
    return false;
  }
  if (!(std::isfinite(h->resolution) && h->resolution > 0.0)) {
    *why = "has an invalid resolution";
    return false;
  }
  return true;
}

// Walks the node stream from `begin` in octomap's order (depth first, children 0..7) and returns
// the number of nodes it creates and the end of the stream. Each node record is, in .bt, 2 bytes of
// child flags, 2 bits per child (00 unknown, 01 free leaf, 10 occupied leaf, 11 inner: its record
// follows); in .ot, the node's float log-odds then 1 byte with a bit per existing child, whose
// records follow. A record at depth `max_depth` (the leaves' depth) must have no children.
bool walkOctomapNodes(const std::string& bytes, size_t begin, bool binary, unsigned max_depth, size_t* nodes,
                      size_t* end, std::string* why) {
  const size_t record = binary ? 2 : sizeof(float) + 1;
  std::vector<unsigned> pending{0};  // depths of the records still to read, next one at the back
  size_t pos = begin;
  size_t n = 1;
  while (!pending.empty()) {
    const unsigned depth = pending.back();
    pending.pop_back();
    if (bytes.size() - pos < record) {
      *why = "ends inside its node stream (after " + std::to_string(n) + " nodes)";
      return false;
    }
    unsigned children = 0, inner = 0;
    if (binary) {
      const unsigned flags = unsigned(uint8_t(bytes[pos])) | unsigned(uint8_t(bytes[pos + 1])) << 8;
      for (int i = 0; i < 8; ++i) {
        const unsigned two = (flags >> (2 * i)) & 3u;
        children += two != 0;
        inner += two == 3;
      }
    } else {
      float log_odds;
      std::memcpy(&log_odds, bytes.data() + pos, sizeof(log_odds));
      if (!std::isfinite(log_odds)) {
        *why = "holds a non-finite log-odds value";
        return false;
      }
      children = inner = unsigned(std::bitset<8>(uint8_t(bytes[pos + sizeof(float)])).count());
    }
    pos += record;
    if (children > 0 && depth >= max_depth) {
      *why = "has nodes below the tree depth of " + std::to_string(max_depth);
      return false;
    }
    n += children;
    pending.insert(pending.end(), inner, depth + 1);  // equal depths: the order among them is immaterial
  }
  *nodes = n;
  *end = pos;
  return true;
}

// Bytes of point data a PCD header declares (points x point step), read from its lines as PCL
// reads them (WIDTH, HEIGHT, POINTS, SIZE, COUNT up to DATA; the largest value where a keyword
// repeats, so that this bounds what PCL allocates). PCL's readHeader allocates that much before it
// reads a single point: a header of a billion points allocated gigabytes (pcd fuzz harness).
double pcdDeclaredBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  double width = 0.0, height = 0.0, points = 0.0;
  std::vector<double> sizes, counts;
  auto values = [](std::istringstream& row) {
    std::vector<double> v;
    std::string token;
    while (row >> token) {
      char* end = nullptr;
      const double x = std::strtod(token.c_str(), &end);
      v.push_back(end != token.c_str() && std::isfinite(x) ? std::abs(x) : 0.0);
    }
    return v;
  };
  auto keepLargest = [](std::vector<double>* into, const std::vector<double>& v) {
    if (into->size() < v.size()) into->resize(v.size(), 0.0);
    for (size_t i = 0; i < v.size(); ++i) (*into)[i] = std::max((*into)[i], v[i]);
  };
  while (std::getline(in, line)) {
    std::istringstream row(line);
    std::string key;
    if (!(row >> key)) continue;
    if (key == "DATA") break;
    const std::vector<double> v = values(row);
    const double first = v.empty() ? 0.0 : v[0];
    if (key == "WIDTH") width = std::max(width, first);
    if (key == "HEIGHT") height = std::max(height, first);
    if (key == "POINTS") points = std::max(points, first);
    if (key == "SIZE") keepLargest(&sizes, v);
    if (key == "COUNT") keepLargest(&counts, v);
  }
  double step = 0.0;
  for (size_t i = 0; i < sizes.size(); ++i) step += sizes[i] * std::max(1.0, i < counts.size() ? counts[i] : 1.0);
  return std::max(points, width * height) * std::max(step, 1.0);
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
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    if (!in.good()) return fail(MapStatus::kFileNotFound, "cannot open '" + path + "'", error);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (in.bad()) return fail(MapStatus::kParseError, "cannot read '" + path + "'", error);
  }
  const bool binary = extensionOf(path) != "ot";
  OctomapHeader header;
  std::string why;
  if (!parseOctomapHeader(bytes, binary, &header, &why))
    return fail(MapStatus::kParseError, "'" + path + "' " + why, error);
  std::unique_ptr<octomap::OcTree> tree;
  try {
    tree = std::make_unique<octomap::OcTree>(header.resolution);
    if (header.size > 0) {
      size_t nodes = 0, end = 0;
      if (!walkOctomapNodes(bytes, header.data_begin, binary, tree->getTreeDepth(), &nodes, &end, &why))
        return fail(MapStatus::kParseError, "'" + path + "' " + why, error);
      if (nodes != header.size)
        return fail(MapStatus::kParseError, "'" + path + "' declares " + std::to_string(header.size) +
                                                " nodes, its node stream holds " + std::to_string(nodes), error);
      std::istringstream stream(bytes.substr(header.data_begin, end - header.data_begin));
      if (binary)
        tree->readBinaryData(stream);
      else
        tree->readData(stream);
      if (tree->size() != nodes)
        return fail(MapStatus::kParseError, "OctoMap read " + std::to_string(tree->size()) + " nodes of '" + path +
                                                "', expected " + std::to_string(nodes), error);
    }
  } catch (const std::exception& e) {
    return fail(MapStatus::kParseError, "OctoMap could not read '" + path + "': " + e.what(), error);
  }

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
  pcl::PCLPointCloud2 blob;
  try {
    // PCL 1.13 reads past the end on files without a valid header (it crashes on garbage), so
    // the header is checked first: it must declare x, y and z fields.
    std::ifstream size_probe(path, std::ios::binary | std::ios::ate);
    const uint64_t file_bytes = uint64_t(std::max<std::streamoff>(0, size_probe.tellg()));
    if (pcdDeclaredBytes(path) > 100.0 * double(file_bytes) + 1e6)
      return fail(MapStatus::kParseError, "'" + path + "' declares more points than its bytes of data hold", error);
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
    // The exact bound once PCL has parsed the header (the one above allows for compression and
    // small files; PCL's body readers allocate the points again). The data must fit the file: binary points
    // take point_step bytes, ASCII ones at least a digit and a line end, compressed ones at least
    // 1/100 of their size (LZF expands a 3-byte back reference to at most 264 bytes).
    const uint64_t points = uint64_t(header.width) * header.height, point_bytes = points * header.point_step;
    const uint64_t data_bytes = file_bytes - std::min<uint64_t>(file_bytes, data_index);
    const bool fits = data_type == 0 ? 2 * points <= data_bytes
                                     : data_type == 1 ? point_bytes <= data_bytes : point_bytes <= 100 * data_bytes;
    if (!fits)
      return fail(MapStatus::kParseError, "'" + path + "' declares " + std::to_string(points) +
                                              " points, more than its " + std::to_string(data_bytes) + " bytes of data hold",
                  error);
    if (data_type == 2 && points > 0) {
      // binary_compressed: two uint32 (compressed, uncompressed size) lead the data, and PCL
      // allocates the uncompressed size as written (4 GB in the pcd fuzz harness).
      uint32_t sizes[2] = {0, 0};
      std::ifstream in(path, std::ios::binary);
      in.seekg(std::streamoff(data_index));
      if (!in.read(reinterpret_cast<char*>(sizes), sizeof(sizes)) || sizes[1] != point_bytes ||
          uint64_t(sizes[0]) + sizeof(sizes) > data_bytes)
        return fail(MapStatus::kParseError, "'" + path + "' has compressed data of the wrong size", error);
    }
    if (points > 0 && reader.read(path, blob) < 0)
      return fail(MapStatus::kParseError, "'" + path + "' is not a readable PCD file", error);
  } catch (const std::exception& e) {
    return fail(MapStatus::kParseError, "PCL could not read '" + path + "': " + e.what(), error);
  }
  // The points are taken from PCL's blob here rather than by pcl::fromPCLPointCloud2, which trusts
  // the header: a file whose fields lie outside a point, or whose data holds fewer bytes than its
  // WIDTH x HEIGHT points, made it read past the buffer (pcd fuzz harness, ASan). So every x, y, z
  // must be a float inside a point and every point inside the data. Sizes are 32-bit in PCL:
  // their products fit in 64 bits.
  const uint64_t width = blob.width, height = blob.height, point_step = blob.point_step, row_step = blob.row_step;
  MapFile file;
  if (width * height > 0) {
    uint64_t offset[3];
    bool found[3] = {false, false, false};
    for (const pcl::PCLPointField& f : blob.fields) {
      const int axis = f.name == "x" ? 0 : f.name == "y" ? 1 : f.name == "z" ? 2 : -1;
      if (axis < 0) continue;
      if (f.datatype != pcl::PCLPointField::FLOAT32 || f.count < 1 || uint64_t(f.offset) + sizeof(float) > point_step)
        return fail(MapStatus::kParseError, "'" + path + "': field " + f.name + " is not a float inside a point", error);
      offset[axis] = f.offset;
      found[axis] = true;
    }
    if (!(found[0] && found[1] && found[2]))
      return fail(MapStatus::kParseError, "'" + path + "' has no x, y, z fields", error);
    if (width * point_step > row_step || height * row_step > blob.data.size())
      return fail(MapStatus::kParseError, "'" + path + "' holds fewer bytes than its " + std::to_string(width) + " x " +
                                              std::to_string(height) + " points", error);
    file.cells.reserve(size_t(width * height));
    for (uint64_t r = 0; r < height; ++r)
      for (uint64_t i = 0; i < width; ++i) {
        const uint8_t* point = blob.data.data() + r * row_step + i * point_step;
        float xyz[3];
        for (int a = 0; a < 3; ++a) std::memcpy(&xyz[a], point + offset[a], sizeof(float));
        const Eigen::Vector3d c(xyz[0], xyz[1], xyz[2]);
        if (c.allFinite()) file.cells.push_back({c, 0.0, true});
      }
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
