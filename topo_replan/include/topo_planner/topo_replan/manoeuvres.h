#pragma once
// The manoeuvres the replanning FSM flies when it cannot, or must not, follow a plan (its
// recoveries): the braking stop, the escape up the distance field, the back-off along the flown path
// (or to the hover it started from), and the slow rest-to-rest flight both of the latter use. Each is
// a value built from the commanded state, the map and a few settings, and checked on that map before
// it is returned; no state, no lock. The FSM decides when to fly one (replan_fsm.h); this unit says
// what the vehicle then does.

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/topo_replan/exec_trajectory.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace topo_planner {

struct ManoeuvreConfig {
  double safety_clearance_m = 0.2;   ///< a trajectory collides below this ESDF distance [m]
  double safety_sample_s = 0.02;     ///< time step of the checks [s]
  double brake_acc_mps2 = 2.5;       ///< deceleration of a stop [m/s^2]
  /// A stop that would come within the safety clearance decelerates harder, in steps of 1.25x, up
  /// to this (the vehicle's limit) [m/s^2].
  double max_brake_acc_mps2 = 5.0;
  double escape_clearance_m = 0.45;      ///< an escape climbs the distance field to this [m] ...
  double escape_min_clearance_m = 0.35;  ///< ... or ends on a ridge at least this far [m]
  double escape_speed_mps = 0.5;         ///< peak speed of an escape [m/s]
  double max_escape_length_m = 1.0;      ///< no escape longer than this [m]; 0: never
  /// Manoeuvres stay in known space (beyond known_start_radius_m of their start, the vehicle's own
  /// place); false: the map's distance alone.
  bool commit_to_known_space = true;
  double known_start_radius_m = 0.3;  ///< [m]
  double backoff_length_m = 1.5;      ///< a back-off flies at least this far back along the flown path [m] ...
  double max_backoff_length_m = 3.0;  ///< ... and on until escape_clearance_m from obstacles, up to this [m]
  double backoff_speed_mps = 1.0;     ///< peak speed of a back-off [m/s]
  /// With no flown path to go back along, a back-off goes back to the known anchor (the hover the
  /// vehicle started from) when it is at least this far from it [m] ...
  double anchor_backoff_min_m = 0.1;
  /// ... and at most known_start_radius_m plus this: it crept to the edge of the anchor's zone [m].
  double anchor_backoff_margin_m = 0.05;
};

/// First time >= t at which `traj` comes closer than clearance_m to an obstacle or leaves the map,
/// sampled every sample_s; -1 if none.
double firstCollisionTime(const ExecTrajectory& traj, double t, const EsdfMap& map, double clearance_m,
                          double sample_s);

/// A stop from s0 at time t: along `along`'s path from t when given (a trajectory flown at t, its
/// path checked when it was published: a stop on a curve stays on the curve), else along the
/// velocity; at brake_acc_mps2, and when that comes within the safety clearance and `may_brake_harder`,
/// harder up to max_brake_acc_mps2. Nearly at rest (below 0.05 m/s), a hold. Always returns a
/// trajectory (braking is the last safe action left); *report says the deceleration and the check.
ExecTrajectory brakingTrajectory(const FlatState& s0, const ExecTrajectory* along, double t, const EsdfMap& map,
                                 const ManoeuvreConfig& config, bool may_brake_harder, std::string* report);

/// From s0's position at rest, up the distance field (ascendDistance) to escape_clearance_m;
/// nullopt with the reason in *report when there is no such way (see restToRest for the rest).
std::optional<ExecTrajectory> escapeTrajectory(const FlatState& s0, double t, const EsdfMap& map,
                                               const ManoeuvreConfig& config, std::string* report);

/// The way a back-off flies, before its timing.
struct BackoffWalk {
  std::vector<Eigen::Vector3d> points;  ///< from the vehicle's position, shortcut where clear
  double length_m = 0.0;                ///< along the flown path (or to the anchor) [m]
  double end_clearance_m = 0.0;         ///< the map's distance at its end [m]
  bool to_anchor = false;               ///< back to the known anchor, not along a flown path
};

/// The flown path the back-offs walk back along: commanded positions of checked trajectories (not
/// the manoeuvres: a back-off would walk back along the previous one), newest last.
class FlownPath {
 public:
  static constexpr double kSpacingM = 0.25;  ///< between recorded positions [m]
  static constexpr size_t kMaxPoints = 200;  ///< beyond, the oldest half is dropped
  /// The commanded position now: kept when kSpacingM from the last one kept.
  void record(const Eigen::Vector3d& p);
  /// A back-off to `end` used the way back up to there: a later one goes on from where it ends.
  void useUpTo(const Eigen::Vector3d& end);
  /// Forgotten (an odometry jump: in the old frame).
  void clear() { points_.clear(); }
  const std::vector<Eigen::Vector3d>& points() const { return points_; }

 private:
  std::vector<Eigen::Vector3d> points_;
};

/// From p0 (d0 from obstacles) back along `flown` (commanded positions, newest last) until
/// backoff_length_m is flown and the point keeps escape_clearance_m, or max_backoff_length_m; with
/// no flown path (shorter than 0.3 m or backoff_length_m), back to `anchor` when p0 is within its
/// zone (anchor_backoff_min_m to known_start_radius_m + anchor_backoff_margin_m from it). Corners are
/// cut where the straight way keeps min(d0, safety_clearance_m). nullopt with the reason otherwise.
std::optional<BackoffWalk> backoffWalk(const Eigen::Vector3d& p0, double d0, const std::vector<Eigen::Vector3d>& flown,
                                       const std::optional<Eigen::Vector3d>& anchor, const EsdfMap& map,
                                       const ManoeuvreConfig& config, std::string* why);

/// The back-off from s0's position (backoffWalk), flown by restToRest at backoff_speed_mps;
/// *to_anchor (when given) says whether it goes back to the anchor.
std::optional<ExecTrajectory> backoffTrajectory(const FlatState& s0, double t, const EsdfMap& map,
                                                const std::vector<Eigen::Vector3d>& flown,
                                                const std::optional<Eigen::Vector3d>& anchor,
                                                const ManoeuvreConfig& config, std::string* report,
                                                bool* to_anchor = nullptr);

/// A slow rest-to-rest flight along `walk` (walk.front() is s0's position, d0 from obstacles),
/// peaking at speed_mps (slowed at corners), an escape-kind ExecTrajectory from t. Checked along the
/// curve: never closer to an obstacle than it starts (nor than the safety clearance when it starts
/// farther), never out of the map. Where the curve crosses unknown space it is not flown: a hold at
/// p0 looking at the walk's end is returned instead, with *report saying so (non-empty); nullopt
/// with the reason when the walk cannot be fitted or the check fails; otherwise *report is empty.
std::optional<ExecTrajectory> restToRest(const std::vector<Eigen::Vector3d>& walk, const FlatState& s0, double t,
                                         const EsdfMap& map, double d0, double speed_mps, const char* what,
                                         const ManoeuvreConfig& config, std::string* report);

}  // namespace topo_planner
