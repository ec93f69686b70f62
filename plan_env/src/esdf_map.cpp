#include "topo_planner/plan_env/esdf_map.h"

#include <algorithm>
#include <cassert>
#include <functional>
#include <cmath>
#include <sstream>

#include "topo_planner/plan_env/distance_transform.h"

namespace topo_planner {

namespace {
// Lines per pool task: enough to amortise the scheduling, small enough to balance two workers.
constexpr int kLinesPerTask = 4;
}  // namespace

bool EsdfMap::Config::validate(std::string* why) const {
  std::ostringstream err;
  if (!(std::isfinite(max_distance_m) && max_distance_m > 0.0)) err << "max_distance_m must be positive; ";
  if (!(std::isfinite(inflate_radius_m) && inflate_radius_m >= 0.0)) err << "inflate_radius_m must be >= 0; ";
  if (inflate_radius_m >= max_distance_m) err << "inflate_radius_m must be below max_distance_m; ";
  if (num_threads < 1 || num_threads > 64) err << "num_threads must be in [1, 64]; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

std::unique_ptr<EsdfMap> EsdfMap::create(const Config& config, std::shared_ptr<const OccupancyMap> occupancy,
                                         std::string* error) {
  std::string why;
  if (!occupancy) why = "no occupancy map";
  if (why.empty() && !config.validate(&why)) why = "invalid ESDF config: " + why;
  if (why.empty() && config.max_distance_m / occupancy->geometry().resolution() > 16384.0)
    why = "invalid ESDF config: max_distance_m is more than 16384 voxels";
  if (!why.empty()) {
    if (error) *error = why;
    return nullptr;
  }
  try {
    return std::unique_ptr<EsdfMap>(new EsdfMap(config, std::move(occupancy)));
  } catch (const std::bad_alloc&) {
    if (error) *error = "out of memory allocating the ESDF";
    return nullptr;
  }
}

EsdfMap::EsdfMap(const Config& config, std::shared_ptr<const OccupancyMap> occupancy)
    : config_(config), occupancy_(std::move(occupancy)), pool_(config.num_threads) {
  const double res = geometry().resolution();
  margin_voxels_ = int(std::ceil(config_.max_distance_m / res));
  const double cap_voxels = config_.max_distance_m / res;
  cap_sq_voxels_ = int32_t(std::ceil(cap_voxels * cap_voxels - 1e-9));
  // Before the first update nothing is known to be near an obstacle.
  distance_.assign(geometry().numVoxels(), float(config_.max_distance_m));
  computed_origin_ = geometry().originIndex();
  scratch_.resize(size_t(pool_.size()));
}

EsdfUpdateStats EsdfMap::updateAll() {
  const VoxelBox window = geometry().windowBox();
  compute(window, window);
  computed_origin_ = geometry().originIndex();
  EsdfUpdateStats stats;
  stats.written_box = stats.input_box = window;
  stats.full = true;
  return stats;
}

EsdfUpdateStats EsdfMap::update(const VoxelBox& changed) {
  if (geometry().originIndex() != computed_origin_) return updateAll();
  const VoxelBox window = geometry().windowBox();
  const VoxelBox c = changed.intersection(window);
  EsdfUpdateStats stats;
  if (c.empty()) return stats;
  stats.written_box = c.inflated(margin_voxels_).intersection(window);
  stats.input_box = stats.written_box.inflated(margin_voxels_).intersection(window);
  stats.full = stats.written_box == window;
  compute(stats.input_box, stats.written_box);
  return stats;
}

void EsdfMap::compute(const VoxelBox& in, const VoxelBox& out) {
  const size_t volume = size_t(in.volume());
  if (pos_sq_.size() < volume) {
    pos_sq_.resize(volume);
    neg_sq_.resize(volume);
  }
  const Eigen::Vector3i n = in.size();
  const size_t longest = size_t(n.maxCoeff());
  for (LineScratch& s : scratch_) {
    if (s.f.size() < longest) {
      s.f.resize(longest);
      s.d.resize(longest);
      s.v.resize(longest);
      s.zn.resize(longest + 1);
      s.zd.resize(longest + 1);
      s.site.resize(longest);
      s.row_a.resize(longest);
      s.row_b.resize(longest);
      s.row_c.resize(longest);
    }
    if (s.plane.size() < size_t(n.x()) * size_t(n.y())) s.plane.resize(size_t(n.x()) * size_t(n.y()));
  }
  firstPassAlongX(in);
  if (std::sqrt(double(cap_sq_voxels_)) <= kMaxWindowVoxels) {
    computeWindowed(in, out);
  } else {
    computeEnvelope(in, out);
  }
}

void EsdfMap::forLines(int lines, const std::function<void(int line, LineScratch& s)>& fn) {
  pool_.parallelFor((lines + kLinesPerTask - 1) / kLinesPerTask, [&](int task, int worker) {
    LineScratch& s = scratch_[size_t(worker)];
    const int end = std::min(lines, (task + 1) * kLinesPerTask);
    for (int line = task * kLinesPerTask; line < end; ++line) fn(line, s);
  });
}

void EsdfMap::firstPassAlongX(const VoxelBox& in) {
  // 1-D squared distances along x to the sites (positive field) and to the non-sites (negative
  // field). Values at or above the truncation become +inf: they cannot give a value below it.
  const Eigen::Vector3i n = in.size();
  const int nx = n.x(), ny = n.y();
  const OccupancyMap& occ = *occupancy_;
  const bool unknown_site = config_.unknown_as_occupied;
  const int32_t cap = cap_sq_voxels_;
  forLines(ny * n.z(), [&](int line, LineScratch& s) {
    const int y = line % ny, z = line / ny;
    const size_t start = size_t(nx) * (size_t(y) + size_t(ny) * size_t(z));
    occ.readSiteLineX(in.min + Eigen::Vector3i(0, y, z), nx, unknown_site, s.site.data());
    binaryLineTransformPair(s.site.data(), pos_sq_.data() + start, neg_sq_.data() + start, nx, cap);
  });
}

namespace {

// Largest value of a row, counting values at or beyond the truncation as the truncation.
// Written as an element-wise max over 8 lanes, which vectorises (a plain float max reduction
// does not without -ffast-math), then reduced.
float rowMax(const float* v, int n, float cap) {
  float lanes[8] = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
  int x = 0;
  for (; x + 8 <= n; x += 8)
    for (int k = 0; k < 8; ++k) lanes[k] = std::max(lanes[k], v[x + k]);
  float m = 0.0f;
  for (; x < n; ++x) m = std::max(m, v[x]);
  for (float l : lanes) m = std::max(m, l);
  return std::min(m, cap);
}

// out[x] = min over |r| <= radius, 0 <= i + r < count of rows(i + r)[x] + r^2, for x in [0, n),
// where rows(k) returns row k. The window stops at the r whose r^2 reaches the largest value of the
// centre row: the result is at most that row, so no farther row can lower it. The inner loops are
// plain element-wise min/add, which the compiler vectorises.
template <typename RowFn>
void windowedMinRow(RowFn&& rows, int i, int count, int radius, int n, float cap, float* out) {
  const float* centre = rows(i);
  std::copy(centre, centre + n, out);
  const float m = rowMax(centre, n, cap);
  for (int r = 1; r <= radius; ++r) {
    const float r2 = float(r) * float(r);
    if (r2 >= m) break;
    if (i - r >= 0) {
      const float* a = rows(i - r);
      for (int x = 0; x < n; ++x) out[x] = std::min(out[x], a[x] + r2);
    }
    if (i + r < count) {
      const float* b = rows(i + r);
      for (int x = 0; x < n; ++x) out[x] = std::min(out[x], b[x] + r2);
    }
  }
}

}  // namespace

void EsdfMap::computeWindowed(const VoxelBox& in, const VoxelBox& out) {
  const Eigen::Vector3i n = in.size();
  const int nx = n.x(), ny = n.y(), nz = n.z();
  const size_t plane = size_t(nx) * size_t(ny);
  const float cap = float(cap_sq_voxels_);
  const int cap_radius = int(std::ceil(std::sqrt(cap)));

  // Pass 2, along y, one z-plane at a time (in place through a per-worker plane buffer).
  forLines(nz, [&](int z, LineScratch& s) {
    for (std::vector<float>* field : {&pos_sq_, &neg_sq_}) {
      float* f = field->data() + size_t(z) * plane;
      for (int y = 0; y < ny; ++y)
        windowedMinRow([&](int k) { return f + size_t(k) * nx; }, y, ny, cap_radius, nx, cap,
                       s.plane.data() + size_t(y) * nx);
      std::copy(s.plane.data(), s.plane.data() + plane, f);
    }
  });

  // Pass 3, along z, one output row (y, z) at a time, straight into the field.
  const int ox0 = out.min.x() - in.min.x(), onx = out.size().x();
  const int oy0 = out.min.y() - in.min.y(), ony = out.size().y();
  const int oz0 = out.min.z() - in.min.z(), onz = out.size().z();
  forLines(ony, [&](int line, LineScratch& s) {
    const int y = oy0 + line;
    auto pos_rows = [&](int k) { return pos_sq_.data() + size_t(k) * plane + size_t(y) * nx + ox0; };
    auto neg_rows = [&](int k) { return neg_sq_.data() + size_t(k) * plane + size_t(y) * nx + ox0; };
    for (int z = oz0; z < oz0 + onz; ++z) {
      windowedMinRow(pos_rows, z, nz, cap_radius, onx, cap, s.row_a.data());
      windowedMinRow(neg_rows, z, nz, cap_radius, onx, cap, s.row_b.data());
      writeRow(in.min + Eigen::Vector3i(ox0, y, z), onx, s.row_a.data(), s.row_b.data(), s.row_c.data());
    }
  });
}

void EsdfMap::computeEnvelope(const VoxelBox& in, const VoxelBox& out) {
  const Eigen::Vector3i n = in.size();
  const int nx = n.x(), ny = n.y(), nz = n.z();
  const int32_t cap = cap_sq_voxels_;
  auto local = [&](int x, int y, int z) { return size_t(x) + size_t(nx) * (size_t(y) + size_t(ny) * size_t(z)); };
  // Transforms one strided line of a field into s.f (squared voxels, >= cap: beyond the
  // truncation): the exact lower envelope for the positive field; for the negative one, where the
  // nearest free voxel is close, the bounded search.
  auto transform = [&](const std::vector<float>& buf, bool positive, size_t start, size_t stride, int len,
                       LineScratch& s) {
    bool all_zero = true, all_empty = true;
    for (int i = 0; i < len; ++i) {
      const float x = buf[start + size_t(i) * stride];
      s.f[size_t(i)] = x < float(cap) ? int32_t(x) : kNoSite;
      all_zero &= x == 0.0f;
      all_empty &= s.f[size_t(i)] == kNoSite;
    }
    if (all_zero || all_empty) return;
    if (positive) {
      lowerEnvelopeTransform(s.f.data(), s.d.data(), len, s.v.data(), s.zn.data(), s.zd.data());
    } else {
      boundedLineTransform(s.f.data(), s.d.data(), len, cap);
    }
    std::copy(s.d.begin(), s.d.begin() + len, s.f.begin());
  };
  auto toFloat = [cap](int32_t v) { return v >= cap ? INFINITY : float(v); };
  const int ox0 = out.min.x() - in.min.x(), onx = out.size().x();
  const int oy0 = out.min.y() - in.min.y(), ony = out.size().y();
  const int oz0 = out.min.z() - in.min.z(), onz = out.size().z();
  // Pass 2, along y, for the output's x-range.
  forLines(onx * nz, [&](int line, LineScratch& s) {
    const int x = ox0 + line % onx, z = line / onx;
    const size_t start = local(x, 0, z);
    for (std::vector<float>* field : {&pos_sq_, &neg_sq_}) {
      transform(*field, field == &pos_sq_, start, size_t(nx), ny, s);
      for (int i = 0; i < ny; ++i) (*field)[start + size_t(i) * nx] = toFloat(s.f[size_t(i)]);
    }
  });
  // Pass 3, along z, for the output columns, written to the field.
  forLines(onx * ony, [&](int line, LineScratch& s) {
    const int x = ox0 + line % onx, y = oy0 + line / onx;
    const size_t start = local(x, y, 0), stride = size_t(nx) * size_t(ny);
    transform(pos_sq_, true, start, stride, nz, s);
    for (int i = 0; i < nz; ++i) s.row_a[size_t(i)] = toFloat(s.f[size_t(i)]);
    transform(neg_sq_, false, start, stride, nz, s);
    for (int i = 0; i < nz; ++i) s.row_b[size_t(i)] = toFloat(s.f[size_t(i)]);
    for (int z = oz0; z < oz0 + onz; ++z)
      writeRow(in.min + Eigen::Vector3i(x, y, z), 1, &s.row_a[size_t(z)], &s.row_b[size_t(z)], s.row_c.data());
  });
}

void EsdfMap::writeRow(const Eigen::Vector3i& first, int n, const float* pos_sq, const float* neg_sq, float* tmp) {
  const float res = float(geometry().resolution());
  const float max_d = float(config_.max_distance_m);
  const float cap = float(cap_sq_voxels_);
  // Branch-free so that it vectorises: sqrt(cap) * res >= max_d, so clamping the square at cap
  // and the distance at max_d gives the truncated value.
  for (int i = 0; i < n; ++i) {
    const float p = std::min(max_d, std::sqrt(std::min(pos_sq[i], cap)) * res);
    const float q = std::min(max_d, std::sqrt(std::min(neg_sq[i], cap)) * res);
    tmp[i] = pos_sq[i] > 0.0f ? p : -q;
  }
  // Consecutive x are consecutive addresses except where the ring buffer wraps (at most once).
  const int sx = geometry().size().x();
  const size_t addr = geometry().address(first);
  float* row = distance_.data() + (addr - addr % size_t(sx));
  const int ring_x = int(addr % size_t(sx));
  const int before_wrap = std::min(n, sx - ring_x);
  std::copy(tmp, tmp + before_wrap, row + ring_x);
  std::copy(tmp + before_wrap, tmp + n, row);
}

QueryStatus EsdfMap::distance(const Eigen::Vector3i& index, double* distance) const {
  if (!geometry().inWindow(index)) return QueryStatus::kOutOfMap;
  *distance = distance_[geometry().address(index)];
  return occupancy_->state(index) == VoxelState::kUnknown ? QueryStatus::kUnknown : QueryStatus::kOk;
}

DistanceQuery EsdfMap::nearest(const Eigen::Vector3d& point) const {
  DistanceQuery q;
  if (!point.allFinite()) {
    q.status = QueryStatus::kInvalidInput;
    return q;
  }
  if (!geometry().inWindow(point)) return q;
  q.status = distance(geometry().indexOf(point), &q.distance);
  return q;
}

bool EsdfMap::interpolate(const Eigen::Vector3d& point, double* distance, Eigen::Vector3d* gradient) const {
  if (!point.allFinite()) return false;
  const GridGeometry& g = geometry();
  const Eigen::Vector3d pm = point * g.inverseResolution() - Eigen::Vector3d::Constant(0.5);
  if ((pm.array().abs() > 1e9).any()) return false;
  const Eigen::Vector3d fl = pm.array().floor();
  const Eigen::Vector3i base = fl.cast<int>();
  const Eigen::Vector3d t = pm - fl;
  if (!g.inWindow(base) || !g.inWindow(Eigen::Vector3i(base + Eigen::Vector3i::Ones()))) return false;
  double v[2][2][2];
  for (int dx = 0; dx < 2; ++dx)
    for (int dy = 0; dy < 2; ++dy)
      for (int dz = 0; dz < 2; ++dz) v[dx][dy][dz] = distance_[g.address(base + Eigen::Vector3i(dx, dy, dz))];
  // Interpolate along x, then y, then z; the gradient is the derivative of the same polynomial.
  double vx[2][2], dvx[2][2];
  for (int dy = 0; dy < 2; ++dy)
    for (int dz = 0; dz < 2; ++dz) {
      vx[dy][dz] = (1 - t.x()) * v[0][dy][dz] + t.x() * v[1][dy][dz];
      dvx[dy][dz] = v[1][dy][dz] - v[0][dy][dz];
    }
  double vxy[2], dxy_x[2], dxy_y[2];
  for (int dz = 0; dz < 2; ++dz) {
    vxy[dz] = (1 - t.y()) * vx[0][dz] + t.y() * vx[1][dz];
    dxy_x[dz] = (1 - t.y()) * dvx[0][dz] + t.y() * dvx[1][dz];
    dxy_y[dz] = vx[1][dz] - vx[0][dz];
  }
  *distance = (1 - t.z()) * vxy[0] + t.z() * vxy[1];
  if (gradient) {
    gradient->x() = ((1 - t.z()) * dxy_x[0] + t.z() * dxy_x[1]) * g.inverseResolution();
    gradient->y() = ((1 - t.z()) * dxy_y[0] + t.z() * dxy_y[1]) * g.inverseResolution();
    gradient->z() = (vxy[1] - vxy[0]) * g.inverseResolution();
  }
  return true;
}

DistanceQuery EsdfMap::query(const Eigen::Vector3d& point) const {
  DistanceQuery q;
  if (!point.allFinite()) {
    q.status = QueryStatus::kInvalidInput;
    return q;
  }
  if (!interpolate(point, &q.distance, &q.gradient)) return q;  // kOutOfMap
  const GridGeometry& g = geometry();
  const Eigen::Vector3i base = (point * g.inverseResolution() - Eigen::Vector3d::Constant(0.5)).array().floor().cast<int>();
  bool unknown = false;
  for (int k = 0; k < 8 && !unknown; ++k)
    unknown = occupancy_->state(Eigen::Vector3i(base + Eigen::Vector3i(k & 1, (k >> 1) & 1, (k >> 2) & 1))) ==
              VoxelState::kUnknown;
  q.status = unknown ? QueryStatus::kUnknown : QueryStatus::kOk;
  return q;
}

bool EsdfMap::isInflatedOccupied(const Eigen::Vector3i& index) const {
  if (!geometry().inWindow(index)) return true;
  return distance_[geometry().address(index)] <= float(config_.inflate_radius_m) + 1e-6f;
}

bool EsdfMap::isInflatedOccupied(const Eigen::Vector3d& point) const {
  if (!geometry().inWindow(point)) return true;
  return isInflatedOccupied(geometry().indexOf(point));
}

bool ascendDistance(const EsdfMap& map, const Eigen::Vector3d& from,
                    const std::function<bool(const Eigen::Vector3d&)>& done, double max_length_m,
                    std::vector<Eigen::Vector3d>* path) {
  assert(path);
  path->clear();
  double distance = 0.0;
  Eigen::Vector3d gradient;
  if (!map.interpolate(from, &distance, &gradient)) return false;
  path->push_back(from);
  const double step = 0.5 * map.geometry().resolution();
  for (double length = 0.0; !done(path->back()); length += step) {
    const double norm = gradient.norm();
    if (!(length + step <= max_length_m) || !(norm > 1e-3)) return false;
    const Eigen::Vector3d next = path->back() + gradient * (step / norm);
    double next_distance = 0.0;
    if (!map.interpolate(next, &next_distance, &gradient) || next_distance < distance - 1e-6) return false;
    distance = next_distance;
    path->push_back(next);
  }
  return true;
}

}  // namespace topo_planner
