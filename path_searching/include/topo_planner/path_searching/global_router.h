#pragma once
// The mission's global route: a weighted A* over the whole map window, at the guide search's
// clearance, through known free space and (optimistically) unknown space, shortened by line of
// sight. The FSM turns it into the global reference, so the local search (which samples around the
// reference segment) looks along the route: a window far aside in a wall is found once it is seen,
// where a straight reference would leave it outside the local sampling box.
//
// Grid. The search runs on cells of cell_voxels^3 voxels. A cell stands for its best voxel: the one
// farthest from obstacles among those in the height band and known free (or unknown, when unknown
// space counts as free). A cell is free when that voxel keeps clearance_m. The best voxels of two
// neighbouring cells are at most (2 cell_voxels - 1) sqrt(3) voxels apart (0.52 m with 2 voxels of
// 0.1 m), so the segment between them keeps at least clearance_m minus half that (0.04 m at the
// defaults): the raw route never crosses an obstacle, and the shortening keeps clearance_m on every
// shortcut it takes. The local planner checks every trajectory itself: the route is guidance.
// Near the start and the goal (end_radius_m; start_radius_m around the start) a cell is free down to
// end_clearance_m and outside the band: the vehicle may hover closer to an obstacle than the
// route's clearance. The voxels of the start and the goal themselves must not be occupied.
//
// Cost. Edge length times 1 + clearance_weight * max(0, preferred_clearance_m - d) /
// preferred_clearance_m, d the ESDF of the cell entered: the route keeps to the middle of openings
// and away from obstacles where there is room, and still passes narrow windows; times 1 +
// unknown_weight when the cell entered is unknown space (a known way before an unknown one). The heuristic is
// heuristic_weight times the Euclidean distance (weighted A*: a route at most that factor longer
// in cost than the best, found with far fewer expansions).
//
// Outcome. kNoPath means the search exhausted the window: at this clearance and band, with unknown
// space free, the goal cannot be reached from the start; the map proves the mission unreachable.
// kBudgetExhausted proves nothing.
//
// Buffers: dense, generation-stamped, reused between calls (about 21 bytes per cell: 21 MB for a
// 40 x 40 x 5 m window at 0.1 m with cell_voxels = 2). Not reentrant; the map is only read.

#include <cstdint>
#include <string>
#include <vector>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/path_searching/search_status.h"
#include "topo_planner/path_searching/visibility.h"

namespace topo_planner {

class GlobalRouter {
 public:
  struct Config {
    double clearance_m = 0.3;              ///< the route keeps this from obstacles [m]
    bool unknown_is_free = true;           ///< route through unobserved space (optimistic)
    int cell_voxels = 2;                   ///< cell edge in voxels, 1 to 4
    double preferred_clearance_m = 1.0;    ///< closer than this costs more [m]
    double clearance_weight = 2.0;         ///< see the class comment; >= 0
    double heuristic_weight = 1.5;         ///< >= 1; 1 is plain A*
    double min_z_m = -1e9;                 ///< height band of the route (geofence) [m]
    double max_z_m = 1e9;
    /// The route keeps this far inside the band where it can; a route in the margin is searched
    /// only when none keeps it (so kNoPath still means: none in the band). Under the band's
    /// ceiling the top of a wall as high as it is seldom in the camera's view: unknown, hence free
    /// to the route, it made a way over the wall that the vehicle flew to, stopped at and backed
    /// off from, again and again [m].
    double band_margin_m = 0.0;
    double end_radius_m = 0.6;             ///< relaxed rules this close to the start and the goal [m]
    double start_radius_m = 0.6;           ///< ... and this close to the start [m] (the larger applies)
    double end_clearance_m = 0.1;          ///< ... down to this clearance [m]
    int max_expansions = 1500000;          ///< budget
    int shortcut_lookahead = 24;           ///< shortening: raw points tried past the last visible one
    double avoid_weight = 4.0;             ///< entering a cell in an avoided zone costs 1 + this times more; >= 0
    /// Entering a cell whose best voxel is unknown costs 1 + this times more (unknown_is_free only),
    /// and the shortening takes no shortcut through unknown space between points the route reached
    /// through known space: a way the camera has seen is preferred unless an unknown one is much
    /// shorter (a return leg goes back through the window it came through). 0: unknown is as
    /// good as known; >= 0.
    double unknown_weight = 0.0;

    bool validate(std::string* why) const;
  };
  struct Result {
    SearchStatus status = SearchStatus::kInvalidInput;
    Path path;       ///< shortened: start, corners, goal
    Path raw;        ///< start, the best voxel of every cell, goal
    int expansions = 0;
    double length_m = 0.0;  ///< of path
  };

  explicit GlobalRouter(const Config& config) : config_(config) {}
  const Config& config() const { return config_; }
  /// A place the route keeps away from where it can (the FSM's stalls: where the vehicle made no
  /// progress along an earlier route): a cell whose best voxel lies within radius_m of center costs
  /// 1 + avoid_weight times more to enter (compounding where zones overlap: a place stalled at again
  /// weighs more each time), and the shortening takes no shortcut that crosses a zone
  /// between two points outside it. The zones only weigh: they never block, so kNoPath still proves
  /// the goal unreachable.
  struct Zone {
    Eigen::Vector3d center = Eigen::Vector3d::Zero();
    double radius_m = 0.0;
  };
  /// The zones of the following searches (non-finite ones are dropped).
  void setAvoided(const std::vector<Zone>& zones);
  const std::vector<Zone>& avoided() const { return avoided_; }
  /// A route from start to goal; see the class comment for the statuses.
  Result route(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal);

 private:
  /// One search with the band [min_z_m, max_z_m].
  Result search(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal, double min_z_m,
                double max_z_m);

  Config config_;
  std::vector<Zone> avoided_;
  std::vector<float> g_;
  std::vector<int32_t> parent_;
  std::vector<uint32_t> stamp_;       // open: generation; closed: generation | top bit
  std::vector<uint32_t> cell_stamp_;  // the cell's best voxel was computed in this generation
  std::vector<float> cell_distance_;  // its distance; -1 when the cell has no usable voxel
  std::vector<uint8_t> cell_best_;    // its offset in the cell (x + k (y + k z))
  std::vector<uint8_t> cell_unknown_; // its best voxel is unknown
  uint32_t generation_ = 0;
};

}  // namespace topo_planner
