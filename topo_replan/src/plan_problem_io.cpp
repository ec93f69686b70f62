#include "topo_planner/topo_replan/plan_problem_io.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <vector>

#include "topo_planner/plan_env/map_io.h"

namespace topo_planner {

namespace {

constexpr const char* kMagic = "topo_planner_plan_problem";
constexpr int kVersion = 1;

bool fail(const std::string& why, std::string* error) {
  if (error) *error = why;
  return false;
}

std::string baseOf(const std::string& path) {
  const std::string ext = ".problem";
  if (path.size() > ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0)
    return path.substr(0, path.size() - ext.size());
  return path;
}

void putVector(std::ostream& os, const Eigen::Vector3d& v) { os << ' ' << v.x() << ' ' << v.y() << ' ' << v.z(); }

// Reads n finite numbers from the rest of a line.
bool readNumbers(std::istringstream& is, int n, std::vector<double>* out) {
  out->clear();
  double x = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!(is >> x) || !std::isfinite(x)) return false;
    out->push_back(x);
  }
  std::string extra;
  return !(is >> extra);
}

}  // namespace

bool savePlanProblem(const std::string& base, const EsdfMap& map, const ReplanRequest& request,
                     const std::string& note, std::string* error) {
  if (!request.reference) return fail("the request has no reference", error);
  const GridGeometry& g = map.geometry();
  std::ofstream os(base + ".problem");
  if (!os) return fail("cannot write '" + base + ".problem'", error);
  os.precision(17);
  os << kMagic << ' ' << kVersion << '\n';
  os << "resolution_m " << g.resolution() << '\n';
  os << "window_origin_index " << g.originIndex().x() << ' ' << g.originIndex().y() << ' ' << g.originIndex().z() << '\n';
  os << "window_size_voxels " << g.size().x() << ' ' << g.size().y() << ' ' << g.size().z() << '\n';
  const EsdfMap::Config& e = map.config();
  os << "esdf " << e.max_distance_m << ' ' << e.inflate_radius_m << ' ' << (e.unknown_as_occupied ? 1 : 0) << '\n';
  const FlatState& s = request.start;
  os << "start";
  putVector(os, s.position);
  putVector(os, s.velocity);
  putVector(os, s.acceleration);
  putVector(os, s.jerk);
  os << '\n';
  os << "reference_time_s " << request.reference_time_s << '\n';
  os << "attempt " << request.attempt << '\n';
  const auto& segments = request.reference->segments();
  os << "segments " << segments.size() << '\n';
  for (const PolynomialTrajectory::Segment& seg : segments) {
    os << "segment " << seg.duration;
    for (int k = 0; k < PolynomialTrajectory::kCoefficients; ++k)
      for (int c = 0; c < 3; ++c) os << ' ' << seg.coefficients(k, c);
    os << '\n';
  }
  std::string flat = note;
  for (char& ch : flat)
    if (ch == '\n' || ch == '\r') ch = ' ';
  os << "note " << flat << '\n';
  os.flush();
  if (!os) return fail("cannot write '" + base + ".problem'", error);
  std::string why;
  if (saveOctomapFile(map.occupancy(), base + ".bt", &why) != MapStatus::kSuccess) return fail(why, error);
  return true;
}

bool loadPlanProblem(const std::string& path, PlanProblem* out, std::string* error, double max_memory_mb) {
  const std::string base = baseOf(path);
  std::ifstream is(base + ".problem");
  if (!is) return fail("cannot open '" + base + ".problem'", error);
  std::string line;
  if (!std::getline(is, line)) return fail("empty problem file", error);
  {
    std::istringstream head(line);
    std::string magic;
    int version = 0;
    if (!(head >> magic >> version) || magic != kMagic || version != kVersion)
      return fail(std::string("not a ") + kMagic + " " + std::to_string(kVersion) + " file", error);
  }
  double resolution = 0.0;
  Eigen::Vector3i origin = Eigen::Vector3i::Zero(), size = Eigen::Vector3i::Zero();
  EsdfMap::Config esdf_config;
  bool have_resolution = false, have_window = false, have_size = false, have_start = false;
  long declared_segments = -1;
  std::vector<PolynomialTrajectory::Segment> segments;
  PlanProblem p;
  std::vector<double> v;
  int line_number = 1;
  while (std::getline(is, line)) {
    ++line_number;
    std::istringstream ls(line);
    std::string key;
    if (!(ls >> key)) continue;
    const std::string where = "line " + std::to_string(line_number) + " (" + key + "): ";
    if (key == "note") {
      std::getline(ls, p.note);
      if (!p.note.empty() && p.note.front() == ' ') p.note.erase(0, 1);
    } else if (key == "resolution_m") {
      if (!readNumbers(ls, 1, &v) || !(v[0] >= 0.01 && v[0] <= 10.0)) return fail(where + "expected 0.01..10", error);
      resolution = v[0];
      have_resolution = true;
    } else if (key == "window_origin_index" || key == "window_size_voxels") {
      if (!readNumbers(ls, 3, &v)) return fail(where + "expected 3 numbers", error);
      const bool is_size = key == "window_size_voxels";
      for (int a = 0; a < 3; ++a) {
        const double lo = is_size ? 1.0 : -1e6, hi = 1e6;
        if (!(v[size_t(a)] >= lo && v[size_t(a)] <= hi && v[size_t(a)] == std::floor(v[size_t(a)])))
          return fail(where + "expected integers in range", error);
        (is_size ? size : origin)(a) = int(v[size_t(a)]);
      }
      (is_size ? have_size : have_window) = true;
    } else if (key == "esdf") {
      if (!readNumbers(ls, 3, &v)) return fail(where + "expected 3 numbers", error);
      esdf_config.max_distance_m = v[0];
      esdf_config.inflate_radius_m = v[1];
      esdf_config.unknown_as_occupied = v[2] != 0.0;
    } else if (key == "start") {
      if (!readNumbers(ls, 12, &v)) return fail(where + "expected 12 finite numbers", error);
      FlatState& s = p.request.start;
      s.position = Eigen::Vector3d(v[0], v[1], v[2]);
      s.velocity = Eigen::Vector3d(v[3], v[4], v[5]);
      s.acceleration = Eigen::Vector3d(v[6], v[7], v[8]);
      s.jerk = Eigen::Vector3d(v[9], v[10], v[11]);
      have_start = true;
    } else if (key == "reference_time_s") {
      if (!readNumbers(ls, 1, &v)) return fail(where + "expected a finite number", error);
      p.request.reference_time_s = v[0];
    } else if (key == "attempt") {
      if (!readNumbers(ls, 1, &v) || !(v[0] >= 0.0 && v[0] <= 4294967295.0))
        return fail(where + "expected an unsigned 32-bit count", error);
      p.request.attempt = uint32_t(v[0]);
    } else if (key == "segments") {
      if (!readNumbers(ls, 1, &v) || !(v[0] >= 1.0 && v[0] <= kMaxPlanProblemSegments))
        return fail(where + "expected 1.." + std::to_string(kMaxPlanProblemSegments), error);
      declared_segments = long(v[0]);
    } else if (key == "segment") {
      if (declared_segments < 0 || long(segments.size()) >= declared_segments)
        return fail(where + "more segments than declared", error);
      if (!readNumbers(ls, 1 + 3 * PolynomialTrajectory::kCoefficients, &v) || !(v[0] > 1e-6 && v[0] <= kMaxPlanProblemDurationS))
        return fail(where + "expected a positive duration and 24 finite coefficients", error);
      PolynomialTrajectory::Segment seg;
      seg.duration = v[0];
      for (int k = 0; k < PolynomialTrajectory::kCoefficients; ++k)
        for (int c = 0; c < 3; ++c) seg.coefficients(k, c) = v[size_t(1 + 3 * k + c)];
      segments.push_back(seg);
    } else {
      return fail(where + "unknown key", error);
    }
  }
  if (!have_resolution || !have_window || !have_size || !have_start || declared_segments < 0)
    return fail("incomplete problem file (resolution_m, window_origin_index, window_size_voxels, start, segments)", error);
  if (long(segments.size()) != declared_segments) return fail("fewer segments than declared", error);
  double duration = 0.0;
  for (const PolynomialTrajectory::Segment& seg : segments) duration += seg.duration;
  if (!(duration <= kMaxPlanProblemDurationS))
    return fail("the reference is longer than " + std::to_string(int(kMaxPlanProblemDurationS)) + " s", error);
  p.reference = PolynomialTrajectory(std::move(segments));

  OccupancyMap::Config config;
  config.resolution_m = resolution;
  config.origin_m = origin.cast<double>() * resolution;
  config.size_m = (size.cast<double>().array() - 0.5).matrix() * resolution;
  config.max_memory_mb = max_memory_mb;
  std::string why;
  p.occupancy = OccupancyMap::create(config, &why);
  if (!p.occupancy) return fail("map window: " + why, error);
  MapFile file;
  if (readOctomapFile(base + ".bt", &file, &why) != MapStatus::kSuccess) return fail(why, error);
  insertMapFile(file, p.occupancy.get());
  p.esdf = EsdfMap::create(esdf_config, p.occupancy, &why);
  if (!p.esdf) return fail("ESDF: " + why, error);
  p.esdf->updateAll();
  *out = std::move(p);
  out->request.reference = &out->reference;
  return true;
}

}  // namespace topo_planner
