#pragma once
// Geometric paths: polylines of waypoints in the world frame.

#include <Eigen/Core>
#include <vector>

namespace topo_planner {

using Path = std::vector<Eigen::Vector3d>;

/// Sum of segment lengths.
double pathLength(const Path& path);

/// K + 1 points at uniform arc length s_i = i / K along the path (the paper's uniform
/// parameterisation of piecewise-straight paths). A path of one point gives K + 1 copies of it.
Path discretizeByArcLength(const Path& path, int k);

/// Points at most `step` apart along the path, keeping every original waypoint, so that two
/// consecutive points always lie on one original segment.
Path resamplePath(const Path& path, double step);

/// Point at normalised arc length s in [0, 1].
Eigen::Vector3d pointAtArcLength(const Path& path, double s);

}  // namespace topo_planner
