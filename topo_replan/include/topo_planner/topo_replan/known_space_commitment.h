#pragma once
// The known-space commitment (FASTER's safe/committed split, Tordesillas et al., T-RO 2021, done
// along the plan's path): the replanner plans optimistically, unknown space counting as free, so it
// explores; what the FSM publishes is cut to what is known. The plan is flown as planned while, at
// every instant, a stop along its path at the back-up deceleration (brake_acc_mps2) would end
// margin_m before the first path point that may not be committed to (committable()); from the last
// such instant the published trajectory brakes along the same path to rest, refitted as one spline
// with the part flown as planned. So at every instant of every published trajectory the vehicle can
// stop in space the map has observed free; if no later plan takes over, it does stop there. When even
// the first instant cannot stop in time at brake_acc_mps2 (the map shrank, or the start is already
// too close) the stop brakes harder, up to max_brake_acc_mps2.
//
// The back-up deceleration decides how fast the vehicle may fly towards the edge of what it has
// seen: a stop from v needs about v^2 / 2a, and the camera sees a few metres. The planning limit
// (2.5 m/s^2) capped a 5 m/s flight at 4.1 m/s in the open, every plan cut 0.0-0.1 s after its start;
// the vehicle's limit (max_brake_acc_mps2, 5 m/s^2) halves the distance, and the stop it would brake
// along is only flown when no new plan comes in time.
//
// A point may be committed to when it is observed free (all 8 voxels around it), at least
// clearance_m from known obstacles, with every voxel within clearance_m of it observed (the ESDF
// counts only observed obstacles: a point in seen air beside a face the camera never saw would pass
// on distance alone), and no farther out of the height band than the plan's start; or when it lies
// within known_start_radius_m of the known anchor (where the vehicle hovers without having been flown
// there: a mission's start, a re-anchoring), whose clearance ball counts as known too (the camera's
// blind zone beside a vehicle starting from a hover).
//
// No ROS, no state between calls; the map is only read.

#include <Eigen/Core>
#include <optional>
#include <string>

#include "topo_planner/bspline_opt/uniform_bspline.h"
#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

class KnownSpaceCommitment {
 public:
  struct Config {
    bool enabled = true;               ///< false: plans are published as planned (optimistic)
    double clearance_m = 0.2;          ///< committed points keep this from known obstacles, all of it observed [m]
    double known_start_radius_m = 0.3; ///< around the known anchor, points count as known [m]
    double margin_m = 0.1;             ///< the stop ends this far before unknown space [m]
    double brake_acc_mps2 = 5.0;       ///< the back-up's deceleration: how early the plan must start stopping [m/s^2]
    double max_brake_acc_mps2 = 5.0;   ///< ... harder, up to this, when even the first instant cannot stop in time [m/s^2]
    double min_z_m = -1e9;             ///< the height band (a geofence): no farther out of it than the start [m]
    double max_z_m = 1e9;
    double sample_s = 0.02;            ///< time step of the checks [s]

    bool validate(std::string* why) const;
  };
  /// A plan as it may be published.
  struct Committed {
    UniformBspline spline;          ///< the plan, or the plan cut to a stop before unknown space
    double brake_start_tau_s = 0.0; ///< flown as planned until here (its duration when not cut) [s]
    bool stops_before_unknown = false;  ///< it was cut
    /// Where the camera should look when the cut trajectory ends at rest: a point past the stop on the
    /// planned path.
    std::optional<Eigen::Vector3d> heading_target;
  };

  explicit KnownSpaceCommitment(const Config& config) : config_(config) {}
  const Config& config() const { return config_; }

  /// The commitment of `plan` on `map` (see the class comment), with `anchor` the known anchor if any.
  /// False (with why) when the cut trajectory cannot be built or leaves the known free space.
  bool commit(const UniformBspline& plan, const EsdfMap& map, const std::optional<Eigen::Vector3d>& anchor,
              Committed* out, std::string* why) const;
  /// Whether a point may be committed to (see the class comment); start_excess: how far the plan's
  /// start lies outside the height band.
  bool committable(const EsdfMap& map, const Eigen::Vector3d& p, double start_excess,
                   const std::optional<Eigen::Vector3d>& anchor) const;
  /// How far z lies outside the height band [m]; 0 inside.
  double bandExcess(double z) const;

 private:
  Config config_;
};

}  // namespace topo_planner
