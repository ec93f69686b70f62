#include "topo_planner/plan_manage/flight_monitor_core.h"

#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "topo_planner/plan_env/timing.h"

namespace topo_planner {

namespace {


bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }
bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

std::string finishWhy(const std::ostringstream& err, std::string* why) {
  std::string s = err.str();
  if (!s.empty()) s = s.substr(0, s.size() - 2);
  if (why) *why = s;
  return s;
}

// "%.*f" of x, or "nan".
std::string fmt(double x, int digits) {
  if (!std::isfinite(x)) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", digits, x);
  return buf;
}

// A CSV field: quoted (with doubled quotes) when it holds a comma, a quote or a line break.
std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

std::string jsonVector(const Eigen::Vector3d& v) {
  return "[" + jsonNumber(v.x()) + ", " + jsonNumber(v.y()) + ", " + jsonNumber(v.z()) + "]";
}

// Writes `text` to `path`; false with the reason when the file cannot be written.
bool writeFile(const std::string& path, const std::string& text, std::string* error) {
  std::ofstream out(path, std::ios::out | std::ios::trunc);
  if (out) out << text;
  if (out) out.close();
  if (!out) {
    if (error) *error = "cannot write " + path;
    return false;
  }
  return true;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// True map

std::vector<Eigen::Vector3d> occupiedColumns(const OccupancyMap& map) {
  const GridGeometry& g = map.geometry();
  std::map<std::pair<int, int>, int> top;  // (ix, iy) -> highest occupied iz
  map.forEachOccupied([&](const Eigen::Vector3i& i) {
    auto it = top.emplace(std::make_pair(i.x(), i.y()), i.z()).first;
    it->second = std::max(it->second, i.z());
  });
  std::vector<Eigen::Vector3d> columns;
  columns.reserve(top.size());
  for (const auto& [xy, iz] : top) {
    const Eigen::Vector3d c = g.centerOf(Eigen::Vector3i(xy.first, xy.second, iz));
    columns.emplace_back(c.x(), c.y(), c.z() + 0.5 * g.resolution());
  }
  return columns;
}

// ---------------------------------------------------------------------------------------------
// SetpointWatch

bool SetpointWatch::Config::validate(std::string* why) const {
  std::ostringstream err;
  if (!finiteNonNegative(jump_margin_m)) err << "setpoint jump_margin_m must be >= 0; ";
  if (!finiteNonNegative(reanchor_tolerance_m)) err << "reanchor_tolerance_m must be >= 0; ";
  if (!finiteNonNegative(reanchor_window_s)) err << "reanchor_window_s must be >= 0; ";
  if (!(finitePositive(finite_difference_s) && max_finite_difference_s >= finite_difference_s &&
        std::isfinite(max_finite_difference_s)))
    err << "need 0 < finite_difference_s <= max_finite_difference_s; ";
  if (!finiteNonNegative(min_speed_mps)) err << "min_speed_mps must be >= 0; ";
  return finishWhy(err, why).empty();
}

SetpointWatch::SetpointWatch() : SetpointWatch(Config()) {}
SetpointWatch::SetpointWatch(const Config& config) : config_(config) { assert(config.validate(nullptr)); }

double SetpointWatch::lastSpeed() const {
  return have_previous_ ? previous_.velocity_mps.norm() : std::numeric_limits<double>::quiet_NaN();
}

double SetpointWatch::lastDecel() const {
  if (!have_previous_) return std::numeric_limits<double>::quiet_NaN();
  const double speed = previous_.velocity_mps.norm();
  if (speed < config_.min_speed_mps || speed <= 0.0) return 0.0;
  return -previous_.acceleration_mps2.dot(previous_.velocity_mps) / speed;
}

void SetpointWatch::addOdometryJump(double t_s, const Eigen::Vector3d& delta_m) {
  if (!std::isfinite(t_s) || !delta_m.allFinite() || delta_m.isZero()) return;
  pending_.push_back({t_s, delta_m});
}

void SetpointWatch::addOdometryReturn(double t_s) {
  if (std::isfinite(t_s)) returns_.push_back(t_s);
}

void SetpointWatch::setMeasuredPosition(const Eigen::Vector3d& p_m) {
  if (!p_m.allFinite()) return;
  measured_m_ = p_m;
  have_measured_ = true;
}

void SetpointWatch::addSetpoint(const SetpointSample& s) {
  if (!std::isfinite(s.t_s) || !s.position_m.allFinite() || !s.velocity_mps.allFinite() ||
      !s.acceleration_mps2.allFinite())
    return;
  ++stats_.setpoints;
  const double speed = s.velocity_mps.norm();
  auto decel = [&](double d, double t, bool from_difference) {
    if (d > stats_.max_decel_mps2) {
      stats_.max_decel_mps2 = d;
      stats_.max_decel_t_s = t;
      stats_.max_decel_from_difference = from_difference;
    }
  };
  // The acceleration field.
  stats_.max_acc_mps2 = std::max(stats_.max_acc_mps2, s.acceleration_mps2.norm());
  if (speed >= config_.min_speed_mps && speed > 0.0) decel(-s.acceleration_mps2.dot(s.velocity_mps) / speed, s.t_s, false);

  const bool restart = have_previous_ && s.t_s < previous_.t_s;  // time went back: no allowance, no difference
  if (restart) history_.clear();

  // The step from the previous setpoint.
  bool reanchored = false;
  if (have_previous_) {
    const double dt = restart ? 0.0 : s.t_s - previous_.t_s;
    const double motion = std::max(previous_.velocity_mps.norm(), speed) * dt;
    const Eigen::Vector3d step = s.position_m - previous_.position_m;
    SetpointStep st;
    st.t_s = s.t_s;
    st.from_m = previous_.position_m;
    st.to_m = s.position_m;
    st.allowed_m = motion + config_.jump_margin_m;
    if (step.norm() > st.allowed_m) {
      pending_.erase(std::remove_if(pending_.begin(), pending_.end(),
                                    [&](const PendingJump& p) { return s.t_s - p.t_s > config_.reanchor_window_s; }),
                     pending_.end());
      for (auto it = pending_.begin(); it != pending_.end(); ++it)
        if ((step - it->delta_m).norm() <= motion + config_.reanchor_tolerance_m) {
          st.reanchoring = true;
          pending_.erase(it);
          break;
        }
      returns_.erase(std::remove_if(returns_.begin(), returns_.end(),
                                    [&](double t) { return s.t_s - t > config_.reanchor_window_s; }),
                     returns_.end());
      if (!st.reanchoring && !returns_.empty() && have_measured_ &&
          (s.position_m - measured_m_).norm() <= motion + config_.reanchor_tolerance_m) {
        st.reanchoring = true;
        returns_.erase(returns_.begin());
      }
      if (st.reanchoring) {
        ++stats_.reanchorings;
        reanchored = true;
      } else {
        ++stats_.jumps;
        stats_.max_excess_m = std::max(stats_.max_excess_m, step.norm() - st.allowed_m);
      }
      if (stats_.steps.size() < config_.max_steps_kept) stats_.steps.push_back(st);
    }
  }

  // The finite difference of the velocity against the newest setpoint at least finite_difference_s older
  // (none across a re-anchoring: its velocity step is the command meeting the measured state).
  if (reanchored) history_.clear();
  while (!history_.empty() && s.t_s - history_.front().t_s > config_.max_finite_difference_s) history_.pop_front();
  for (auto it = history_.rbegin(); it != history_.rend(); ++it) {
    const double dt = s.t_s - it->t_s;
    if (dt < config_.finite_difference_s) continue;
    const Eigen::Vector3d a = (s.velocity_mps - it->velocity_mps) / dt;
    stats_.max_acc_mps2 = std::max(stats_.max_acc_mps2, a.norm());
    const double v0 = it->velocity_mps.norm();
    if (v0 >= config_.min_speed_mps && v0 > 0.0) decel(-a.dot(it->velocity_mps) / v0, s.t_s, true);
    break;
  }
  history_.push_back(s);
  previous_ = s;
  have_previous_ = true;
}

// ---------------------------------------------------------------------------------------------
// TimeStepFilter, GoalResendPolicy

TimeStepFilter::TimeStepFilter(double max_gap_s, double max_back_s) : max_gap_s_(max_gap_s), max_back_s_(max_back_s) {
  assert(max_gap_s > 0.0 && max_back_s >= 0.0);
}

double TimeStepFilter::addStreamStamp(double raw_s) {
  if (!std::isfinite(raw_s)) return raw_s + correction_s_;
  if (have_last_) {
    const double d = raw_s - last_raw_s_;
    if (d < -max_back_s_ || d > max_gap_s_) {
      // corrected(raw_s) = corrected(last) + the previous interval
      correction_s_ += last_interval_s_ - d;
      ++steps_;
    } else if (d > 0.0) {
      last_interval_s_ = d;
    }
  }
  have_last_ = true;
  last_raw_s_ = raw_s;
  return raw_s + correction_s_;
}

bool GoalResendPolicy::onHeartbeat(uint64_t planner_session, bool inputs_ok, double t_s) {
  inputs_ok_ = inputs_ok;
  const bool restart = have_session_ && planner_session != session_;
  if (restart) {
    ++restarts_;
    pending_ = true;
    due_t_s_ = t_s + settle_s_;
  }
  have_session_ = true;
  session_ = planner_session;
  return restart;
}

void GoalResendPolicy::onFaultCleared(double t_s) {
  pending_ = true;
  due_t_s_ = t_s + settle_s_;  // a later trigger postpones an earlier one
}

bool GoalResendPolicy::due(double t_s) {
  if (!pending_ || t_s < due_t_s_ || !inputs_ok_) return false;
  pending_ = false;
  return true;
}

// ---------------------------------------------------------------------------------------------
// FlightRecorder

const char* toString(FlightStatus status) {
  switch (status) {
    case FlightStatus::kInProgress: return "kInProgress";
    case FlightStatus::kSuccess: return "kSuccess";
    case FlightStatus::kCollision: return "kCollision";
    case FlightStatus::kGoalTimeout: return "kGoalTimeout";
    case FlightStatus::kNoStart: return "kNoStart";
    case FlightStatus::kInterrupted: return "kInterrupted";
  }
  return "unknown";
}

bool FlightRecorder::Config::validate(std::string* why) const {
  std::ostringstream err;
  if (!finitePositive(goal_tolerance_m)) err << "goal_tolerance_m must be positive; ";
  if (!finiteNonNegative(goal_max_speed_mps)) err << "goal_max_speed_mps must be >= 0 (0 = no speed condition); ";
  if (!finitePositive(waypoint_tolerance_m)) err << "waypoint_tolerance_m must be positive; ";
  if (!(finitePositive(goal_timeout_s) && goal_timeout_s <= 1e6)) err << "goal_timeout_s must be in (0, 1e6]; ";
  if (!finiteNonNegative(collision_radius_m)) err << "collision_radius_m must be >= 0; ";
  if (!finiteNonNegative(contact_release_m)) err << "contact_release_m must be >= 0; ";
  if (!(finiteNonNegative(trace_period_s) && trace_period_s <= 3600.0)) err << "trace_period_s must be in [0, 3600]; ";
  if (!finitePositive(max_sample_gap_s)) err << "max_sample_gap_s must be positive; ";
  std::string sub;
  if (!setpoints.validate(&sub)) err << sub << "; ";
  if (!speed.validate(&sub)) err << "speed account: " << sub << "; ";
  return finishWhy(err, why).empty();
}

FlightRecorder::FlightRecorder(const Config& config, const std::vector<Eigen::Vector3d>& goals)
    : config_(config), speed_account_(config.speed), setpoint_watch_(config.setpoints) {
  assert(config.validate(nullptr));
  goals_.resize(goals.size());
  for (size_t i = 0; i < goals.size(); ++i) {
    goals_[i].index = int(i);
    goals_[i].goal_m = goals[i];
  }
}

FlightRecorder::Update FlightRecorder::start(double t_s) {
  Update update;
  if (started_ || finished()) return update;
  started_ = true;
  start_t_s_ = last_t_s_ = t_s;
  have_previous_ = false;
  if (goals_.empty()) {
    endFlight(t_s, FlightStatus::kSuccess, "no goals to fly to");
    update.finished = true;
    return update;
  }
  active_ = 0;
  goals_[0].sent = true;
  goals_[0].sent_t_s = t_s;
  update.next_goal = 0;
  return update;
}

FlightRecorder::Update FlightRecorder::addOdometry(const OdometrySample& s) {
  Update update;
  if (!flying()) return update;
  if (!std::isfinite(s.t_s) || !s.position_m.allFinite() || !s.velocity_mps.allFinite()) return update;
  if (have_previous_ && s.t_s < previous_.t_s) return update;  // out of order
  GoalRecord& goal = goals_[size_t(active_)];
  const double speed = s.velocity_mps.norm();
  setpoint_watch_.setMeasuredPosition(s.position_m);

  // Speed and path from the odometry only without a ground truth (its noise is no motion).
  if (have_previous_ && !truth_seen_) {
    const double dt = s.t_s - previous_.t_s;
    if (dt > 0.0 && dt <= config_.max_sample_gap_s) {
      speed_integral_m_ += 0.5 * (previous_.velocity_mps.norm() + speed) * dt;
      integrated_s_ += dt;
      const double step = (s.position_m - previous_.position_m).norm();
      path_length_m_ += step;
      goal.path_length_m += step;
    }
  }
  if (!truth_seen_) {
    max_speed_mps_ = std::max(max_speed_mps_, speed);
    goal.max_speed_mps = std::max(goal.max_speed_mps, speed);
    speed_account_.addSpeed(s.t_s, speed);
  }

  if (std::isfinite(s.clearance_m)) addClearance(s.position_m, s.clearance_m, &goal);

  // Rows on a fixed grid of trace_period_s (a sample within 1 ms before its slot takes it), so the
  // rate is exact even when odometry stamps jitter; after a gap the grid restarts at the sample.
  const double slack = std::min(1e-3, 0.1 * config_.trace_period_s);
  if (trace_.empty() || s.t_s >= next_trace_t_s_ - slack) {
    TraceRow row;
    row.t_s = s.t_s - start_t_s_;
    row.position_m = s.position_m;
    row.velocity_mps = s.velocity_mps;
    row.clearance_m = std::isfinite(s.clearance_m) ? s.clearance_m : truth_clearance_m_;
    row.goal_index = active_;
    row.commanded_speed_mps = setpoint_watch_.lastSpeed();
    row.commanded_decel_mps2 = setpoint_watch_.lastDecel();
    trace_.push_back(row);
    next_trace_t_s_ = (trace_.size() == 1 ? s.t_s : next_trace_t_s_) + config_.trace_period_s;
    if (next_trace_t_s_ <= s.t_s) next_trace_t_s_ = s.t_s + config_.trace_period_s;
  }
  previous_ = s;
  have_previous_ = true;
  last_t_s_ = std::max(last_t_s_, s.t_s);

  goal.distance_m = (s.position_m - goal.goal_m).norm();
  const bool slow = config_.goal_max_speed_mps <= 0.0 || speed <= config_.goal_max_speed_mps;
  const bool waypoint = config_.pass_through && size_t(active_ + 1) < goals_.size();
  if (waypoint ? goal.distance_m <= config_.waypoint_tolerance_m
               : goal.distance_m <= config_.goal_tolerance_m && slow) {
    goal.reached = true;
    goal.reached_t_s = s.t_s;
    update.goal_reached = active_;
    advanceFrom(active_, s.t_s, &update);
    return update;
  }
  return checkTimeout(s.t_s);
}

void FlightRecorder::addClearance(const Eigen::Vector3d& position_m, double clearance_m, GoalRecord* goal) {
  if (!(clearance_m >= min_clearance_m_)) {  // also true while min_clearance_m_ is NaN
    min_clearance_m_ = clearance_m;
    min_clearance_position_m_ = position_m;
  }
  if (!(clearance_m >= goal->min_clearance_m)) goal->min_clearance_m = clearance_m;
  if (!in_contact_ && clearance_m < config_.collision_radius_m) {
    in_contact_ = true;
    ++clearance_contacts_;
    ++goal->clearance_contacts;
  } else if (in_contact_ && clearance_m > config_.collision_radius_m + config_.contact_release_m) {
    in_contact_ = false;
  }
}

void FlightRecorder::addTruth(const OdometrySample& truth) {
  if (!flying() || !std::isfinite(truth.t_s) || !truth.position_m.allFinite() || !truth.velocity_mps.allFinite())
    return;
  truth_speed_mps_ = truth.velocity_mps.norm();
  GoalRecord& goal = goals_[size_t(active_)];
  if (!truth_seen_) {  // from now on speed and path come from here
    truth_seen_ = true;
    speed_integral_m_ = integrated_s_ = path_length_m_ = max_speed_mps_ = 0.0;
    for (GoalRecord& g : goals_) g.path_length_m = g.max_speed_mps = 0.0;
  }
  if (have_previous_truth_ && truth.t_s > previous_truth_.t_s) {
    const double dt = truth.t_s - previous_truth_.t_s;
    if (dt <= config_.max_sample_gap_s) {
      speed_integral_m_ += 0.5 * (previous_truth_.velocity_mps.norm() + truth_speed_mps_) * dt;
      integrated_s_ += dt;
      const double step = (truth.position_m - previous_truth_.position_m).norm();
      path_length_m_ += step;
      goal.path_length_m += step;
    }
  }
  if (!have_previous_truth_ || truth.t_s >= previous_truth_.t_s) {
    previous_truth_ = truth;
    have_previous_truth_ = true;
  }
  max_speed_mps_ = std::max(max_speed_mps_, truth_speed_mps_);
  goal.max_speed_mps = std::max(goal.max_speed_mps, truth_speed_mps_);
  speed_account_.addSpeed(truth.t_s, truth_speed_mps_);
  if (!std::isfinite(truth.clearance_m)) return;
  truth_clearance_m_ = truth.clearance_m;
  addClearance(truth.position_m, truth.clearance_m, &goal);
}

void FlightRecorder::addSetpoint(const SetpointSample& setpoint) {
  if (!flying()) return;
  setpoint_watch_.addSetpoint(setpoint);
  SpeedAccount::Setpoint sp;
  sp.mode = setpoint.mode;
  sp.session = setpoint.planner_session;
  sp.trajectory_id = setpoint.trajectory_id;
  sp.velocity = setpoint.velocity_mps;
  sp.acceleration = setpoint.acceleration_mps2;
  speed_account_.setSetpoint(sp);
}

void FlightRecorder::setOracle(const FlightOracle::Result& oracle) {
  if (!oracle.ok || oracle.time_s.size() != goals_.size()) return;
  for (size_t i = 0; i < goals_.size(); ++i) goals_[i].oracle_time_s = oracle.time_s[i];
}

void FlightRecorder::addOdometryJump(double t_s, const Eigen::Vector3d& delta_m) {
  setpoint_watch_.addOdometryJump(t_s, delta_m);
}

void FlightRecorder::addOdometryReturn(double t_s) { setpoint_watch_.addOdometryReturn(t_s); }

void FlightRecorder::addFault(double t_s, const std::string& kind, const std::string& phase, const std::string& text) {
  FaultRecord f;
  f.t_s = t_s;
  f.kind = kind;
  f.phase = phase;
  f.text = text;
  f.commanded_speed_mps = setpoint_watch_.lastSpeed();
  f.true_speed_mps = truth_speed_mps_;
  f.goal_index = flying() ? active_ : -1;
  faults_.push_back(f);
}

void FlightRecorder::setCounters(int planner_restarts, int goal_resends, int time_steps) {
  planner_restarts_ = planner_restarts;
  goal_resends_ = goal_resends;
  time_steps_ = time_steps;
}

FlightRecorder::Update FlightRecorder::checkTimeout(double t_s) {
  Update update;
  if (!flying() || !std::isfinite(t_s)) return update;
  last_t_s_ = std::max(last_t_s_, t_s);
  GoalRecord& goal = goals_[size_t(active_)];
  if (t_s - goal.sent_t_s <= config_.goal_timeout_s) return update;
  goal.timed_out = true;
  update.goal_timed_out = active_;
  std::ostringstream m;
  m << "goal " << active_ + 1 << "/" << goals_.size() << " not reached within " << fmt(config_.goal_timeout_s, 1)
    << " s (" << fmt(goal.distance_m, 2) << " m away); " << summary().goals_reached << " of " << goals_.size()
    << " goals reached";
  endFlight(t_s, FlightStatus::kGoalTimeout, m.str());
  update.finished = true;
  return update;
}

void FlightRecorder::advanceFrom(int reached, double t_s, Update* update) {
  if (size_t(reached + 1) < goals_.size()) {
    active_ = reached + 1;
    goals_[size_t(active_)].sent = true;
    goals_[size_t(active_)].sent_t_s = t_s;
    update->next_goal = active_;
    return;
  }
  const FlightSummary s = summary();
  std::ostringstream m;
  m << s.goals_reached << "/" << s.goals_total << " goals reached, ";
  if (s.collisions == 0) {
    m << "no collision";
  } else {
    m << s.collisions << (s.collisions == 1 ? " collision" : " collisions");
  }
  endFlight(t_s, s.collisions == 0 ? FlightStatus::kSuccess : FlightStatus::kCollision, m.str());
  update->finished = true;
}

void FlightRecorder::addReplan(ReplanRecord record) {
  if (!flying()) return;
  record.goal_index = active_;
  GoalRecord& goal = goals_[size_t(active_)];
  if (record.stall) {
    ++goal.stalls;
  } else if (record.published) {
    ++goal.replans;
  } else {
    ++goal.replan_failures;
  }
  replans_.push_back(std::move(record));
}

void FlightRecorder::addSimCollisionCount(double /*t_s*/, uint32_t count) {
  if (!started_) {  // before the flight: the baseline
    have_sim_count_ = true;
    sim_count_base_ = sim_count_max_ = count;
    return;
  }
  if (!flying()) return;
  if (!have_sim_count_) {  // nothing seen before the flight: the simulator counted none
    have_sim_count_ = true;
    sim_count_base_ = sim_count_max_ = 0;
  }
  if (count > sim_count_max_) {
    goals_[size_t(active_)].sim_collisions += int(count - sim_count_max_);
    sim_count_max_ = count;
  }
}

void FlightRecorder::finish(double t_s, FlightStatus status, const std::string& message) {
  if (finished()) return;
  if (!started_) start_t_s_ = last_t_s_ = t_s;
  endFlight(t_s, status, message);
}

void FlightRecorder::endFlight(double t_s, FlightStatus status, const std::string& message) {
  status_ = status;
  message_ = message;
  end_t_s_ = std::isfinite(t_s) ? t_s : last_t_s_;
  active_ = -1;
}

FlightSummary FlightRecorder::summary() const {
  FlightSummary s;
  s.status = status_;
  s.success = status_ == FlightStatus::kSuccess;
  s.message = finished() ? message_ : (started_ ? "in progress" : "not started");
  s.goals_total = int(goals_.size());
  for (const GoalRecord& g : goals_) s.goals_reached += g.reached ? 1 : 0;
  s.sim_collisions = int(sim_count_max_ - sim_count_base_);
  s.clearance_contacts = clearance_contacts_;
  s.collisions = std::max(s.sim_collisions, s.clearance_contacts);
  s.min_clearance_m = min_clearance_m_;
  s.min_clearance_position_m = min_clearance_position_m_;
  s.mean_speed_mps = integrated_s_ > 0.0 ? speed_integral_m_ / integrated_s_ : 0.0;
  s.max_speed_mps = max_speed_mps_;
  std::vector<double> ms;
  ms.reserve(replans_.size());
  for (const ReplanRecord& r : replans_) {
    if (r.stall) {
      ++s.stalls;
      continue;
    }
    (r.published ? s.replans : s.replan_failures) += 1;
    if (std::isfinite(r.total_ms)) ms.push_back(r.total_ms);
  }
  s.replan_ms_median = percentile(ms, 0.5);
  s.replan_ms_p95 = percentile(ms, 0.95);
  s.replan_ms_max = percentile(ms, 1.0);
  if (started_) s.duration_s = (finished() ? end_t_s_ : last_t_s_) - start_t_s_;
  s.path_length_m = path_length_m_;
  s.measured_on_truth = truth_seen_;
  s.speed = speed_account_.totals();
  s.fast_share = s.speed.total_s > 0.0 ? s.speed.fast_s / s.speed.total_s : 0.0;
  double oracle = 0.0, flown = 0.0;
  bool any = false, all_known = true;
  for (const GoalRecord& g : goals_)
    if (g.reached) {
      any = true;
      all_known = all_known && std::isfinite(g.oracle_time_s);
      oracle += g.oracle_time_s;
      flown += g.reached_t_s - g.sent_t_s;
    }
  if (any && all_known && oracle > 0.0) {
    s.oracle_time_s = oracle;
    s.reached_time_s = flown;
    s.time_ratio = flown / oracle;
  }
  const SetpointWatch::Stats& w = setpoint_watch_.stats();
  s.setpoints = w.setpoints;
  s.setpoint_jumps = w.jumps;
  s.reanchorings = w.reanchorings;
  s.max_decel_mps2 = w.max_decel_mps2;
  s.max_acc_mps2 = w.max_acc_mps2;
  for (const FaultRecord& f : faults_)
    if (f.goal_index >= 0 && f.phase != "end") ++s.faults_injected;
  s.planner_restarts = planner_restarts_;
  s.goal_resends = goal_resends_;
  s.time_steps = time_steps_;
  return s;
}

// ---------------------------------------------------------------------------------------------
// Text

std::string formatGoalLine(const GoalRecord& goal, int goals_total, double flight_start_s, double now_s) {
  std::ostringstream l;
  l << "goal " << goal.index + 1 << "/" << goals_total << " (" << fmt(goal.goal_m.x(), 1) << ", "
    << fmt(goal.goal_m.y(), 1) << ", " << fmt(goal.goal_m.z(), 1) << ") ";
  const double end = goal.reached ? goal.reached_t_s : now_s;
  if (goal.reached) {
    l << "reached";
  } else if (goal.timed_out) {
    l << "NOT reached (timeout, " << fmt(goal.distance_m, 2) << " m away)";
  } else {
    l << "NOT reached (" << fmt(goal.distance_m, 2) << " m away)";
  }
  l << " at t=" << fmt(end - flight_start_s, 1) << " s after " << fmt(goal.elapsedS(now_s), 1)
    << " s: path " << fmt(goal.path_length_m, 1) << " m, max speed " << fmt(goal.max_speed_mps, 2) << " m/s, "
    << goal.replans << " replans (" << goal.replan_failures << " failed), " << goal.stalls << " stalls, min clearance "
    << fmt(goal.min_clearance_m, 2) << " m, collisions " << goal.collisions();
  return l.str();
}

namespace {
// "12.3 s for the goals reached, flown in 20.1 s: 1.63x" (or why there is none).
std::string speedLine(const FlightSummary& s) {
  if (!std::isfinite(s.time_ratio)) return "n/a (no oracle, or no goal reached)";
  return fmt(s.oracle_time_s, 1) + " s for the goals reached, flown in " + fmt(s.reached_time_s, 1) + " s: " +
         fmt(s.time_ratio, 2) + "x";
}
}  // namespace

std::string accountLine(const SpeedAccount::Totals& t) {
  if (!(t.slow() > 0.0)) return "none";
  std::ostringstream l;
  bool first = true;
  for (int c = 0; c < kNumSlowCauses; ++c) {
    const double share = t.share(SlowCause(c));
    if (share < 0.005) continue;
    l << (first ? "" : ", ") << toString(SlowCause(c)) << " " << fmt(100.0 * share, 0) << "%";
    first = false;
  }
  return l.str();
}

std::string formatReport(const FlightSummary& s, const std::string& name) {
  std::ostringstream r;
  r << "flight report" << (name.empty() ? "" : " (" + name + ")") << ": " << (s.success ? "SUCCESS" : "FAILURE")
    << " (" << toString(s.status) << ": " << s.message << ")\n"
    << "  goals reached        " << s.goals_reached << "/" << s.goals_total << "\n"
    << "  collisions           " << s.collisions << " (simulator " << s.sim_collisions << ", clearance check "
    << s.clearance_contacts << ")\n"
    << "  min clearance        "
    << (std::isfinite(s.min_clearance_m)
            ? fmt(s.min_clearance_m, 2) + " m at (" + fmt(s.min_clearance_position_m.x(), 1) + ", " +
                  fmt(s.min_clearance_position_m.y(), 1) + ", " + fmt(s.min_clearance_position_m.z(), 1) + ")"
            : std::string("n/a (no odometry during the flight)"))
    << "\n"
    << "  speed mean / max     " << fmt(s.mean_speed_mps, 2) << " / " << fmt(s.max_speed_mps, 2) << " m/s\n"
    << "  replans              " << s.replans << " (" << s.replan_failures << " failed), " << s.stalls
    << " stall re-routes\n"
    << "  replanning time      median " << fmt(s.replan_ms_median, 1) << " ms, p95 " << fmt(s.replan_ms_p95, 1)
    << " ms, max " << fmt(s.replan_ms_max, 1) << " ms\n"
    << "  duration             " << fmt(s.duration_s, 1) << " s, path " << fmt(s.path_length_m, 1) << " m"
    << (s.measured_on_truth ? " (ground truth)" : " (odometry)") << "\n"
    << "  oracle               " << speedLine(s) << "\n"
    << "  speed account        " << fmt(100.0 * s.fast_share, 0) << "% of the time fast; slow: " << accountLine(s.speed)
    << "\n"
    << "  setpoints            " << s.setpoints << ", " << s.setpoint_jumps << " jumps, " << s.reanchorings
    << " re-anchorings, worst deceleration " << fmt(s.max_decel_mps2, 2) << " m/s^2, worst acceleration "
    << fmt(s.max_acc_mps2, 2) << " m/s^2\n"
    << "  faults               " << s.faults_injected << " injected, " << s.planner_restarts << " planner restarts, "
    << s.goal_resends << " goals re-sent, " << s.time_steps << " ROS time steps";
  return r.str();
}

std::string jsonString(const std::string& s) {
  std::string out = "\"";
  for (unsigned char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default:
        if (c < 0x20) {
          char buf[8];
          std::snprintf(buf, sizeof(buf), "\\u%04x", c);
          out += buf;
        } else {
          out += char(c);
        }
    }
  }
  return out + "\"";
}

std::string jsonNumber(double x) {
  if (!std::isfinite(x)) return "null";
  char buf[64];
  const auto result = std::to_chars(buf, buf + sizeof(buf), x);
  return std::string(buf, result.ptr);
}

// ---------------------------------------------------------------------------------------------
// Files

bool writeTraceCsv(const std::string& path, const std::vector<TraceRow>& rows, std::string* error) {
  std::string text = "t,x,y,z,vx,vy,vz,speed,clearance_m,goal_index,cmd_speed,cmd_decel\n";
  text.reserve(rows.size() * 96 + text.size());
  char line[512];
  for (const TraceRow& r : rows) {
    std::snprintf(line, sizeof(line), "%.3f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%s,%d,%s,%s\n", r.t_s,
                  r.position_m.x(), r.position_m.y(), r.position_m.z(), r.velocity_mps.x(), r.velocity_mps.y(),
                  r.velocity_mps.z(), r.velocity_mps.norm(), fmt(r.clearance_m, 4).c_str(), r.goal_index,
                  fmt(r.commanded_speed_mps, 4).c_str(), fmt(r.commanded_decel_mps2, 4).c_str());
    text += line;
  }
  return writeFile(path, text, error);
}

bool writeReplanCsv(const std::string& path, const std::vector<ReplanRecord>& replans, double start_t_s,
                    std::string* error) {
  std::ostringstream text;
  text << "t,x,y,z,trigger,status,fallback,total_ms,trajectory_id,goal_index,message\n";
  for (const ReplanRecord& r : replans) {
    text << fmt(r.t_s - start_t_s, 3) << ',' << fmt(r.position_m.x(), 4) << ',' << fmt(r.position_m.y(), 4)
         << ',' << fmt(r.position_m.z(), 4) << ',' << csvField(r.trigger) << ',' << csvField(r.status) << ','
         << csvField(r.fallback) << ',' << fmt(r.total_ms, 3) << ',' << r.trajectory_id << ',' << r.goal_index
         << ',' << csvField(r.message) << '\n';
  }
  return writeFile(path, text.str(), error);
}

bool writeMapCsv(const std::string& path, const std::vector<Eigen::Vector3d>& columns, std::string* error) {
  std::ostringstream text;
  text << "x,y,z_max\n";
  for (const Eigen::Vector3d& c : columns) text << fmt(c.x(), 3) << ',' << fmt(c.y(), 3) << ',' << fmt(c.z(), 3) << '\n';
  return writeFile(path, text.str(), error);
}

bool writeReferenceCsv(const std::string& path, const std::vector<ReferenceRecord>& references, std::string* error) {
  std::ostringstream text;
  text << "id,t,x,y,z\n";
  for (const ReferenceRecord& r : references)
    for (const Eigen::Vector3d& p : r.points_m)
      text << r.id << ',' << fmt(r.t_s, 3) << ',' << fmt(p.x(), 4) << ',' << fmt(p.y(), 4) << ','
           << fmt(p.z(), 4) << '\n';
  return writeFile(path, text.str(), error);
}

bool writeReportJson(const std::string& path, const FlightSummary& s, const std::vector<GoalRecord>& goals,
                     double start_t_s, const FlightReportInfo& info, std::string* error,
                     const FlightRecorder* recorder) {
  return writeFile(path, reportJson(s, goals, start_t_s, info, recorder), error);
}

std::string reportJson(const FlightSummary& s, const std::vector<GoalRecord>& goals, double start_t_s,
                       const FlightReportInfo& info, const FlightRecorder* recorder) {
  std::ostringstream j;
  j << "{\n"
    << "  \"name\": " << jsonString(info.name) << ",\n"
    << "  \"success\": " << (s.success ? "true" : "false") << ",\n"
    << "  \"status\": " << jsonString(toString(s.status)) << ",\n"
    << "  \"message\": " << jsonString(s.message) << ",\n"
    << "  \"goals_total\": " << s.goals_total << ",\n"
    << "  \"goals_reached\": " << s.goals_reached << ",\n"
    << "  \"collisions\": " << s.collisions << ",\n"
    << "  \"sim_collisions\": " << s.sim_collisions << ",\n"
    << "  \"clearance_contacts\": " << s.clearance_contacts << ",\n"
    << "  \"min_clearance_m\": " << jsonNumber(s.min_clearance_m) << ",\n"
    << "  \"min_clearance_position_m\": " << jsonVector(s.min_clearance_position_m) << ",\n"
    << "  \"mean_speed_mps\": " << jsonNumber(s.mean_speed_mps) << ",\n"
    << "  \"max_speed_mps\": " << jsonNumber(s.max_speed_mps) << ",\n"
    << "  \"replans\": " << s.replans << ",\n"
    << "  \"replan_failures\": " << s.replan_failures << ",\n"
    << "  \"stalls\": " << s.stalls << ",\n"
    << "  \"replan_ms_median\": " << jsonNumber(s.replan_ms_median) << ",\n"
    << "  \"replan_ms_p95\": " << jsonNumber(s.replan_ms_p95) << ",\n"
    << "  \"replan_ms_max\": " << jsonNumber(s.replan_ms_max) << ",\n"
    << "  \"duration_s\": " << jsonNumber(s.duration_s) << ",\n"
    << "  \"path_length_m\": " << jsonNumber(s.path_length_m) << ",\n"
    << "  \"measured_on_truth\": " << (s.measured_on_truth ? "true" : "false") << ",\n"
    << "  \"oracle_time_s\": " << jsonNumber(s.oracle_time_s) << ",\n"
    << "  \"reached_time_s\": " << jsonNumber(s.reached_time_s) << ",\n"
    << "  \"time_ratio\": " << jsonNumber(s.time_ratio) << ",\n"
    << "  \"fast_share\": " << jsonNumber(s.fast_share) << ",\n"
    << "  \"speed_account_s\": {\"total\": " << jsonNumber(s.speed.total_s) << ", \"fast\": " << jsonNumber(s.speed.fast_s);
  for (int c = 0; c < kNumSlowCauses; ++c)
    j << ", " << jsonString(toString(SlowCause(c))) << ": " << jsonNumber(s.speed.slow_s[size_t(c)]);
  j << "},\n"
    << "  \"setpoints\": " << s.setpoints << ",\n"
    << "  \"setpoint_jumps\": " << s.setpoint_jumps << ",\n"
    << "  \"reanchorings\": " << s.reanchorings << ",\n"
    << "  \"max_decel_mps2\": " << jsonNumber(s.max_decel_mps2) << ",\n"
    << "  \"max_acc_mps2\": " << jsonNumber(s.max_acc_mps2) << ",\n"
    << "  \"faults_injected\": " << s.faults_injected << ",\n"
    << "  \"planner_restarts\": " << s.planner_restarts << ",\n"
    << "  \"goal_resends\": " << s.goal_resends << ",\n"
    << "  \"time_steps\": " << s.time_steps << ",\n"
    << "  \"start_m\": " << jsonVector(info.start_m) << ",\n"
    << "  \"map_resolution_m\": " << jsonNumber(info.map_resolution_m) << ",\n"
    << "  \"map_occupied_voxels\": " << info.map_occupied_voxels << ",\n"
    << "  \"collision_radius_m\": " << jsonNumber(info.collision_radius_m) << ",\n"
    << "  \"scenario\": {";
  bool first = true;
  for (const auto& [key, value] : info.scenario) {
    j << (first ? "\n" : ",\n") << "    " << jsonString(key) << ": " << (value.empty() ? "null" : value);
    first = false;
  }
  j << (first ? "" : "\n  ") << "},\n"
    << "  \"goals\": [";
  for (size_t i = 0; i < goals.size(); ++i) {
    const GoalRecord& g = goals[i];
    j << (i ? ",\n" : "\n") << "    {\"index\": " << g.index << ", \"goal_m\": " << jsonVector(g.goal_m)
      << ", \"sent\": " << (g.sent ? "true" : "false") << ", \"reached\": " << (g.reached ? "true" : "false")
      << ", \"timed_out\": " << (g.timed_out ? "true" : "false")
      << ", \"sent_t_s\": " << jsonNumber(g.sent ? g.sent_t_s - start_t_s : std::nan(""))
      << ", \"reached_t_s\": " << jsonNumber(g.reached ? g.reached_t_s - start_t_s : std::nan(""))
      << ", \"time_s\": " << jsonNumber(g.reached ? g.reached_t_s - g.sent_t_s : std::nan(""))
      << ", \"oracle_time_s\": " << jsonNumber(g.oracle_time_s)
      << ", \"path_length_m\": " << jsonNumber(g.path_length_m) << ", \"max_speed_mps\": " << jsonNumber(g.max_speed_mps)
      << ", \"min_clearance_m\": " << jsonNumber(g.min_clearance_m) << ", \"distance_m\": " << jsonNumber(g.distance_m)
      << ", \"replans\": " << g.replans << ", \"replan_failures\": " << g.replan_failures << ", \"stalls\": " << g.stalls
      << ", \"collisions\": " << g.collisions() << "}";
  }
  j << (goals.empty() ? "" : "\n  ") << "]";
  if (recorder) {
    const auto rel = [&](double t) { return jsonNumber(t - start_t_s); };
    j << ",\n  \"faults\": [";
    const std::vector<FaultRecord>& faults = recorder->faults();
    for (size_t i = 0; i < faults.size(); ++i) {
      const FaultRecord& f = faults[i];
      j << (i ? ",\n" : "\n") << "    {\"t_s\": " << rel(f.t_s) << ", \"kind\": " << jsonString(f.kind)
        << ", \"phase\": " << jsonString(f.phase) << ", \"commanded_speed_mps\": " << jsonNumber(f.commanded_speed_mps)
        << ", \"true_speed_mps\": " << jsonNumber(f.true_speed_mps) << ", \"goal_index\": " << f.goal_index
        << ", \"text\": " << jsonString(f.text) << "}";
    }
    j << (faults.empty() ? "" : "\n  ") << "],\n  \"setpoint_steps\": [";
    const std::vector<SetpointStep>& steps = recorder->setpoints().stats().steps;
    for (size_t i = 0; i < steps.size(); ++i) {
      const SetpointStep& st = steps[i];
      j << (i ? ",\n" : "\n") << "    {\"t_s\": " << rel(st.t_s) << ", \"from_m\": " << jsonVector(st.from_m)
        << ", \"to_m\": " << jsonVector(st.to_m) << ", \"step_m\": " << jsonNumber((st.to_m - st.from_m).norm())
        << ", \"allowed_m\": " << jsonNumber(st.allowed_m)
        << ", \"reanchoring\": " << (st.reanchoring ? "true" : "false") << "}";
    }
    j << (steps.empty() ? "" : "\n  ") << "],\n  \"max_decel_t_s\": "
      << rel(recorder->setpoints().stats().max_decel_t_s) << ",\n  \"max_decel_from\": "
      << jsonString(recorder->setpoints().stats().max_decel_from_difference ? "velocity_difference"
                                                                           : "acceleration");
  }
  j << "\n}\n";
  return j.str();
}

}  // namespace topo_planner
