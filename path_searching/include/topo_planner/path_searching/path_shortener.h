#pragma once
// Path shortening of the paper's Alg. 2 (Sect. IV-C): walk the discretised path keeping the last
// waypoint; where a point is not visible from it, take the first blocking voxel, push it away from
// the obstacle along the ESDF gradient made orthogonal to the line of sight, and append it.
//
// Two guards the paper leaves implicit make the result safe: a pushed point is accepted only if it
// is free and sees both the last waypoint and the current point (otherwise the last visible point of
// the input is appended instead, which keeps every segment collision-free); and a result that is
// longer than the input, or not equivalent to it, is replaced by the input.

#include "topo_planner/path_searching/path.h"
#include "topo_planner/path_searching/visibility.h"

namespace topo_planner {

class PathShortener {
 public:
  explicit PathShortener(const VisibilityChecker& checker) : checker_(checker) {}

  /// The shortened path; `fell_back` (optional) tells whether the input was returned unchanged
  /// because the shortcut was longer or not equivalent.
  Path shorten(const Path& raw, bool* fell_back = nullptr) const;

 private:
  const VisibilityChecker& checker_;
};

}  // namespace topo_planner
