#include "topo_planner/topo_replan/mission.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

namespace topo_planner {

const char* toString(GoalStatus status) {
  switch (status) {
    case GoalStatus::kAccepted: return "kAccepted";
    case GoalStatus::kNoOdometry: return "kNoOdometry";
    case GoalStatus::kInvalidInput: return "kInvalidInput";
    case GoalStatus::kGoalInObstacle: return "kGoalInObstacle";
    case GoalStatus::kGoalOutOfMap: return "kGoalOutOfMap";
    case GoalStatus::kReferenceFailed: return "kReferenceFailed";
    case GoalStatus::kInputsStale: return "kInputsStale";
    case GoalStatus::kUnreachable: return "kUnreachable";
    case GoalStatus::kGivenUp: return "kGivenUp";
  }
  return "unknown";
}

namespace {
// The route search that may leave a narrow passage around the vehicle (a dead-end slot it braked in).
GlobalRouter::Config startRouterConfig(const Mission::Config& config) {
  GlobalRouter::Config c = config.route;
  c.start_radius_m = std::max(c.start_radius_m, config.max_backoff_length_m + 1.0);
  return c;
}
}  // namespace

Mission::Mission(const Config& config)
    : config_(config),
      router_(std::make_unique<GlobalRouter>(config.route)),
      start_router_(std::make_unique<GlobalRouter>(startRouterConfig(config))),
      route_watch_(config.routeWatch()),
      remedies_(config.remedies()) {}

void Mission::setConfig(const Config& config) {
  config_ = config;
  router_ = std::make_unique<GlobalRouter>(config_.route);
  start_router_ = std::make_unique<GlobalRouter>(startRouterConfig(config_));
  route_watch_.setConfig(config_.routeWatch());
  remedies_.setConfig(config_.remedies());
  route_stale_ = true;  // its clearance may have changed: searched again at the next reference
}

// --- Goals ---------------------------------------------------------------------------------------

GoalStatus Mission::check(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map, std::string* why) const {
  for (size_t i = 0; i < goals.size(); ++i) {
    const DistanceQuery q = map.query(goals[i]);
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput) {
      *why = "goal " + std::to_string(i) + " is outside the map";
      return GoalStatus::kGoalOutOfMap;
    }
    if (q.distance < config_.goal_clearance_m) {
      *why = "goal " + std::to_string(i) + " is " + std::to_string(q.distance) + " m from an obstacle";
      return GoalStatus::kGoalInObstacle;
    }
  }
  return GoalStatus::kAccepted;
}

void Mission::give(const std::vector<Eigen::Vector3d>& goals) {
  pending_goals_ = goals;
  goals_pending_ = true;
  new_mission_ = true;
  rerouting_ = false;
  remedies_.goalsGiven();
  invalidateRoute();
}

void Mission::pendRemaining(bool reroute) {
  pending_goals_ = remaining();
  goals_pending_ = !pending_goals_.empty();
  if (reroute) rerouting_ = goals_pending_;
}

void Mission::refusePending(GoalStatus status) {
  goals_pending_ = false;
  status_ = status;
}

std::vector<Eigen::Vector3d> Mission::remaining() const {
  if (next_goal_ >= goals_.size()) return goals_.empty() ? goals_ : std::vector<Eigen::Vector3d>{goals_.back()};
  return std::vector<Eigen::Vector3d>(goals_.begin() + long(next_goal_), goals_.end());
}

void Mission::passWaypoints(const Eigen::Vector3d& position) {
  // The last one ends the mission (atLastGoal, once the trajectory to it has ended).
  while (next_goal_ + 1 < goals_.size() && (position - goals_[next_goal_]).norm() <= config_.waypoint_reached_radius_m)
    ++next_goal_;
}

bool Mission::atLastGoal(const Eigen::Vector3d& position) const {
  return !goals_.empty() && (position - goals_.back()).norm() <= config_.goal_tolerance_m;
}

void Mission::reached() {
  goals_.clear();
  next_goal_ = 0;
  progress_.clear();
}

void Mission::end(GoalStatus status, const EsdfMap& map) {
  status_ = status;
  goals_.clear();
  next_goal_ = 0;
  if (rerouting_) goals_pending_ = false;  // the re-route of this mission; new goals (give) stay pending
  rerouting_ = false;
  route_.clear();
  route_goals_.clear();
  route_watch_.reset(route_, map);
  remedies_.missionEnded();
  progress_.clear();
}

// --- The reference -------------------------------------------------------------------------------

Mission::Started Mission::start(double t, FlatState start, const EsdfMap& map, const ReferenceConfig& limits) {
  goals_pending_ = false;
  const std::vector<Eigen::Vector3d> goals = pending_goals_;
  const bool rerouted = std::exchange(rerouting_, false);
  Started started;
  auto refuse = [&](GoalStatus status, const std::string& why) {
    status_ = status;
    new_mission_ = false;
    started.summary = std::string(toString(status)) + ": " + why;
    return started;
  };
  if (goals.empty()) return refuse(GoalStatus::kInvalidInput, "no goals");
  std::string why;
  const GoalStatus on_map = check(goals, map, &why);
  if (on_map != GoalStatus::kAccepted) return refuse(on_map, why);
  started.goals_valid = true;
  start.jerk.setZero();  // the reference's jerk at the start is free of the spline's knots
  std::vector<Eigen::Vector3d> waypoints{start.position};
  // Through the global route when there is one for these goals (its first point is where the
  // vehicle was when it was searched; the reference starts from where it takes over).
  const bool routed = config_.global_route && route_.size() >= 2 && route_goals_ == goals;
  if (routed) {
    for (size_t i = 1; i < route_.size(); ++i)
      if ((route_[i] - waypoints.back()).norm() > 1e-3) waypoints.push_back(route_[i]);
  } else {
    for (const Eigen::Vector3d& g : goals)
      if ((g - waypoints.back()).norm() > 1e-3) waypoints.push_back(g);
  }
  if (waypoints.size() < 2) waypoints.push_back(goals.back() + Eigen::Vector3d(1e-3, 0, 0));
  // Moving across or away from the first leg (a re-route at speed): from the velocity along it only
  // (the plans start from the vehicle's state; the profile timing is not held to the reference's ramp).
  start = referenceStartState(start, waypoints[1] - waypoints[0]);
  PolynomialTrajectory ref;
  const TrajectoryStatus status =
      referenceTrajectory(waypoints, start, FlatState::atRest(waypoints.back()), limits, &ref);
  if (status != TrajectoryStatus::kSuccess)
    return refuse(GoalStatus::kReferenceFailed, std::string("minimum-snap reference: ") + toString(status));
  goals_ = goals;
  next_goal_ = 0;
  const bool new_mission = std::exchange(new_mission_, false);
  if (new_mission) {
    remedies_.newMission(t, ref.duration());
    MissionProgress::Config progress;
    progress.min_gain_m = config_.progress_min_gain_m;
    progress_ = MissionProgress(progress);
    // The places stalled at stay weighed by later missions (a return leg through them), the oldest
    // dropped beyond kMaxStallZones.
  }
  // The distance left is measured along the way the reference takes; a rebuilt one re-bases it.
  progress_.reset(waypoints, t, start.position, !new_mission);
  remedies_.referenceStarted(progress_.lastGain());
  progress_tick_s_ = t;
  reference_ = std::move(ref);
  status_ = GoalStatus::kAccepted;
  started.ok = true;
  started.summary = std::string(rerouted ? "re-routed" : "new") + " reference, " + std::to_string(goals.size()) +
                    " goal(s)" + (routed ? ", along the global route" : "");
  return started;
}

double Mission::localGoalLimit(double from_s) const {
  if (next_goal_ + 1 >= goals_.size() || reference_.empty()) return NAN;
  return waypointPassTime(reference_, goals_[next_goal_], from_s, config_.waypoint_reached_radius_m);
}

// --- The global route ----------------------------------------------------------------------------

std::optional<Mission::RouteSearch> Mission::prepareRouteSearch(const EsdfMap& map) {
  RouteSearch search;
  search.goals = goals_pending_ ? pending_goals_ : remaining();
  if (search.goals.empty() || (!route_stale_ && search.goals == route_goals_)) return std::nullopt;
  for (const Eigen::Vector3d& g : search.goals)
    if (!g.allFinite()) return std::nullopt;  // refused by start()
  // New goals start() will refuse: no search, and the route of the mission flown stays (one
  // searched for them replaced it, or cleared it when the goal's clearance failed the search, and
  // the mission went on without).
  std::string refused;
  if (goals_pending_ && !rerouting_ && check(search.goals, map, &refused) != GoalStatus::kAccepted) return std::nullopt;
  search.epoch = route_epoch_;
  search.rerouting = rerouting_;
  // The places this mission stalled at weigh against a way through them.
  router_->setAvoided(stall_zones_);
  start_router_->setAvoided(stall_zones_);
  return search;
}

Mission::RouteFound Mission::searchRoute(const EsdfMap& map, const RouteSearch& search) const {
  RouteFound found;
  found.route = {search.start};
  for (size_t i = 0; i < search.goals.size() && found.status == SearchStatus::kSuccess; ++i) {
    GlobalRouter::Result leg = router_->route(map, found.route.back(), search.goals[i]);
    found.expansions += leg.expansions;
    if (leg.status == SearchStatus::kNoPath && i == 0) {
      // Not yet a proof: the vehicle may hover in a passage narrower than the route's clearance (a
      // dead-end slot it braked in) that the small relaxed start region does not leave.
      leg = start_router_->route(map, found.route.back(), search.goals[i]);
      found.expansions += leg.expansions;
      found.near_start = leg.status == SearchStatus::kSuccess;
    }
    found.status = leg.status;
    found.failed_leg = i;
    if (found.status == SearchStatus::kSuccess)
      found.route.insert(found.route.end(), leg.path.begin() + 1, leg.path.end());
  }
  return found;
}

Mission::RouteOutcome Mission::applyRoute(const RouteSearch& search, RouteFound found, const EsdfMap& map,
                                          std::string* text) {
  // New goals, a stop or an odometry jump meanwhile: the search answered another question.
  if (route_epoch_ != search.epoch) return RouteOutcome::kOvertaken;
  route_stale_ = false;
  route_goals_ = search.goals;
  remedies_.routeSearched();
  char line[240];
  if (found.status == SearchStatus::kSuccess) {
    route_ = std::move(found.route);
    route_watch_.reset(route_, map);
    std::snprintf(line, sizeof(line), "global route: %.1f m through %zu points (%d expansions)%s", pathLength(route_),
                  route_.size(), found.expansions,
                  found.near_start ? ", narrower than its clearance near the vehicle" : "");
    *text = line;
    return RouteOutcome::kFound;
  }
  if (found.status == SearchStatus::kNoPath && config_.route.unknown_is_free) {
    // Both searches exhausted the map window: with unknown space free, no way to this goal exists.
    const size_t i = found.failed_leg;
    std::snprintf(line, sizeof(line),
                  "goal %zu (%.2f, %.2f, %.2f) is unreachable in the known map: no route keeps %.2f m from obstacles "
                  "(except within %.1f m of the vehicle) within the height band [%.2f, %.2f] m",
                  i, search.goals[i].x(), search.goals[i].y(), search.goals[i].z(), config_.route.clearance_m,
                  start_router_->config().start_radius_m, std::max(config_.route.min_z_m, map.geometry().windowMin().z()),
                  std::min(config_.route.max_z_m, map.geometry().windowMax().z()));
    *text = line;
    if (goals_pending_ && !search.rerouting) {
      // New goals: refused like a goal in an obstacle (a mission in progress goes on).
      goals_pending_ = false;
      new_mission_ = false;
      status_ = GoalStatus::kUnreachable;
      *text = std::string("goal refused: ") + toString(GoalStatus::kUnreachable) + ": " + line;
      return RouteOutcome::kRefused;
    }
    return RouteOutcome::kUnreachable;
  }
  // No proof either way (budget, start or goal inside the route's end clearance, or unknown space
  // not free to the route): straight references.
  route_.clear();
  route_watch_.reset(route_, map);
  std::snprintf(line, sizeof(line), "no global route (%s at goal %zu): references go straight through the goals",
                toString(found.status), found.failed_leg);
  *text = line;
  return RouteOutcome::kNone;
}

void Mission::invalidateRoute() {
  route_stale_ = true;
  ++route_epoch_;
}

bool Mission::routeCheckDue(double t) const {
  return config_.global_route && config_.route_check_length_m > 0.0 && !route_watch_.empty() && !goals_.empty() &&
         route_goals_ == remaining() && t - route_checked_s_ >= config_.route_check_interval_s;
}

bool Mission::routeBlocked(double t, const Eigen::Vector3d& position, const EsdfMap& map, std::string* text) {
  if (!routeCheckDue(t)) return false;
  route_checked_s_ = t;
  const std::optional<RouteWatch::Blocked> blocked = route_watch_.check(position, map);
  if (!blocked) return false;
  char line[200];
  std::snprintf(line, sizeof(line),
                "the route is blocked %.1f m ahead at (%.2f, %.2f, %.2f) (%.2f m from a known obstacle): re-routing",
                blocked->ahead_m, blocked->where.x(), blocked->where.y(), blocked->where.z(), blocked->distance_m);
  *text = reroute_reason_ = line;
  route_stale_ = true;
  pendRemaining(true);
  return true;
}

std::string Mission::takeRerouteReason() { return std::exchange(reroute_reason_, std::string()); }

// --- Progress and stalls -------------------------------------------------------------------------

Mission::Stall Mission::checkProgress(double t, const Eigen::Vector3d& position, bool stopped, bool manoeuvring) {
  Stall stall;
  if (!checksProgress()) return stall;
  progress_.update(t, position);
  progress_tick_s_ = t;
  remedies_.progressMeasured(progress_.lastGain());  // progress: the remedies start over
  if (remedies_.backoffNowStopped(stopped)) {
    stall.kind = Stall::Kind::kBackOffNow;
    return stall;
  }
  const double since = progress_.sinceGain(t);
  bool forced = false;
  const MissionRemedies::Stall verdict = remedies_.stall(since, manoeuvring, goals_pending_, &forced);
  char text[220];
  if (verdict == MissionRemedies::Stall::kNone) return stall;
  if (verdict == MissionRemedies::Stall::kGiveUp) {
    std::snprintf(text, sizeof(text),
                  "no progress towards the goal for the mission's time limit of %.0f s (%.1f m left, %.1f m when it "
                  "last gained)", remedies_.missionLimit(), progress_.remaining(), progress_.best());
    stall.kind = Stall::Kind::kGiveUp;
    stall.why = text;
    return stall;
  }
  if (forced) {
    std::snprintf(text, sizeof(text), "%d plans failed at rest, no back-off left (%.1f m left)",
                  config_.max_plan_failures, progress_.remaining());
  } else {
    std::snprintf(text, sizeof(text), "no progress towards the goal for %.0f s (%.1f m left, %.1f m when it last gained)",
                  since, progress_.remaining(), progress_.best());
  }
  // A stall (counted): the next remedy. Every one marks the place for the route searches to avoid.
  // The zone lies ahead along the way, where the vehicle was heading (one around the vehicle alone
  // weighs on every way out of it alike).
  addStallZone(progress_.ahead(config_.stall_zone_radius_m));
  route_stale_ = true;
  stall.kind = Stall::Kind::kRemedy;
  stall.why = text;
  stall.backs_off = remedies_.stallBacksOff();
  return stall;
}

bool Mission::checksProgress() const {
  return config_.global_route && config_.progress_timeout_s > 0.0 && progress_.active() && !goals_.empty();
}

void Mission::stalledAtHold() {
  // The zone lies ahead along the way (where the progress is tracked), else around the hold.
  const bool tracked = config_.progress_timeout_s > 0.0 && progress_.active();
  addStallZone(tracked ? progress_.ahead(config_.stall_zone_radius_m) : remedies_.lookHoldPosition());
  route_stale_ = true;
}

void Mission::addStallZone(const Eigen::Vector3d& center) {
  if (!(config_.stall_zone_radius_m > 0.0)) return;
  stall_zones_.push_back({center, config_.stall_zone_radius_m});
  if (stall_zones_.size() > kMaxStallZones) stall_zones_.erase(stall_zones_.begin());
}

void Mission::pauseProgress(double t) {
  if (progress_.active() && std::isfinite(progress_tick_s_) && t > progress_tick_s_) progress_.shift(t - progress_tick_s_);
  progress_tick_s_ = t;
}

void Mission::shift(double dt) {
  remedies_.shift(dt);  // its times are read from this clock
  progress_.shift(dt);
  progress_tick_s_ += dt;
}

}  // namespace topo_planner
