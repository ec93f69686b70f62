#pragma once
// The cost terms of path-guided optimisation (paper, Sect. III-B), on the control points of a
// uniform B-spline, with analytic gradients.
//
// Conventions shared by every term: q holds the control points Q_0..Q_N, one per row; the
// optimised ("free") ones are Q_first..Q_last, the others are fixed by the boundary states. Each
// function returns its unweighted cost and, when grad is not null, ADDS weight * d cost / d Q to
// grad (same shape as q; rows of fixed points receive their derivative too, which the optimiser
// ignores). Pass weight = 1 and a zeroed grad to get the plain gradient.

#include <Eigen/Core>
#include <algorithm>

#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

/// Elastic band smoothness of Eq. 2: sum over i = first - 1 .. last + 1 (within [1, N - 1]) of
/// ||Q_{i+1} - 2 Q_i + Q_{i-1}||^2, i.e. every second difference that involves a free point [m^2].
double smoothnessCost(const Eigen::MatrixX3d& q, int first, int last, double weight, Eigen::MatrixX3d* grad);

/// Guide cost of Eq. 3: sum over i = first..last of ||Q_i - G_i||^2 [m^2]; guide has one row per
/// free point (row i - first is G_i).
double guideCost(const Eigen::MatrixX3d& q, const Eigen::MatrixX3d& guide, int first, int last, double weight,
                 Eigen::MatrixX3d* grad);


/// Signed distance of p to the faces of the map's window (the domain of EsdfMap::interpolate: half a
/// voxel inside them), negative outside; *inward (optional) is the unit normal of the nearest face,
/// pointing into the window [m].
double windowDistance(const GridGeometry& geometry, const Eigen::Vector3d& p, Eigen::Vector3d* inward);

/// How far z lies outside the height band [min_z_m, max_z_m] (a geofence: the optimiser's final
/// check, the replanner's local goal and the FSM's committed part all allow a curve no farther out
/// of it than its start or its goal); 0 inside the band [m].
inline double heightBandExcess(double z, double min_z_m, double max_z_m) {
  return std::max({0.0, min_z_m - z, z - max_z_m});
}

/// Collision cost on the free control points: sum of (d0 - d(Q_i))^2 over the points whose distance
/// d is below d0; zero beyond d0, C1 at d0 [m^2]. d is the smaller of the ESDF distance (trilinear,
/// EsdfMap::interpolate) and windowDistance: the map window's faces count as obstacles, since
/// nothing outside the window is known or checkable (the final check refuses a curve that leaves
/// it), so a curve near a face (a raised floor, a ceiling, the window's edge) is pushed back inside
/// instead of failing the final check every time. NaN points contribute nothing. The faces of a
/// height band [min_z_m, max_z_m] (a geofence the final check enforces) count as obstacles too,
/// face_offset_m farther than they are: the final check asks an obstacle's clearance of the curve,
/// none of a face, and with the offset a face pushes no harder than an obstacle at that clearance.
double collisionCost(const Eigen::MatrixX3d& q, int first, int last, const EsdfMap& map, double d0_m, double weight,
                     Eigen::MatrixX3d* grad, double min_z_m = -1e9, double max_z_m = 1e9, double face_offset_m = 0.0);

/// Velocity feasibility on the derivative control points V_i = (Q_{i+1} - Q_i) / dt, i = 0..N-1:
/// sum of (||V_i|| - v_max)^2 over the V_i faster than v_max [(m/s)^2]. Every V_i is included
/// (those between fixed points only add a constant).
double velocityCost(const Eigen::MatrixX3d& q, double dt_s, double max_vel_mps, double weight, Eigen::MatrixX3d* grad);

/// Acceleration feasibility on A_i = (Q_{i+2} - 2 Q_{i+1} + Q_i) / dt^2, i = 0..N-2: sum of
/// (||A_i|| - a_max)^2 over the A_i above a_max [(m/s^2)^2].
double accelerationCost(const Eigen::MatrixX3d& q, double dt_s, double max_acc_mps2, double weight,
                        Eigen::MatrixX3d* grad);

}  // namespace topo_planner
