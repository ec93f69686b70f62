#include "topo_planner/topo_replan/known_space_commitment.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "topo_planner/bspline_opt/bspline_costs.h"
#include "topo_planner/topo_replan/stop_profile.h"

namespace topo_planner {

bool KnownSpaceCommitment::Config::validate(std::string* why) const {
  std::string e;
  if (!(std::isfinite(clearance_m) && clearance_m >= 0.0 && clearance_m <= OccupancyMap::kMaxKnownRadius))
    e += "clearance_m must be in [0, 1]; ";
  if (!(std::isfinite(known_start_radius_m) && known_start_radius_m >= 0.0)) e += "known_start_radius_m must be >= 0; ";
  if (!(std::isfinite(margin_m) && margin_m >= 0.0)) e += "margin_m must be >= 0; ";
  if (!(std::isfinite(brake_acc_mps2) && brake_acc_mps2 > 0.0)) e += "brake_acc_mps2 must be positive; ";
  if (!(std::isfinite(max_brake_acc_mps2) && max_brake_acc_mps2 >= brake_acc_mps2))
    e += "max_brake_acc_mps2 must be >= brake_acc_mps2; ";
  if (!(min_z_m < max_z_m)) e += "min_z_m must be below max_z_m; ";
  if (!(sample_s >= 1e-3 && sample_s <= 0.5)) e += "sample_s must be in [0.001, 0.5]; ";
  if (why) *why = e.empty() ? "" : e.substr(0, e.size() - 2);
  return e.empty();
}

double KnownSpaceCommitment::bandExcess(double z) const { return heightBandExcess(z, config_.min_z_m, config_.max_z_m); }

bool KnownSpaceCommitment::committable(const EsdfMap& map, const Eigen::Vector3d& p, double start_excess,
                                       const std::optional<Eigen::Vector3d>& anchor) const {
  // The height band (route/min_z_m, max_z_m, a geofence): no farther out of it than the plan's start
  // (a take-off from below the band climbs into it; a plan from inside stays inside).
  if (bandExcess(p.z()) > start_excess + 1e-3) return false;
  // Only around a hover the planner did not fly to (a mission's start, a re-anchoring): around any
  // plan's start, each plan would commit known_start_radius_m further into unobserved space (a
  // creep at a metre per second into space the camera cannot see, e.g. above or below it).
  if (anchor && (p - *anchor).norm() <= config_.known_start_radius_m) return true;
  // Observed free with the clearance all round: the ESDF counts only observed obstacles, so a point
  // in seen air beside an unseen face (below or beside the camera's view) would pass on distance.
  // Around the anchor the clearance ball of every exempt point counts as known too: the camera's
  // blind zone beside and above a vehicle that starts from a hover (its view is a cone from the
  // camera) would otherwise hold it there.
  const DistanceQuery q = map.query(p);
  if (q.status != QueryStatus::kOk || q.distance < config_.clearance_m) return false;
  const double anchor_ball = config_.known_start_radius_m + config_.clearance_m;
  return map.occupancy().isKnownWithin(p, config_.clearance_m, [&](const Eigen::Vector3d& c) {
    return anchor && (c - *anchor).norm() <= anchor_ball;
  });
}

bool KnownSpaceCommitment::commit(const UniformBspline& plan, const EsdfMap& map,
                                  const std::optional<Eigen::Vector3d>& anchor, Committed* out, std::string* why) const {
  Committed* traj = out;
  traj->spline = plan;
  traj->brake_start_tau_s = plan.duration();
  traj->stops_before_unknown = false;
  traj->heading_target.reset();
  if (!config_.enabled) return true;
  // The plan sampled by time, with arc length, up to its first point that may not be committed to.
  const double T = plan.duration(), dt = config_.sample_s;
  const UniformBspline vel = plan.derivative();
  const Eigen::Vector3d start = plan.evaluate(0.0);
  const double start_excess = bandExcess(start.z());
  const UniformBspline acc = vel.derivative();
  std::vector<double> taus, arc, speed, along;  // along: the acceleration along the path
  double blocked_s = -1.0;
  Eigen::Vector3d prev = start;
  for (double tau = 0.0;; tau = std::min(T, tau + dt)) {
    const Eigen::Vector3d p = plan.evaluate(tau);
    const double s = arc.empty() ? 0.0 : arc.back() + (p - prev).norm();
    prev = p;
    // (Not where the vehicle is: the start, and a hold there. After an odometry jump, or beside space
    // that became unknown when the window scrolled, it holds and looks instead of failing every plan.)
    if ((p - start).norm() > 1e-6 && !committable(map, p, start_excess, anchor)) {
      blocked_s = s;
      break;
    }
    taus.push_back(tau);
    arc.push_back(s);
    const Eigen::Vector3d v_tau = vel.evaluate(tau);
    speed.push_back(tau >= T ? 0.0 : v_tau.norm());
    along.push_back(tau >= T ? 0.0 : alongAcceleration(v_tau, acc.evaluate(tau)));
    if (tau >= T) break;
  }
  if (blocked_s < 0.0) return true;  // all of it is known free: flown as planned

  // The last sample from which (and from every one before it) a stop along the path at the planning
  // deceleration ends `margin` before the blocked point. The stop is fitted as one spline with the
  // part flown as planned, and the fit may swerve a few centimetres where the deceleration starts or
  // ends: where that leaves the known free space (a path that runs along its edge), the stop is cut
  // again with a wider margin.
  const double a = config_.brake_acc_mps2;
  const Eigen::Vector3d v0 = vel.evaluate(0.0), a0 = acc.evaluate(0.0);
  double tau_b = 0.0;
  bool cut = false;
  // Stop lengths from each sample, at the planning deceleration computed once (shared by the margins).
  std::vector<double> length_at_a(taus.size(), -1.0);
  auto stopLength = [&](size_t k, double decel) {
    if (decel != a) return StopProfile(speed[k], decel, along[k], false).length();
    if (length_at_a[k] < 0.0) length_at_a[k] = StopProfile(speed[k], a, along[k], false).length();
    return length_at_a[k];
  };
  for (const double margin : {config_.margin_m, config_.margin_m + 0.15, config_.margin_m + 0.4}) {
    size_t kb = 0;
    while (kb + 1 < taus.size() && stopLength(kb + 1, a) + margin <= blocked_s - arc[kb + 1]) ++kb;
    double a_stop = a;
    const double room = blocked_s - arc[kb] - margin;
    // A wider margin is no reason to brake harder than planned: only the first may need that.
    if (margin > config_.margin_m && stopLength(kb, a) > room) break;
    // Even now it cannot stop before unknown space at the planning limit (the map shrank or the
    // start is already too close): stop harder, as hard as the vehicle allows.
    while (a_stop < config_.max_brake_acc_mps2 && stopLength(kb, a_stop) > room)
      a_stop = std::min(config_.max_brake_acc_mps2, 1.15 * a_stop);
    // Flown as planned to tau_b, then a stop along the same path, refitted as one spline.
    tau_b = taus[kb];
    const double v_b = speed[kb];
    const StopProfile stop(v_b, a_stop, along[kb]);
    const double T_stop = v_b > 1e-3 ? stop.duration() : 0.0, T_total = tau_b + T_stop;
    const PathByLength path(plan, tau_b, 0.01);
    if (T_total < 0.05 && v0.norm() < 0.05 && a0.norm() < 0.5) {
      // At rest at the edge of the known space: hold, and look where the plan goes.
      traj->spline = UniformBspline::straightLine(start, start, 6, 3, 0.1);
    } else {
      // (At least 0.2 s: the end of a stop still decelerating eases to rest instead of a step to a hold.)
      const double T_fit = std::max(T_total, 0.2);
      const int n = std::max(6, int(std::ceil(T_fit / 0.05)));
      const double h = T_fit / n;
      std::vector<Eigen::Vector3d> points;
      for (int k = 0; k <= n; ++k) {
        const double tau = k * h;
        if (tau <= tau_b) {
          points.push_back(plan.evaluate(tau));
        } else {
          points.push_back(path.at(stop.distance(tau - tau_b)));
        }
      }
      UniformBspline fitted;
      if (!UniformBspline::fitToPoints(points, h, v0, a0, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 3, &fitted)) {
        *why = "known-space commitment: the cut trajectory could not be fitted";
        return false;
      }
      traj->spline = fitted;
    }
    // The cut trajectory is checked as it will be flown.
    const double D = traj->spline.duration();
    cut = true;
    for (double tau = 0.0;; tau = std::min(D, tau + dt)) {
      const Eigen::Vector3d q = traj->spline.evaluate(tau);
      if ((q - start).norm() > 1e-6 && !committable(map, q, start_excess, anchor)) {
        *why = "known-space commitment: the cut trajectory leaves the known free space " + std::to_string(tau) +
               " s after its start";
        cut = false;
        break;
      }
      if (tau >= D) break;
    }
    if (cut) break;
  }
  if (!cut) return false;
  why->clear();
  traj->brake_start_tau_s = std::min(tau_b, traj->spline.duration());
  traj->stops_before_unknown = true;
  // The camera should look past the stop, along the plan.
  const PathByLength ahead(plan, 0.0, 0.02);
  traj->heading_target = ahead.at(std::min(ahead.length(), blocked_s + 1.0));
  return true;
}

}  // namespace topo_planner
