#include "topo_planner/topo_replan/manoeuvres.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/topo_replan/stop_profile.h"

namespace topo_planner {

double firstCollisionTime(const ExecTrajectory& traj, double t, const EsdfMap& map, double clearance_m,
                          double sample_s) {
  const double begin = std::max(t, traj.start_time_s), end = traj.endTime();
  for (double s = begin;; s = std::min(end, s + sample_s)) {
    const DistanceQuery q = map.query(traj.spline.evaluate(s - traj.start_time_s));
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput || q.distance < clearance_m)
      return s;
    if (s >= end) break;
  }
  return -1.0;
}

ExecTrajectory brakingTrajectory(const FlatState& start, const ExecTrajectory* along, double t, const EsdfMap& map,
                                 const ManoeuvreConfig& config, bool may_brake_harder, std::string* report) {
  FlatState s0 = start;
  const double speed = s0.velocity.norm();
  // Nearly at rest: a hold where it is, from the commanded velocity and acceleration (the end of a
  // stop still decelerating), so neither steps.
  const Eigen::Vector3d creep = s0.velocity;
  if (speed < 0.05) s0.velocity.setZero();
  // Along the path flown at t, which was checked when it was published: a stop on a curve stays on
  // the curve instead of leaving it along the tangent. Without one, along the velocity.
  const bool along_path = along && t - along->start_time_s < along->spline.duration();
  std::optional<PathByLength> path;
  if (along_path) {
    path.emplace(along->spline, t - along->start_time_s, 0.01);
    if (speed >= 0.05) path->setDirection(s0.velocity);
  }
  auto brakeAt = [&](double a) {
    std::vector<Eigen::Vector3d> points;
    double interval = 0.1;
    Eigen::Vector3d start_acc = Eigen::Vector3d::Zero(), start_vel = s0.velocity;
    if (speed < 0.05) {
      points.assign(4, s0.position);
      start_vel = creep;
      start_acc = s0.acceleration;
    } else if (path) {
      // From the flown acceleration (the curve's included): no step in the commanded acceleration.
      points = stopPoints(*path, 0.0, speed, a, alongAcceleration(s0.velocity, s0.acceleration), &interval);
      points.front() = s0.position;
      start_acc = s0.acceleration;
    } else {
      const Eigen::Vector3d u = s0.velocity / speed;
      const double a0 = alongAcceleration(s0.velocity, s0.acceleration);
      const StopProfile stop(speed, a, a0);
      const int n = std::max(4, int(std::ceil(stop.duration() / 0.05)));
      interval = stop.duration() / n;
      for (int k = 0; k <= n; ++k) points.push_back(s0.position + u * stop.distance(k * interval));
      start_acc = a0 * u;  // along the line of the stop
    }
    ExecTrajectory brake;
    brake.start_time_s = t;
    brake.braking = true;
    if (!UniformBspline::fitToPoints(points, interval, start_vel, start_acc, Eigen::Vector3d::Zero(),
                                     Eigen::Vector3d::Zero(), 3, &brake.spline)) {
      // Only for a degenerate state; hold the position instead (a spline of equal points).
      brake.spline = UniformBspline::straightLine(s0.position, s0.position, 6, 3, 0.1);
    }
    brake.brake_start_s = t;
    return brake;
  };
  // At the planner's limit when that stops in time; harder (up to the vehicle's) when it does not.
  double a = config.brake_acc_mps2;
  ExecTrajectory brake = brakeAt(a);
  double hit = firstCollisionTime(brake, t, map, config.safety_clearance_m, config.safety_sample_s);
  while (hit >= 0.0 && speed >= 0.05 && a < config.max_brake_acc_mps2 && may_brake_harder) {
    a = std::min(config.max_brake_acc_mps2, 1.25 * a);
    brake = brakeAt(a);
    hit = firstCollisionTime(brake, t, map, config.safety_clearance_m, config.safety_sample_s);
  }
  if (report) {
    char decel[96];
    std::snprintf(decel, sizeof(decel), "braking at %.2f m/s^2 %s", speed < 0.05 ? 0.0 : a,
                  path ? "along the path " : "");
    *report = std::string(decel) + (hit < 0.0 ? "checked: collision-free"
                                              : "checked: comes within the safety clearance " +
                                                    std::to_string(hit - t) + " s after braking starts");
  }
  return brake;
}

std::optional<ExecTrajectory> escapeTrajectory(const FlatState& s0, double t, const EsdfMap& map,
                                               const ManoeuvreConfig& config, std::string* report) {
  const Eigen::Vector3d p0 = s0.position;
  double d0 = 0.0;
  if (!(config.max_escape_length_m > 0.0) || !map.interpolate(p0, &d0, nullptr)) {
    *report = "no escape: disabled, or the vehicle is outside the map";
    return std::nullopt;
  }
  const double target = config.escape_clearance_m;
  std::vector<Eigen::Vector3d> walk;
  const bool reached = ascendDistance(map, p0, [&](const Eigen::Vector3d& p) {
    double d = 0.0;
    return map.interpolate(p, &d, nullptr) && d >= target;
  }, config.max_escape_length_m, &walk);
  // A walk that stops short of the target (on a ridge between obstacles) still escapes when it
  // ended at least escape_min_clearance_m from obstacles.
  double d_end = -INFINITY;
  if (!walk.empty()) map.interpolate(walk.back(), &d_end, nullptr);
  if (walk.size() < 2 || (!reached && !(d_end >= config.escape_min_clearance_m))) {
    *report = "no escape: no way up the distance field to " + std::to_string(config.escape_min_clearance_m) +
              " m within " + std::to_string(config.max_escape_length_m) + " m (from " + std::to_string(d0) + " m)";
    return std::nullopt;
  }
  std::optional<ExecTrajectory> escape = restToRest(walk, s0, t, map, d0, config.escape_speed_mps, "escape", config, report);
  if (!escape || !report->empty()) return escape;
  char text[160];
  std::snprintf(text, sizeof(text), "escape: %.2f m up the distance field from %.2f m to %.2f m clearance in %.1f s",
                pathLength(walk), d0, d_end, escape->spline.duration());
  *report = text;
  return escape;
}

std::optional<BackoffWalk> backoffWalk(const Eigen::Vector3d& p0, double d0, const std::vector<Eigen::Vector3d>& flown,
                                       const std::optional<Eigen::Vector3d>& anchor, const EsdfMap& map,
                                       const ManoeuvreConfig& config, std::string* why) {
  // Back along the flown path (newest first) until backoff_length_m is flown and the point keeps
  // escape_clearance_m, or max_backoff_length_m.
  BackoffWalk w;
  std::vector<Eigen::Vector3d> walk{p0};
  double length = 0.0, d_end = d0;
  for (auto it = flown.rbegin(); it != flown.rend(); ++it) {
    const double step = (*it - walk.back()).norm();
    if (step < 0.05) continue;
    if (length + step > config.max_backoff_length_m) break;
    walk.push_back(*it);
    length += step;
    if (!map.interpolate(*it, &d_end, nullptr)) d_end = -INFINITY;
    if (length >= config.backoff_length_m && d_end >= config.escape_clearance_m) break;
  }
  if (length < std::min(0.3, config.backoff_length_m) || walk.size() < 2) {
    // No flown path since the vehicle hovered without having flown there (a mission's start, or at
    // rest after a re-anchoring cleared the map): back to that hover, the known anchor, when it has
    // crept away from it within the anchor's zone. There the blind zone beside the camera counts as
    // known; from where it crept to, the space just ahead (seen by the camera, its clearance ball
    // not) is neither, and every plan was cut to a hold (fault_odom_blackout held 60 s).
    const double from_anchor = anchor ? (p0 - *anchor).norm() : INFINITY;
    if (!(from_anchor >= config.anchor_backoff_min_m &&
          from_anchor <= config.known_start_radius_m + config.anchor_backoff_margin_m)) {
      *why = "no back-off: no flown path to go back along";
      return std::nullopt;
    }
    w.points = {p0, *anchor};
    w.length_m = from_anchor;
    if (!map.interpolate(*anchor, &d_end, nullptr)) d_end = -INFINITY;
    w.end_clearance_m = d_end;
    w.to_anchor = true;
    return w;
  }
  // The flown path zig-zags where the vehicle hovered and re-planned: shortcut it where the straight
  // way keeps the clearance the vehicle had (or the safety clearance), so the manoeuvre has no corners.
  const double keep = std::min(d0, config.safety_clearance_m);
  auto straightIsClear = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const int n = std::max(1, int(std::ceil((b - a).norm() / 0.05)));
    for (int k = 0; k <= n; ++k) {
      double d = 0.0;
      if (!map.interpolate(a + (b - a) * (double(k) / n), &d, nullptr) || d < keep) return false;
    }
    return true;
  };
  w.points = {walk.front()};
  for (size_t i = 0; i + 1 < walk.size();) {
    size_t j = walk.size() - 1;
    while (j > i + 1 && !straightIsClear(walk[i], walk[j])) --j;
    w.points.push_back(walk[j]);
    i = j;
  }
  w.length_m = length;
  w.end_clearance_m = d_end;
  return w;
}

std::optional<ExecTrajectory> backoffTrajectory(const FlatState& s0, double t, const EsdfMap& map,
                                                const std::vector<Eigen::Vector3d>& flown,
                                                const std::optional<Eigen::Vector3d>& anchor,
                                                const ManoeuvreConfig& config, std::string* report, bool* to_anchor) {
  double d0 = 0.0;
  if (!map.interpolate(s0.position, &d0, nullptr)) {
    *report = "no back-off: the vehicle is outside the map";
    return std::nullopt;
  }
  const std::optional<BackoffWalk> walk = backoffWalk(s0.position, d0, flown, anchor, map, config, report);
  if (!walk) return std::nullopt;
  std::optional<ExecTrajectory> backoff =
      restToRest(walk->points, s0, t, map, d0, config.backoff_speed_mps, "back-off", config, report);
  if (to_anchor) *to_anchor = walk->to_anchor;
  if (!backoff || !report->empty()) return backoff;
  char text[160];
  std::snprintf(text, sizeof(text), "back-off: %.2f m back %s, from %.2f m to %.2f m clearance in %.1f s",
                walk->length_m, walk->to_anchor ? "to the hover it started from" : "along the flown path", d0,
                walk->end_clearance_m, backoff->spline.duration());
  *report = text;
  return backoff;
}

std::optional<ExecTrajectory> restToRest(const std::vector<Eigen::Vector3d>& walk, const FlatState& s0, double t,
                                         const EsdfMap& map, double d0, double speed_mps, const char* what,
                                         const ManoeuvreConfig& config, std::string* report) {
  report->clear();
  const Eigen::Vector3d p0 = walk.front();
  std::vector<double> arc{0.0};
  for (size_t i = 1; i < walk.size(); ++i) arc.push_back(arc.back() + (walk[i] - walk[i - 1]).norm());
  const double length = arc.back();
  // Rest to rest along the walk with a smoothstep s(u) = L (3u^2 - 2u^3), whose peak speed is 1.5 L / T;
  // slowed down (at most 2 x 1.5 times: the bound is conservative, and a stretched walk must stay a
  // manoeuvre of seconds, cheap to fit) while the fitted curve's acceleration bound exceeds half the
  // braking deceleration (corners of the walk), so the vehicle tracks it closely. At most 200 points.
  ExecTrajectory escape;
  escape.start_time_s = t;
  escape.escape = true;
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  double T = std::max(0.5, 1.5 * length / speed_mps);
  for (int attempt = 0;; ++attempt) {
    const int n = std::clamp(int(std::ceil(T / 0.05)), 6, 200);
    std::vector<Eigen::Vector3d> points;
    size_t seg = 1;
    for (int k = 0; k <= n; ++k) {
      const double u = double(k) / n, s = length * u * u * (3.0 - 2.0 * u);
      while (seg + 1 < walk.size() && arc[seg] < s) ++seg;
      const double span = arc[seg] - arc[seg - 1];
      const double f = span > 0.0 ? std::clamp((s - arc[seg - 1]) / span, 0.0, 1.0) : 1.0;
      points.push_back(walk[seg - 1] + f * (walk[seg] - walk[seg - 1]));
    }
    // It starts in the state flown there (a creep below stopped_speed_mps is not a rest: no step).
    if (!UniformBspline::fitToPoints(points, T / n, s0.velocity, s0.acceleration, zero, zero, 3, &escape.spline)) {
      *report = std::string("no ") + what + ": the walk could not be fitted";
      return std::nullopt;
    }
    const double acc = escape.spline.maxAcceleration(), limit = 0.5 * config.brake_acc_mps2;
    if (acc <= limit || attempt >= 2) break;
    T *= std::min(1.5, std::sqrt(acc / limit) * 1.05);
  }
  // Checked along the curve: never closer than it starts (nor than the safety clearance, when it
  // starts farther), never out of the map, in known space (beyond the vehicle's own radius).
  const double floor_m = std::min(d0, config.safety_clearance_m) - 0.02;
  for (double tau = 0.0;; tau = std::min(escape.spline.duration(), tau + config.safety_sample_s)) {
    double d = 0.0;
    const Eigen::Vector3d p = escape.spline.evaluate(tau);
    const bool known = !config.commit_to_known_space || (p - p0).norm() <= config.known_start_radius_m ||
                       (map.query(p).status == QueryStatus::kOk &&
                        map.occupancy().isKnownWithin(p, std::max(0.0, floor_m)));
    if (!known) {
      // Look before moving: hold here, turning the camera towards the way out (the trajectory
      // server turns to a held trajectory's heading target); the next try sees it.
      ExecTrajectory look;
      look.start_time_s = t;
      look.escape = true;
      look.spline = UniformBspline::straightLine(p0, p0, 6, 3, 0.1);
      look.brake_start_s = t;
      look.has_heading_target = true;
      look.heading_target = walk.back();
      *report = std::string(what) + ": the way crosses unknown space; holding and looking there first";
      return look;
    }
    if (!map.interpolate(p, &d, nullptr) || d < floor_m) {
      *report = std::string("no ") + what + ": the fitted manoeuvre comes closer to an obstacle than it starts";
      return std::nullopt;
    }
    if (tau >= escape.spline.duration()) break;
  }
  return escape;
}

void FlownPath::record(const Eigen::Vector3d& p) {
  if (points_.empty() || (p - points_.back()).norm() >= kSpacingM) points_.push_back(p);
  if (points_.size() > kMaxPoints) points_.erase(points_.begin(), points_.begin() + kMaxPoints / 2);
}

void FlownPath::useUpTo(const Eigen::Vector3d& end) {
  while (!points_.empty() && (points_.back() - end).norm() > 0.3) points_.pop_back();
}

}  // namespace topo_planner
