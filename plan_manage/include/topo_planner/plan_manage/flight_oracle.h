#pragma once
// The time an ideal vehicle that knows the map needs for a mission: the yardstick of the flight's
// speed (mission time / oracle time).
//
// Each leg is the global route (path_searching GlobalRouter) on the simulator's true map at the
// planning clearance and the route's height band, searched for length alone (no preference for
// the middle of openings, plain A*) and shortened by line of sight; it is then flown time-optimally
// along its length at max_vel and max_acc (topo_replan PathSpeedProfile: corners as the widest arcs
// the legs allow, a forward-backward pass over the curvature speed limit). A sequential mission
// stops at every goal (rest to rest per leg); a pass-through mission flies its goals as waypoints
// of one path and stops at the last only. It knows the whole map and has no sensing, planning or
// jerk limit: a lower bound of a real vehicle's time, not a plan it could fly.
// No ROS; the map is only read.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

class FlightOracle {
 public:
  struct Config {
    double clearance_m = 0.3;      ///< the planner's guide search clearance [m]
    double min_z_m = 0.3;          ///< the route's height band [m]
    double max_z_m = 3.0;          ///< [m]
    double max_vel_mps = 3.0;      ///< [m/s]
    double max_acc_mps2 = 2.5;     ///< [m/s^2]
    int max_expansions = 4000000;  ///< route search budget per leg
    bool pass_through = false;     ///< the goals are waypoints of one mission (rest at the last only)

    bool validate(std::string* why) const;
  };
  struct Result {
    bool ok = false;
    std::string why;                  ///< when not ok
    std::vector<Path> routes;         ///< per leg: start (or the previous goal) to the goal
    std::vector<double> length_m;     ///< per leg, of the smoothed path [m]
    std::vector<double> time_s;       ///< per leg [s]
    double total_s = 0.0;             ///< [s]
  };

  /// The oracle's legs from `start` through `goals` on `truth` (all of it known).
  static Result compute(const EsdfMap& truth, const Eigen::Vector3d& start, const std::vector<Eigen::Vector3d>& goals,
                        const Config& config);
  /// The same within the planner's map window (origin, size): the true map's occupied voxels there,
  /// everything else in it free, nothing outside. The simulator's true map reaches beyond the
  /// planner's window (a margin around the obstacles), where the oracle would fly round the end of
  /// a wall that closes the planner's world.
  static Result computeInWindow(const OccupancyMap& truth, const Eigen::Vector3d& window_origin_m,
                                const Eigen::Vector3d& window_size_m, const Eigen::Vector3d& start,
                                const std::vector<Eigen::Vector3d>& goals, const Config& config);
};

}  // namespace topo_planner
