#include "topo_planner/uav_sim/depth_camera.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>

#include "topo_planner/plan_env/raycast.h"

namespace topo_planner {

namespace {

constexpr int kBlockVoxels = 8;  // edge of a culling block [voxels]

// Per-frame quantities of the rasteriser.
struct View {
  Eigen::Matrix3d R_cw;  // world -> camera rotation
  Eigen::Vector3d o;     // camera centre, world [m]
  double res;
  // Camera-frame point of the voxel-grid corner c. The same corner always gives the same bits,
  // which makes shared face edges exact (see the class comment).
  Eigen::Vector3d corner(const Eigen::Vector3i& c) const { return R_cw * (c.cast<double>() * res - o); }
};

// Smallest distance from p to the box [lo, hi].
double distanceToBox(const Eigen::Vector3d& p, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  return (p.cwiseMax(lo).cwiseMin(hi) - p).norm();
}

}  // namespace

const char* DepthCamera::toString(Method method) {
  switch (method) {
    case Method::kRasterize: return "rasterize";
    case Method::kRaycast: return "raycast";
  }
  return "?";
}

DepthCamera::DepthCamera(const Config& config, const EsdfMap& truth) : config_(config), truth_(truth), rng_(config.seed) {
  assert(config_.camera.valid());
  const PinholeCamera& cam = config_.camera;
  ray_x_.resize(cam.width);
  ray_y_.resize(cam.height);
  for (int u = 0; u < cam.width; ++u) ray_x_[u] = float((u - cam.cx) / cam.fx);
  for (int v = 0; v < cam.height; ++v) ray_y_[v] = float((v - cam.cy) / cam.fy);
  buildSurface();
}

void DepthCamera::buildSurface() {
  const GridGeometry& g = truth_.geometry();
  const VoxelBox w = g.windowBox();
  // Occupied as the raycast sees it (the sign of the field). A neighbour outside the window is not
  // free: a camera inside the map never sees that face, and one outside sees nothing.
  auto occupied = [&](const Eigen::Vector3i& i) {
    float d;
    return truth_.voxelDistance(i, &d) && d <= 0.0f;
  };
  auto free = [&](const Eigen::Vector3i& i) {
    float d;
    return truth_.voxelDistance(i, &d) && d > 0.0f;
  };
  const Eigen::Vector3i nb = (w.size().array() + kBlockVoxels - 1) / kBlockVoxels;
  std::vector<std::array<std::vector<Face>, 6>> lists(size_t(nb.x()) * nb.y() * nb.z());
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        if (!occupied(i)) continue;
        const Eigen::Vector3i b = (i - w.min) / kBlockVoxels;
        auto& block = lists[size_t(b.x()) + size_t(nb.x()) * (size_t(b.y()) + size_t(nb.y()) * b.z())];
        for (int d = 0; d < 6; ++d) {
          Eigen::Vector3i n = i;
          n[d / 2] += (d & 1) ? 1 : -1;
          if (free(n)) block[d].push_back({i.x(), i.y(), i.z()});
        }
      }
  faces_.clear();
  blocks_.clear();
  for (size_t k = 0; k < lists.size(); ++k) {
    size_t count = 0;
    for (const auto& l : lists[k]) count += l.size();
    if (count == 0) continue;
    const Eigen::Vector3i b(int(k % nb.x()), int(k / nb.x() % nb.y()), int(k / (size_t(nb.x()) * nb.y())));
    Block block;
    block.lo = w.min + b * kBlockVoxels;
    block.hi = (block.lo + Eigen::Vector3i::Constant(kBlockVoxels - 1)).cwiseMin(w.max);
    for (int d = 0; d < 6; ++d) {
      block.begin[d] = uint32_t(faces_.size());
      faces_.insert(faces_.end(), lists[k][d].begin(), lists[k][d].end());
    }
    block.begin[6] = uint32_t(faces_.size());
    blocks_.push_back(block);
  }
}

bool DepthCamera::render(const Eigen::Isometry3d& T_world_camera, std::vector<float>* depth) {
  if (!T_world_camera.matrix().allFinite()) return false;
  stats_ = RenderStats();
  if (config_.method == Method::kRaycast)
    raycast(T_world_camera, depth);
  else
    rasterize(T_world_camera, depth);
  // Noise and the minimum range, shared by both renderers (same draws for the same hits).
  const bool noisy = config_.noise_stddev_at_1m > 0.0, holes = config_.invalid_fraction > 0.0;
  std::normal_distribution<float> noise(0.0f, 1.0f);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  for (float& out : *depth) {
    if (holes && u01(rng_) < config_.invalid_fraction) {
      out = NAN;
      continue;
    }
    if (!std::isfinite(out)) continue;
    double z = out;
    if (noisy) z += config_.noise_stddev_at_1m * z * z * noise(rng_);
    out = z < config_.min_range_m ? NAN : float(z);
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Rasteriser

void DepthCamera::rasterize(const Eigen::Isometry3d& T_world_camera, std::vector<float>* depth) {
  const PinholeCamera& cam = config_.camera;
  const int W = cam.width, H = cam.height;
  depth->assign(size_t(W) * size_t(H), INFINITY);
  const GridGeometry& g = truth_.geometry();
  View view;
  view.R_cw = T_world_camera.linear().transpose();
  view.o = T_world_camera.translation();
  view.res = g.resolution();
  const double res = view.res, max_range = config_.max_range_m;

  // As the raycast: nothing seen from outside the map, depth 0 from inside an obstacle.
  float here;
  if (!truth_.voxelDistance(g.indexOf(view.o), &here)) return;
  if (here <= 0.0f) {
    std::fill(depth->begin(), depth->end(), 0.0f);
    return;
  }

  inv_depth_.assign(size_t(W) * size_t(H), 0.0f);
  // Side planes of the view frustum (through the camera centre, normals inwards, one pixel of
  // margin), in the world frame, for culling blocks.
  const double x_lo = (-1.0 - cam.cx) / cam.fx, x_hi = (W - cam.cx) / cam.fx;
  const double y_lo = (-1.0 - cam.cy) / cam.fy, y_hi = (H - cam.cy) / cam.fy;
  const Eigen::Matrix3d R_wc = T_world_camera.linear();
  const std::array<Eigen::Vector3d, 4> planes = {R_wc * Eigen::Vector3d(1.0, 0.0, -x_lo), R_wc * Eigen::Vector3d(-1.0, 0.0, x_hi),
                                                 R_wc * Eigen::Vector3d(0.0, 1.0, -y_lo), R_wc * Eigen::Vector3d(0.0, -1.0, y_hi)};
  // Outward normals of the six face directions in the camera frame.
  std::array<Eigen::Vector3d, 6> normal_c;
  for (int d = 0; d < 6; ++d) normal_c[d] = view.R_cw.col(d / 2) * ((d & 1) ? 1.0 : -1.0);
  const Eigen::Vector3d o_grid = view.o / res;  // camera centre in voxel units
  const double z_eps = 1e-3 * res;             // below this a corner is not projected for the bounding box

  for (const Block& block : blocks_) {
    const Eigen::Vector3d lo = block.lo.cast<double>() * res, hi = (block.hi + Eigen::Vector3i::Ones()).cast<double>() * res;
    if (distanceToBox(view.o, lo, hi) > max_range) continue;
    const Eigen::Vector3d centre = 0.5 * (lo + hi) - view.o, half = 0.5 * (hi - lo);
    bool outside = false;
    for (const Eigen::Vector3d& n : planes) outside |= n.dot(centre) + n.cwiseAbs().dot(half) < 0.0;
    if (outside) continue;
    ++stats_.blocks_drawn;

    for (int d = 0; d < 6; ++d) {
      const int a = d / 2, b = (a + 1) % 3, c = (a + 2) % 3;
      const bool positive = d & 1;
      // A face is seen from the free side of its plane only (strictly: edge-on faces cover nothing).
      if (positive ? o_grid[a] <= block.lo[a] + 1 : o_grid[a] >= block.hi[a]) continue;
      for (uint32_t f = block.begin[d]; f < block.begin[d + 1]; ++f) {
        const Eigen::Vector3i voxel(faces_[f].x, faces_[f].y, faces_[f].z);
        const int plane = voxel[a] + (positive ? 1 : 0);
        if (positive ? !(o_grid[a] > plane) : !(o_grid[a] < plane)) continue;
        // Corners counter-clockwise about +axis a: (b, c) = (0,0), (1,0), (1,1), (0,1).
        Eigen::Vector3i k = voxel;
        k[a] = plane;
        std::array<Eigen::Vector3d, 4> P;
        P[0] = view.corner(k);
        ++k[b];
        P[1] = view.corner(k);
        ++k[c];
        P[2] = view.corner(k);
        --k[b];
        P[3] = view.corner(k);

        // Rows and columns to scan: the projected bounding box when the face is in front of the
        // camera, else the whole image (the edge functions below are exact either way).
        double u_min = 0.0, u_max = W - 1, v_min = 0.0, v_max = H - 1;
        if (P[0].z() > z_eps && P[1].z() > z_eps && P[2].z() > z_eps && P[3].z() > z_eps) {
          double pu_min = INFINITY, pu_max = -INFINITY, pv_min = INFINITY, pv_max = -INFINITY;
          for (const Eigen::Vector3d& p : P) {
            const double pu = cam.cx + cam.fx * p.x() / p.z(), pv = cam.cy + cam.fy * p.y() / p.z();
            pu_min = std::min(pu_min, pu);
            pu_max = std::max(pu_max, pu);
            pv_min = std::min(pv_min, pv);
            pv_max = std::max(pv_max, pv);
          }
          u_min = std::max(u_min, std::floor(pu_min));
          u_max = std::min(u_max, std::ceil(pu_max));
          v_min = std::max(v_min, std::floor(pv_min));
          v_max = std::min(v_max, std::ceil(pv_max));
          if (u_min > u_max || v_min > v_max) continue;
        }
        ++stats_.faces_drawn;

        // Edge functions: ray r is inside the face iff e_k . r >= 0 for the 4 edges, with
        // e_k = sign * P_k x P_k+1. The sign orients the cone: det(P0, P1, P2) has the sign of
        // (plane - o) along axis a, i.e. negative for faces towards +a.
        std::array<Eigen::Vector3d, 4> e;
        for (int j = 0; j < 4; ++j) {
          e[j] = P[j].cross(P[(j + 1) & 3]);
          if (positive) e[j] = -e[j];
        }
        // 1/z over the face: r . normal / (normal . P0), r = (x_n, y_n, 1).
        const double plane_offset = (positive ? 1.0 : -1.0) * (plane * res - view.o[a]);  // normal . P0 < 0
        const Eigen::Vector3d gz = normal_c[d] / plane_offset;
        const float gx = float(gz.x());

        for (int v = int(v_min); v <= int(v_max); ++v) {
          const double yn = ray_y_[v];
          double first = u_min, last = u_max;
          for (const Eigen::Vector3d& n : e) {
            // n.x (u - cx) / fx + n.y yn + n.z >= 0. The bound is computed from n the same way
            // whatever its sign, so a shared edge (opposite e) gives the same value on both sides.
            const double q = n.y() * yn + n.z();
            if (n.x() > 0.0)
              first = std::max(first, std::ceil(cam.cx - cam.fx * (q / n.x())));
            else if (n.x() < 0.0)
              last = std::min(last, std::floor(cam.cx - cam.fx * (q / n.x())));
            else if (q < 0.0)
              last = -1.0;
          }
          if (first > last) continue;
          const int u0 = int(first), u1 = int(last);
          stats_.fragments += u1 - u0 + 1;
          const float w_axis = float(gz.y() * yn + gz.z());
          float* row = &inv_depth_[size_t(v) * W];
          const float* xn = ray_x_.data();
          for (int u = u0; u <= u1; ++u) row[u] = std::max(row[u], w_axis + gx * xn[u]);
        }
      }
    }
  }

  // 1/z to z; the range is along the ray, as for the raycast: t^2 = z^2 (x_n^2 + y_n^2 + 1).
  const float max_range_sq = float(max_range * max_range);
  for (int v = 0; v < H; ++v) {
    const float yy = ray_y_[v] * ray_y_[v] + 1.0f;
    const float* in = &inv_depth_[size_t(v) * W];
    float* out = &(*depth)[size_t(v) * W];
    for (int u = 0; u < W; ++u) {
      if (in[u] <= 0.0f) continue;
      const float z = 1.0f / in[u];
      if (z * z * (ray_x_[u] * ray_x_[u] + yy) <= max_range_sq) out[u] = z;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Raycast (reference)

double DepthCamera::castRay(const Eigen::Vector3d& o, const Eigen::Vector3d& u) const {
  const GridGeometry& g = truth_.geometry();
  const double res = g.resolution(), half_diagonal = 0.5 * std::sqrt(3.0) * res, nudge = 1e-6 * res;
  const double max_t = config_.max_range_m;
  double t = 0.0;
  while (t <= max_t) {
    const Eigen::Vector3d p = o + u * t;
    const Eigen::Vector3i v = g.indexOf(p);
    float d;
    if (!truth_.voxelDistance(v, &d)) return INFINITY;  // left the map: nothing more to see
    if (d <= 0.0f) {
      // Occupied: depth of the entry point into this voxel along the ray.
      const Eigen::Vector3d lo = v.cast<double>() * res, hi = lo + Eigen::Vector3d::Constant(res);
      double t_enter = 0.0;
      for (int k = 0; k < 3; ++k)
        if (std::abs(u[k]) > 1e-12) t_enter = std::max(t_enter, std::min((lo[k] - o[k]) / u[k], (hi[k] - o[k]) / u[k]));
      return t_enter <= max_t ? t_enter : INFINITY;
    }
    double next = t + distanceToBallExit(p, u, g.centerOf(v), double(d) - half_diagonal);
    if (next <= t + nudge) next = t + distanceToVoxelExit(p, u, v, res) + nudge;  // into the next voxel
    t = next;
  }
  return INFINITY;
}

void DepthCamera::raycast(const Eigen::Isometry3d& T_world_camera, std::vector<float>* depth) {
  const PinholeCamera& cam = config_.camera;
  depth->assign(size_t(cam.width) * size_t(cam.height), INFINITY);
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d o = T_world_camera.translation();
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d ray_c((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      const double len = ray_c.norm();  // metres along the ray per metre of depth
      const double t = castRay(o, R * (ray_c / len));
      if (std::isfinite(t)) (*depth)[size_t(v) * cam.width + u] = float(t / len);
    }
}

void DepthCamera::toMillimetres(const std::vector<float>& depth, std::vector<uint16_t>* mm) {
  mm->resize(depth.size());
  for (size_t i = 0; i < depth.size(); ++i) {
    const float d = depth[i];
    (*mm)[i] = std::isfinite(d) && d > 0.0f ? uint16_t(std::min(65535.0f, std::round(d * 1000.0f))) : uint16_t(0);
  }
}

}  // namespace topo_planner
