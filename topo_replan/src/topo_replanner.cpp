#include "topo_planner/topo_replan/topo_replanner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <sstream>

#include "topo_planner/bspline_opt/bspline_costs.h"
#include "topo_planner/path_searching/path_shortener.h"

namespace topo_planner {

namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

const char* toString(ReplanStatus status) {
  switch (status) {
    case ReplanStatus::kSuccess: return "success";
    case ReplanStatus::kStartInCollision: return "start in collision";
    case ReplanStatus::kGoalInCollision: return "no safe local goal on the reference";
    case ReplanStatus::kGoalOutOfMap: return "local goal out of the map";
    case ReplanStatus::kInvalidInput: return "invalid input";
    case ReplanStatus::kNoPath: return "no guide path";
    case ReplanStatus::kOptimizationFailed: return "no candidate passed the final check";
  }
  return "unknown status";
}

const char* toString(ReplanFallback fallback) {
  switch (fallback) {
    case ReplanFallback::kNone: return "none";
    case ReplanFallback::kKeepReference: return "keep the reference (safe prefix)";
    case ReplanFallback::kStop: return "stop";
  }
  return "?";
}

bool TopoReplanner::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string sub;
  if (!search.validate(&sub)) err << "search: " << sub << "; ";
  if (!optimizer.validate(&sub)) err << "optimizer: " << sub << "; ";
  if (!(std::isfinite(horizon_m) && horizon_m > 0.0)) err << "horizon_m must be positive; ";
  if (!(std::isfinite(horizon_time_s) && horizon_time_s >= 0.0 && horizon_time_s <= 10.0))
    err << "horizon_time_s must be in [0, 10]; ";
  if (!(std::isfinite(reference_clearance_m) && reference_clearance_m >= 0.0)) err << "reference_clearance_m must be >= 0; ";
  if (!(std::isfinite(local_goal_margin_m) && local_goal_margin_m >= 0.0)) err << "local_goal_margin_m must be >= 0; ";
  if (!(std::isfinite(max_local_goal_extension_m) && max_local_goal_extension_m >= 0.0))
    err << "max_local_goal_extension_m must be >= 0; ";
  if (!(reference_sample_s >= 1e-4 && reference_sample_s < 1.0)) err << "reference_sample_s must be in [1e-4, 1); ";
  if (!(control_point_spacing_m > 0.0)) err << "control_point_spacing_m must be positive; ";
  if (!(guide_timing_ratio >= 1.0) || !std::isfinite(guide_timing_ratio)) err << "guide_timing_ratio must be >= 1; ";
  if (!(max_start_velocity_step_mps >= 0.0)) err << "max_start_velocity_step_mps must be >= 0; ";
  if (!(min_start_clearance_m >= 0.0)) err << "min_start_clearance_m must be >= 0; ";
  if (!(max_search_start_offset_m >= 0.0 && max_search_start_offset_m <= 5.0))
    err << "max_search_start_offset_m must be in [0, 5]; ";
  if (!(std::isfinite(astar.search_margin_m) && astar.search_margin_m >= 0.0)) err << "astar: search_margin_m must be >= 0; ";
  if (!(std::isfinite(astar.heuristic_weight) && astar.heuristic_weight >= 1.0)) err << "astar: heuristic_weight must be >= 1; ";
  if (astar.margin_doublings < 0 || astar.margin_doublings > 6) err << "astar: margin_doublings must be in [0, 6]; ";
  if (num_threads < 1 || num_threads > 64) err << "num_threads must be in [1, 64]; ";
  if (!(std::isfinite(duration_weight) && duration_weight >= 0.0)) err << "duration_weight must be >= 0; ";
  if (!(max_selection_delay_ratio >= 1.0)) err << "max_selection_delay_ratio must be >= 1; ";
  if (!(std::isfinite(cruise_speed_mps) && cruise_speed_mps >= 0.0)) err << "cruise_speed_mps must be >= 0; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

std::unique_ptr<TopoReplanner> TopoReplanner::create(const Config& config, std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid replanner config: " + why;
    return nullptr;
  }
  return std::unique_ptr<TopoReplanner>(new TopoReplanner(config));
}

TopoReplanner::TopoReplanner(const Config& config)
    : config_(config),
      pool_(config.num_threads),
      optimizers_(size_t(config.num_threads), PathGuidedOptimizer([&] {
                    // An initial timed from the vehicle's speed: its guide phase keeps that timing.
                    PathGuidedOptimizer::Config c = config.optimizer;
                    c.guide_follows_initial = c.guide_follows_initial || config.profile_timing;
                    return c;
                  }())),
      raw_optimizers_(size_t(config.num_threads), PathGuidedOptimizer([&] {
                        PathGuidedOptimizer::Config c = optimizers_.front().config();
                        c.precondition = false;
                        return c;
                      }())),
      checker_([&] {
        PathGuidedOptimizer::Config c = config.optimizer;
        c.reallocate_time = false;
        return c;
      }()),
      search_(config.search),
      astar_(config.astar) {}

LocalProblem TopoReplanner::localProblem(const EsdfMap& map, const ReplanRequest& request) const {
  LocalProblem lp;
  auto fail = [&](ReplanStatus status, const std::string& message) {
    lp.status = status;
    lp.message = message;
    return lp;
  };
  if (!request.reference || request.reference->empty() || !request.start.allFinite() ||
      !std::isfinite(request.reference_time_s))
    return fail(ReplanStatus::kInvalidInput, "no reference, or a NaN/inf state or time");
  const PolynomialTrajectory& ref = *request.reference;
  const FlatState& start = request.start;
  const double t0 = std::clamp(request.reference_time_s, 0.0, ref.duration());
  lp.start = start.position;
  lp.start_time_s = t0;

  // Start and goal must satisfy both the optimiser's check (interpolated distance) and the guide
  // search's (voxel-centre distance at its clearance), or the search could not start or end there.
  const VisibilityChecker search_free(map, std::max(config_.search.clearance_m, config_.astar.clearance_m),
                                      config_.search.unknown_is_free);
  const DistanceQuery at_start = map.query(start.position);
  if (at_start.status == QueryStatus::kOutOfMap || at_start.status == QueryStatus::kInvalidInput)
    return fail(ReplanStatus::kInvalidInput, "the start is outside the map");
  if (at_start.distance < std::min(config_.min_start_clearance_m, config_.optimizer.clearance_m))
    return fail(ReplanStatus::kStartInCollision, "the start is closer than min_start_clearance_m to an obstacle");
  lp.search_start = start.position;
  if (!search_free.isFree(start.position)) {
    std::vector<Eigen::Vector3d> walk;
    if (!(config_.max_search_start_offset_m > 0.0) ||
        !ascendDistance(map, start.position, [&](const Eigen::Vector3d& p) { return search_free.isFree(p); },
                        config_.max_search_start_offset_m, &walk))
      return fail(ReplanStatus::kStartInCollision, "the start is inside the search's clearance with no way out of it");
    lp.search_start = walk.back();
  }

  // The reference within the horizon: where does it first collide, where does the horizon end.
  // Out of the height band (the optimiser's, which its check enforces) counts as a collision: a
  // minimum-snap reference overshoots its route over a wall as high as the band, and a local goal
  // there cannot be planned to. A start or a final goal out of the band (a take-off, a landing)
  // allows as much, as the optimiser's check does.
  const double dt = config_.reference_sample_s, T = ref.duration();
  auto bandExcess = [&](double z) { return heightBandExcess(z, config_.optimizer.min_z_m, config_.optimizer.max_z_m); };
  const double band_allowed = std::max(bandExcess(start.position.z()), bandExcess(ref.position(T).z())) + 1e-3;
  // The final goal, at rest, may keep only the optimiser's clearance, as the start may: a goal beside
  // an obstacle, accepted at the FSM's goal clearance, that the growing map (noise, drift) has since
  // shown a few centimetres closer. Within max_search_start_offset_m of it the reference is held to
  // the optimiser's clearance, and the search ends up the distance field from it (below).
  const Eigen::Vector3d final_goal = ref.position(T);
  auto collides = [&](double t) {
    const Eigen::Vector3d p = ref.position(t);
    const DistanceQuery q = map.query(p);
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput ||
        bandExcess(p.z()) > band_allowed)
      return true;
    if (config_.max_search_start_offset_m > 0.0 && (p - final_goal).norm() <= config_.max_search_start_offset_m)
      return q.distance < config_.optimizer.clearance_m;
    return q.distance < config_.reference_clearance_m || !search_free.isFree(p);
  };
  double arc = 0.0, t_h = t0, last_collision_s = -1.0;
  Eigen::Vector3d previous = start.position;
  // At speed, horizon_time_s of flight (a plan that ends moving must end further ahead than the
  // vehicle needs to stop, or one failed replan brakes it: at 4.5 m/s a 7 m plan ended 1.6 s ahead).
  const double horizon = std::max(config_.horizon_m, config_.horizon_time_s * start.velocity.norm());
  const double t_end = std::isnan(request.max_local_goal_time_s) ? T : std::clamp(request.max_local_goal_time_s, t0, T);
  while (t_h < t_end && arc < horizon) {
    const double t_next = std::min(t_end, t_h + dt);
    const Eigen::Vector3d p = ref.position(t_next);
    arc += (p - previous).norm();
    previous = p;
    t_h = t_next;
    if (collides(t_h)) {
      if (lp.collision_time_s < 0.0) lp.collision_time_s = t_h;
      last_collision_s = t_h;
    }
  }
  lp.horizon_end_time_s = t_h;

  // The local goal: the horizon end, moved forward along the reference to the first safe point.
  double t_g = t_h;
  while (t_g < T && collides(t_g)) t_g = std::min(T, t_g + dt);
  if (last_collision_s >= 0.0 && config_.local_goal_margin_m > 0.0) {
    // The goal is the first point from t_g on that ends local_goal_margin_m of collision-free
    // reference (counted from the last collision; looked for up to max_local_goal_extension_m past
    // t_g, past further collisions too); the final goal, at rest, always qualifies. A goal right
    // before the next obstacle would end the spline heading into it: its last control points,
    // fixed by the goal's state, lie on the reference.
    double run = 0.0, extension = 0.0, t = last_collision_s;
    bool found = false;
    for (Eigen::Vector3d prev = ref.position(t); t < T;) {
      const double t_next = std::min(T, t + dt);
      const Eigen::Vector3d p = ref.position(t_next);
      const double step = (p - prev).norm();
      prev = p;
      run = collides(t_next) ? 0.0 : run + step;
      if (t_next > t_g) extension += step;
      t = t_next;
      if (t >= t_g && run >= config_.local_goal_margin_m) {
        found = true;
        break;
      }
      if (extension > config_.max_local_goal_extension_m) break;
    }
    if (found || (t >= T && !collides(T))) {
      t_g = t;
    } else {
      // None within reach: at least local_goal_margin_m of collision-free reference between the
      // last collision and the goal (extending stops at the next collision or the end).
      double free_arc = 0.0;
      for (double s = last_collision_s; s < t_g; s += dt)
        free_arc += (ref.position(std::min(s + dt, t_g)) - ref.position(s)).norm();
      if (collides(t_h)) free_arc = 0.0;  // t_g is then the first free point after the collision
      while (t_g < T && free_arc < config_.local_goal_margin_m) {
        const double t_next = std::min(T, t_g + dt);
        if (collides(t_next)) break;
        free_arc += (ref.position(t_next) - ref.position(t_g)).norm();
        t_g = t_next;
      }
    }
  }
  lp.goal_time_s = t_g;
  lp.goal = ref.position(t_g);
  if (map.query(lp.goal).status == QueryStatus::kOutOfMap)
    return fail(ReplanStatus::kGoalOutOfMap, "the local goal is outside the map");
  if (collides(t_g)) return fail(ReplanStatus::kGoalInCollision, "the reference is in collision up to its end");
  lp.search_goal = lp.goal;
  if (!search_free.isFree(lp.goal)) {  // the final goal, inside the search's clearance (above)
    std::vector<Eigen::Vector3d> walk;
    if (!ascendDistance(map, lp.goal, [&](const Eigen::Vector3d& p) { return search_free.isFree(p); },
                        config_.max_search_start_offset_m, &walk))
      return fail(ReplanStatus::kGoalInCollision, "the goal is inside the search's clearance with no way out of it");
    lp.search_goal = walk.back();
  }

  // The initial trajectory: the reference segment from the start to the local goal as a B-spline,
  // about one control point per control_point_spacing_m. A start off the reference (after a detour)
  // lengthens the way to the goal: its time grows with it, at the segment's own mean speed (flown
  // in the reference's time, a start 2 m aside asked 4.6 m/s of a 2.25 m/s reference, and the
  // refine pulled the curve through a wall to make up for it).
  double seg_arc = 0.0, ref_arc = 0.0;
  Eigen::Vector3d prev = start.position, prev_ref = ref.position(t0);
  for (double t = t0; t < t_g; t += dt) {
    const Eigen::Vector3d p = ref.position(std::min(t + dt, t_g));
    seg_arc += (p - prev).norm();
    ref_arc += (p - prev_ref).norm();
    prev = prev_ref = p;
  }
  // The fit is a dense least-squares system over the control points: a local segment of more than
  // kMaxInitialSegments control point spacings is no local problem but a reference that moves
  // absurdly fast (found by the plan_problem fuzzer: 1e5 points, a minute in the fit).
  const double wanted = std::ceil(seg_arc / config_.control_point_spacing_m);
  if (!(wanted <= kMaxInitialSegments)) {
    char text[160];
    std::snprintf(text, sizeof(text), "the local segment is %.3g m long (more than %d control points): the reference moves too fast",
                  seg_arc, kMaxInitialSegments);
    return fail(ReplanStatus::kInvalidInput, text);
  }
  const int segments = std::max(4, int(wanted));
  Eigen::Vector3d goal_velocity = ref.velocity(t_g), goal_acceleration = ref.acceleration(t_g);
  if (config_.profile_timing) {
    if (!profileTimedSegment(ref, start, t0, t_g, segments, &goal_velocity, &goal_acceleration, &lp.initial))
      return fail(ReplanStatus::kInvalidInput, "the reference segment could not be timed and fitted");
  } else {
    const double ref_step = (t_g - t0) / segments;
    const double interval = ref_step * (ref_arc > 1e-3 ? std::max(1.0, seg_arc / ref_arc) : 1.0);
    if (!(interval > 1e-4)) return fail(ReplanStatus::kInvalidInput, "the local segment is too short to replan");
    std::vector<Eigen::Vector3d> points{start.position};
    for (int k = 1; k <= segments; ++k) points.push_back(ref.position(t0 + k * ref_step));
    if (!UniformBspline::fitToPoints(points, interval, start.velocity, start.acceleration, goal_velocity,
                                     goal_acceleration, 3, &lp.initial))
      return fail(ReplanStatus::kInvalidInput, "the reference segment could not be fitted");
  }
  lp.initial_length_m = seg_arc;
  lp.goal_velocity = goal_velocity;
  lp.goal_acceleration = goal_acceleration;
  lp.status = ReplanStatus::kSuccess;
  return lp;
}

bool TopoReplanner::profileTimedSegment(const PolynomialTrajectory& ref, const FlatState& start, double t0, double t_g,
                                        int segments, Eigen::Vector3d* goal_velocity,
                                        Eigen::Vector3d* goal_acceleration, UniformBspline* out) const {
  // The segment's path, as the reference's timing gives it (the start, then the reference's points
  // from t0 to t_g), and at each point the reference's own speed as a cap: where the reference
  // slows (a corner, the goal) the segment slows too. The speed along it is the fastest within
  // those caps from the start's speed at the acceleration limit (a forward-backward pass over
  // arc length), so a vehicle slower than the reference is not asked to be where the reference is.
  struct Point {
    Eigen::Vector3d p;
    double s, cap;
  };
  // From the start along its velocity into the reference a little ahead (a cubic Hermite blend): the
  // start may lie off the reference (after a detour), and a first leg straight to the reference's
  // next point jumped sideways, which the fit made a spike of the speed (4.6 m/s at 0.2 s from
  // 1.6 m/s) and the refine a kink that only a stretch of the whole plan could fly.
  const double dt = config_.reference_sample_s;
  std::vector<double> ref_t;
  std::vector<Eigen::Vector3d> ref_p;
  for (double t = t0;; t = std::min(t_g, t + dt)) {
    const Eigen::Vector3d p = ref.position(t);
    if (ref_p.empty() || (p - ref_p.back()).norm() >= 0.02 || t >= t_g) ref_p.push_back(p), ref_t.push_back(t);
    if (t >= t_g) break;
  }
  const double speed0 = start.velocity.norm();
  const double join_m = std::clamp(0.5 + 0.5 * speed0, 1.0, 3.0);
  const double a = config_.optimizer.max_acc_mps2 * config_.optimizer.feasibility_margin;
  // The cap at the reference's time t: its own speed where it keeps or loses speed (a corner, the
  // goal); where it gains speed, what the curvature allows at the acceleration limit (|v x a| / |v|^3
  // of the reference): its gain is its own start from rest, and a vehicle already faster (a replan
  // after a stop, a mission started from a hover earlier) was held to it.
  auto capAt = [&](double t) -> double {
    const Eigen::Vector3d v = ref.velocity(t), acc = ref.acceleration(t);
    const double speed = v.norm();
    if (!(speed > 1e-6) || acc.dot(v) / speed <= 0.1) return speed;
    if (speed < 0.3) return INFINITY;  // from rest: the forward pass from the start's speed limits it
    const double kappa = v.cross(acc).norm() / (speed * speed * speed);
    return std::max(speed, kappa > 1e-9 ? std::sqrt(a / kappa) : INFINITY);
  };
  size_t j = 0;
  while (j + 1 < ref_p.size() && (ref_p[j] - start.position).norm() < join_m) ++j;
  std::vector<Point> path{{start.position, 0.0, INFINITY}};
  const Eigen::Vector3d to_join = ref_p[j] - start.position;
  const double L = to_join.norm();
  const double join_cap = capAt(ref_t[j]);
  if (L > 1e-3) {
    const Eigen::Vector3d m0 = (speed0 > 0.1 ? Eigen::Vector3d(start.velocity / speed0) : Eigen::Vector3d(to_join / L)) * L;
    const Eigen::Vector3d ref_dir = ref.velocity(ref_t[j]);
    const Eigen::Vector3d m1 = (ref_dir.norm() > 1e-6 ? Eigen::Vector3d(ref_dir.normalized()) : Eigen::Vector3d(to_join / L)) * L;
    const int k_max = std::max(2, int(std::ceil(L / 0.05)));
    for (int k = 1; k <= k_max; ++k) {
      const double u = double(k) / k_max, u2 = u * u, u3 = u2 * u;
      const Eigen::Vector3d p = (2 * u3 - 3 * u2 + 1) * start.position + (u3 - 2 * u2 + u) * m0 +
                                (-2 * u3 + 3 * u2) * ref_p[j] + (u3 - u2) * m1;
      path.push_back({p, path.back().s + (p - path.back().p).norm(), join_cap});
    }
  }
  for (size_t k = j + 1; k < ref_p.size(); ++k)
    path.push_back({ref_p[k], path.back().s + (ref_p[k] - path.back().p).norm(), capAt(ref_t[k])});
  const size_t n = path.size();
  if (n < 2 || !(path.back().s > 1e-6)) return false;
  const double vmax = cruiseSpeed();
  std::vector<double> v(n);
  v[n - 1] = std::min(vmax, path[n - 1].cap);
  for (size_t i = n - 1; i-- > 0;)
    v[i] = std::min({vmax, path[i].cap, std::sqrt(v[i + 1] * v[i + 1] + 2.0 * a * (path[i + 1].s - path[i].s))});
  v[0] = std::min(vmax, start.velocity.norm());
  for (size_t i = 1; i < n; ++i)
    v[i] = std::min(v[i], std::sqrt(v[i - 1] * v[i - 1] + 2.0 * a * (path[i].s - path[i - 1].s)));
  std::vector<double> time(n, 0.0);
  for (size_t i = 1; i < n; ++i)
    time[i] = time[i - 1] + 2.0 * (path[i].s - path[i - 1].s) / std::max(v[i] + v[i - 1], 0.1);
  const double duration = time.back();
  if (!(duration > 1e-3)) return false;
  // Positions at equal times.
  const double interval = duration / segments;
  std::vector<Eigen::Vector3d> points{start.position};
  size_t i = 1;
  for (int k = 1; k <= segments; ++k) {
    const double t = std::min(duration, k * interval);
    while (i + 1 < n && time[i] < t) ++i;
    const double span = time[i] - time[i - 1];
    const double f = span > 0.0 ? std::clamp((t - time[i - 1]) / span, 0.0, 1.0) : 1.0;
    points.push_back(path[i - 1].p + f * (path[i].p - path[i - 1].p));
  }
  points.back() = path.back().p;
  // Arriving at the pass's speed along the reference: no faster than the pass allows from this start,
  // and faster than the reference where it still gains speed from its own start and the vehicle is
  // ahead of it.
  const Eigen::Vector3d ref_velocity = ref.velocity(t_g);
  if (ref_velocity.norm() > 1e-6 && std::abs(v[n - 1] - ref_velocity.norm()) > 1e-3) {
    *goal_velocity = ref_velocity * (v[n - 1] / ref_velocity.norm());
    goal_acceleration->setZero();
  } else {
    *goal_velocity = ref_velocity;
    *goal_acceleration = ref.acceleration(t_g);
  }
  return UniformBspline::fitToPoints(points, interval, start.velocity, start.acceleration, *goal_velocity,
                                     *goal_acceleration, 3, out);
}

std::optional<UniformBspline> TopoReplanner::initialAlong(const LocalProblem& lp, const Path& guide) const {
  // A guide much longer than the reference segment (a detour round a wall, a window far aside) gets
  // its own initial spline: along the guide, with as many control points and as much time as its
  // length asks at the segment's mean speed. Optimised from the segment's timing instead, the
  // detour cannot be flown in the time given, and the feasibility cost pulls it through the
  // obstacle (every candidate failed in collision before, e.g. a goal 0.6 m behind a 3 m wall).
  double length = 0.0;
  for (size_t i = 1; i < guide.size(); ++i) length += (guide[i] - guide[i - 1]).norm();
  if (guide.size() < 2 || !(lp.initial_length_m > 0.0) || length <= config_.guide_timing_ratio * lp.initial_length_m)
    return std::nullopt;
  const double duration = lp.initial.duration() * length / lp.initial_length_m;
  const int segments = std::max(4, int(std::ceil(length / config_.control_point_spacing_m)));
  const double interval = duration / segments;
  std::vector<double> arc{0.0};
  for (size_t i = 1; i < guide.size(); ++i) arc.push_back(arc.back() + (guide[i] - guide[i - 1]).norm());
  // Arc length over time: a cubic from the start's speed to the local goal's (Hermite), so the fit
  // meets its boundary velocities without a spurt of acceleration; clamped monotone.
  const UniformBspline vel = lp.initial.derivative();
  const double v0 = vel.evaluate(0.0).norm(), v1 = lp.goal_velocity.norm();
  auto arcAt = [&](double u) {  // u in [0, 1]
    const double h10 = u * u * u - 2.0 * u * u + u, h01 = -2.0 * u * u * u + 3.0 * u * u, h11 = u * u * u - u * u;
    return h10 * duration * v0 + h01 * length + h11 * duration * v1;
  };
  std::vector<Eigen::Vector3d> points{lp.start};
  size_t seg = 1;
  double s_prev = 0.0;
  for (int k = 1; k <= segments; ++k) {
    const double s = std::clamp(std::max(s_prev, arcAt(double(k) / segments)), 0.0, length);
    s_prev = s;
    while (seg + 1 < guide.size() && arc[seg] < s) ++seg;
    const double span = arc[seg] - arc[seg - 1];
    const double f = span > 0.0 ? std::clamp((s - arc[seg - 1]) / span, 0.0, 1.0) : 1.0;
    points.push_back(guide[seg - 1] + f * (guide[seg] - guide[seg - 1]));
  }
  points.back() = lp.goal;
  UniformBspline out;
  if (!UniformBspline::fitToPoints(points, interval, vel.evaluate(0.0), vel.derivative().evaluate(0.0), lp.goal_velocity,
                                   lp.goal_acceleration, 3, &out))
    return std::nullopt;
  return out;
}

ReplanResult TopoReplanner::replan(const EsdfMap& map, const ReplanRequest& request) {
  const auto t_begin = std::chrono::steady_clock::now();
  ReplanResult result;
  const LocalProblem lp = localProblem(map, request);
  result.local_start_time_s = lp.start_time_s;
  result.local_goal_time_s = lp.goal_time_s;
  result.reference_collision_time_s = lp.collision_time_s;
  result.stats.check_ms = msSince(t_begin);
  auto fail = [&](ReplanStatus status, const std::string& message) {
    result.status = status;
    result.message = message;
    // Every failure names a fallback: keep the reference while it is free for a while, else stop.
    result.fallback = ReplanFallback::kStop;
    if (status != ReplanStatus::kInvalidInput && status != ReplanStatus::kStartInCollision) {
      const double free_until = lp.collision_time_s >= 0.0 ? lp.collision_time_s : lp.horizon_end_time_s;
      result.safe_prefix_s = std::max(0.0, free_until - lp.start_time_s);
      if (result.safe_prefix_s > 0.5) result.fallback = ReplanFallback::kKeepReference;
    }
    result.stats.total_ms = msSince(t_begin);
    return result;
  };
  if (lp.status != ReplanStatus::kSuccess) return fail(lp.status, lp.message);

  // A free reference within the horizon is kept (as a verified spline), without searching.
  if (lp.collision_time_s < 0.0) {
    // Without time reallocation: a reference segment that breaks the limits as fitted is optimised
    // like a colliding one rather than stretched (which would change the start velocity).
    const OptimizationResult checked = checker_.check(lp.initial, map);
    if (checked.status == OptimizationStatus::kSuccess) {
      result.status = ReplanStatus::kSuccess;
      result.trajectory = checked.spline;
      result.stats.start_repaired = repairStart(request.start, map, 1.0, &result.trajectory, nullptr);
      result.stats.start_velocity_jump_mps =
          (result.trajectory.derivative().evaluate(0.0) - request.start.velocity).norm();
      result.stats.total_ms = msSince(t_begin);
      return result;
    }
  }

  // Guide paths: the topological search.
  result.stats.searched = true;
  auto t_search = std::chrono::steady_clock::now();
  // Guides from a moved search start begin at the start itself; to a moved search goal, they end at
  // the goal itself.
  auto fromStart = [&](std::vector<Path> paths) {
    for (Path& path : paths) {
      if (lp.search_start != lp.start) path.insert(path.begin(), lp.start);
      if (lp.search_goal != lp.goal) path.push_back(lp.goal);
    }
    return paths;
  };
  const TopoSearchResult search = search_.search(map, lp.search_start, lp.search_goal, request.attempt);
  result.stats.search = search.stats;
  result.roadmap = search.roadmap;
  result.stats.search_ms = msSince(t_search);

  // One path-guided optimisation per guide, in parallel; each worker has its own optimiser.
  auto optimizeAll = [&](const std::vector<Path>& guides, bool raw) {
    std::vector<PathGuidedOptimizer>& optimizers = raw ? raw_optimizers_ : optimizers_;
    auto t_opt = std::chrono::steady_clock::now();
    const size_t first = result.candidates.size();
    result.candidates.resize(first + guides.size());
    pool_.parallelFor(int(guides.size()), [&](int i, int worker) {
      ReplanCandidate& c = result.candidates[first + size_t(i)];
      c.guide = guides[size_t(i)];
      c.result = optimizers[size_t(worker)].optimize(lp.initial, c.guide, map);
      // A guide much longer than the segment that failed from the segment's timing: once more from
      // an initial spline along the guide, timed for its length (the fast path is unchanged).
      if (c.result.status != OptimizationStatus::kSuccess)
        if (const std::optional<UniformBspline> along = initialAlong(lp, c.guide)) {
          c.retried_along = true;
          c.first_status = c.result.status;
          c.first_min_clearance_m = c.result.stats.min_clearance_m;
          OptimizationResult second = optimizers[size_t(worker)].optimize(*along, c.guide, map);
          // The better attempt is kept (and reported): the one that passed, else the clearer one.
          if (second.status == OptimizationStatus::kSuccess ||
              (second.status == c.result.status && second.stats.min_clearance_m > c.result.stats.min_clearance_m))
            c.result = std::move(second);
        }
      if (c.result.status == OptimizationStatus::kSuccess) {
        c.selection_cost = c.result.cost.jerk_integral_m2ps5 + config_.duration_weight * c.result.cost.duration_s;
        // Time reallocation scaled the start velocity: restore it here, per candidate, so the choice
        // can prefer a candidate that joins the current trajectory without a velocity step.
        c.start_repaired =
            repairStart(request.start, map, c.result.stats.time_ratio, &c.result.spline, &c.repair_note);
        c.start_velocity_step_mps = (c.result.spline.derivative().evaluate(0.0) - request.start.velocity).norm();
      }
    });
    result.stats.optimize_ms += msSince(t_opt);
    result.stats.paths += int(guides.size());
    for (size_t i = first; i < result.candidates.size(); ++i)
      if (std::isfinite(result.candidates[i].selection_cost)) ++result.stats.feasible_candidates;
    result.chosen = selectCandidate(result.candidates, config_.max_start_velocity_step_mps,
                                    config_.max_selection_delay_ratio);
  };
  if (search.status == SearchStatus::kSuccess) optimizeAll(fromStart(search.paths), false);

  // Last resort, when the search found nothing or no candidate passed: one A* guide.
  if (result.chosen < 0) {
    t_search = std::chrono::steady_clock::now();
    const GridAStar::Result astar = astar_.search(map, lp.search_start, lp.search_goal);
    result.stats.search_ms += msSince(t_search);
    if (astar.status == SearchStatus::kSuccess) {
      const VisibilityChecker checker(map, config_.astar.clearance_m, config_.astar.unknown_is_free);
      result.stats.used_astar = true;
      optimizeAll(fromStart({PathShortener(checker).shorten(astar.path)}), false);
    } else if (result.candidates.empty()) {
      return fail(ReplanStatus::kNoPath, std::string("no guide path: ") + toString(search.status) + ", A*: " +
                                             toString(astar.status));
    }
  }
  // Then every guide once more, refined in the control points' own coordinates.
  if (result.chosen < 0 && config_.raw_refine_fallback && config_.optimizer.precondition &&
      !result.candidates.empty()) {
    std::vector<Path> guides;
    for (const ReplanCandidate& c : result.candidates) guides.push_back(c.guide);
    result.stats.used_raw_refine = true;
    optimizeAll(guides, true);
  }
  if (result.chosen < 0) {
    // Why each candidate failed, for the logs: "2 x in collision (min clearance 0.21 m), 1 x infeasible".
    std::ostringstream why;
    why << "no candidate is collision-free and feasible:";
    for (int st = 0; st <= int(OptimizationStatus::kInvalidInput); ++st) {
      int count = 0;
      double best_clearance = -INFINITY, best_ratio = INFINITY;
      const ReplanCandidate* best = nullptr;
      for (const ReplanCandidate& c : result.candidates)
        if (int(c.result.status) == st) {
          ++count;
          if (c.result.stats.min_clearance_m > best_clearance) best = &c;
          best_clearance = std::max(best_clearance, c.result.stats.min_clearance_m);
          best_ratio = std::min(best_ratio, c.result.stats.time_ratio);
        }
      if (count == 0) continue;
      why << " " << count << " x " << toString(OptimizationStatus(st));
      if (OptimizationStatus(st) == OptimizationStatus::kInCollision && best) {
        // Where: the closest point of the best candidate, and how far along it (for the logs).
        const double t_min = best->result.stats.min_clearance_t_s;
        const Eigen::Vector3d p = best->result.spline.evaluate(t_min);
        why << " (best min clearance " << std::fixed << std::setprecision(2) << best_clearance << " m at ("
            << p.x() << ", " << p.y() << ", " << p.z() << "), " << t_min << " of " << best->result.spline.duration()
            << " s)";
      }
      if (OptimizationStatus(st) == OptimizationStatus::kInfeasible)
        why << " (least time ratio " << std::fixed << std::setprecision(2) << best_ratio << ")";
      why << ";";
    }
    const long retried = std::count_if(result.candidates.begin(), result.candidates.end(),
                                       [](const ReplanCandidate& c) { return c.retried_along; });
    if (retried > 0) why << " " << retried << " of them tried again along the guide;";
    std::string message = why.str();
    message.pop_back();
    char ends[160];
    std::snprintf(ends, sizeof(ends), "; from (%.2f, %.2f, %.2f) to the local goal (%.2f, %.2f, %.2f)%s", lp.start.x(),
                  lp.start.y(), lp.start.z(), lp.goal.x(), lp.goal.y(), lp.goal.z(),
                  result.stats.used_astar ? ", A* guide tried" : "");
    if (result.stats.used_raw_refine) message += ", refined again in raw coordinates";
    message += ends;
    return fail(ReplanStatus::kOptimizationFailed, message);
  }
  result.status = ReplanStatus::kSuccess;
  result.trajectory = result.candidates[size_t(result.chosen)].result.spline;
  if (result.candidates[size_t(result.chosen)].start_velocity_step_mps > config_.max_start_velocity_step_mps)
    result.message = "start velocity not restored: " + result.candidates[size_t(result.chosen)].repair_note;
  result.stats.start_repaired = result.candidates[size_t(result.chosen)].start_repaired;
  result.stats.start_velocity_jump_mps = (result.trajectory.derivative().evaluate(0.0) - request.start.velocity).norm();
  result.stats.total_ms = msSince(t_begin);
  return result;
}

int TopoReplanner::selectCandidate(const std::vector<ReplanCandidate>& candidates, double max_start_velocity_step_mps,
                                   double max_selection_delay_ratio) {
  // Those that keep the start velocity (within max_start_velocity_step_mps) first; among all only
  // when none does.
  auto joins = [&](const ReplanCandidate& k) { return k.start_velocity_step_mps <= max_start_velocity_step_mps; };
  bool any_joins = false;
  double fastest = INFINITY;
  for (const ReplanCandidate& k : candidates)
    if (std::isfinite(k.selection_cost)) any_joins = any_joins || joins(k);
  for (const ReplanCandidate& k : candidates)
    if (std::isfinite(k.selection_cost) && (joins(k) || !any_joins)) fastest = std::min(fastest, k.result.spline.duration());
  // The smoothest among those that reach the local goal about as soon as the fastest: a candidate
  // stretched in time has less jerk for its slowness alone (jerk falls with the fifth power of the
  // stretch), and chosen for it, every plan crept round the obstacle it was slowed for.
  int chosen = -1;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const ReplanCandidate& k = candidates[i];
    if (!std::isfinite(k.selection_cost) || (any_joins && !joins(k))) continue;
    if (k.result.spline.duration() > max_selection_delay_ratio * fastest + 1e-9) continue;
    if (chosen < 0 || k.selection_cost < candidates[size_t(chosen)].selection_cost) chosen = int(i);
  }
  return chosen;
}

bool TopoReplanner::repairStart(const FlatState& start, const EsdfMap& map, double time_ratio,
                                UniformBspline* trajectory, std::string* why) const {
  // What each try came to, for the logs: "eased 1.0 s: limits exceeded (v 3.02, a 2.61)".
  std::ostringstream notes;
  notes << std::fixed << std::setprecision(2) << "start |v| " << start.velocity.norm() << ", |a| "
        << start.acceleration.norm() << "; time ratio " << time_ratio;
  const auto note = [&](const char* what, const OptimizationResult& r) {
    notes << "; " << what << ": " << toString(r.status) << " (v " << r.stats.max_vel_mps << ", a "
          << r.stats.max_acc_mps2 << ", clearance " << r.stats.min_clearance_m << ")";
  };
  const auto give_up = [&](const char* what) {
    if (what) notes << "; " << what;
    if (why) *why = notes.str();
    return false;
  };
  const UniformBspline vel = trajectory->derivative();
  const Eigen::Vector3d v0 = vel.evaluate(0.0), a0 = vel.derivative().evaluate(0.0);
  if ((v0 - start.velocity).norm() < 1e-6 && (a0 - start.acceleration).norm() < 1e-6) return false;
  // The same path, with the start's pace from before the stretch, easing into the stretched one.
  if (time_ratio > 1.0)
    for (const double ease_s : {1.0, 0.5, 2.0}) {
      UniformBspline eased;
      if (!trajectory->easeIntoStretch(time_ratio, ease_s, &eased)) continue;
      const UniformBspline eased_vel = eased.derivative();
      // Only a trajectory stretched from this start state: its eased start is that state.
      if ((eased_vel.evaluate(0.0) - start.velocity).norm() > 1e-3 ||
          (eased_vel.derivative().evaluate(0.0) - start.acceleration).norm() > 1e-2) {
        notes << "; eased: not from this start";
        break;
      }
      const OptimizationResult checked = checker_.check(eased, map);
      if (checked.status == OptimizationStatus::kSuccess) {
        *trajectory = eased;
        return true;
      }
      note(ease_s == 1.0 ? "eased 1.0 s" : ease_s == 0.5 ? "eased 0.5 s" : "eased 2.0 s", checked);
    }
  const double dt = trajectory->knotSpan(), duration = trajectory->duration();
  const int segments = trajectory->numSegments();
  std::vector<Eigen::Vector3d> points;
  for (int k = 0; k <= segments; ++k) points.push_back(trajectory->evaluate(std::min(duration, k * dt)));
  points.front() = start.position;
  UniformBspline refit;
  if (!UniformBspline::fitToPoints(points, dt, start.velocity, start.acceleration, vel.evaluate(duration),
                                   vel.derivative().evaluate(duration), trajectory->degree(), &refit))
    return give_up("refit: no fit");
  const OptimizationResult refit_check = checker_.check(refit, map);
  if (refit_check.status != OptimizationStatus::kSuccess) {
    note("refit", refit_check);
    // The refit breaks a limit or grazes an obstacle: refine it once more (its first and last
    // control points, the start and end states, stay fixed), checked without stretching time.
    const OptimizationResult again = checker_.refinePhase(refit, map);
    if (again.status != OptimizationStatus::kSuccess) return give_up("refined: NLopt failed");
    const OptimizationResult checked = checker_.check(again.spline, map);
    if (checked.status != OptimizationStatus::kSuccess) {
      note("refined", checked);
      return give_up(nullptr);
    }
    refit = checked.spline;
  }
  *trajectory = refit;
  return true;
}

}  // namespace topo_planner
