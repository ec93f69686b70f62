#include "topo_planner/plan_manage/health.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace topo_planner {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}  // namespace

const char* toString(HealthLevel level) {
  switch (level) {
    case HealthLevel::kOk: return "OK";
    case HealthLevel::kWarn: return "WARN";
    case HealthLevel::kError: return "ERROR";
  }
  return "unknown";
}

void HealthReport::raise(HealthLevel l, const std::string& why) {
  if (l > level) {
    level = l;
    message = why;
  } else if (l == level) {
    message += (message.empty() ? "" : "; ") + why;
  }
}

void HealthReport::add(const std::string& key, const std::string& v) { values.emplace_back(key, v); }

void HealthReport::add(const std::string& key, double v, int precision) {
  if (!std::isfinite(v)) {
    add(key, std::string("nan"));
    return;
  }
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", std::clamp(precision, 0, 9), v);
  add(key, std::string(text));
}

std::string HealthReport::value(const std::string& key) const {
  for (const auto& kv : values)
    if (kv.first == key) return kv.second;
  return "";
}

void EventWindow::add(double t, double value) {
  if (!std::isfinite(t)) return;
  if (!events_.empty() && t < events_.back().first) events_.clear();
  events_.emplace_back(t, value);
  prune(t);
}

void EventWindow::prune(double now) {
  if (!std::isfinite(now)) return;
  if (!events_.empty() && now < events_.back().first) {
    events_.clear();  // the clock went back
    return;
  }
  while (!events_.empty() && events_.front().first < now - window_s_) events_.pop_front();
}

double EventWindow::median() const {
  if (events_.empty()) return kNaN;
  std::vector<double> v;
  v.reserve(events_.size());
  for (const auto& e : events_) v.push_back(e.second);
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  if (v.size() % 2 == 1) return v[mid];
  const double upper = v[mid];
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + mid));
}

double EventWindow::max() const {
  if (events_.empty()) return kNaN;
  double m = events_.front().second;
  for (const auto& e : events_) m = std::max(m, e.second);
  return m;
}

size_t EventWindow::countAbove(double threshold) const {
  return size_t(std::count_if(events_.begin(), events_.end(), [&](const auto& e) { return e.second > threshold; }));
}

double EventWindow::increase() const {
  return events_.size() < 2 ? 0.0 : events_.back().second - events_.front().second;
}

double EventWindow::increasePerSecond() const {
  if (events_.size() < 2) return kNaN;
  const double dt = events_.back().first - events_.front().first;
  return dt > 0.0 ? increase() / dt : kNaN;
}

PlannerHealth::PlannerHealth(const Config& config)
    : config_(config), calls_(config.window_s), failures_(config.window_s), stops_(config.window_s) {}

void PlannerHealth::addPlanningCall(double t, bool published, double total_ms) {
  std::lock_guard<std::mutex> lock(mutex_);
  calls_.add(t, std::isfinite(total_ms) ? total_ms : 0.0);
  if (!published) failures_.add(t);
  ++calls_total_;
  if (published) ++published_total_;
}

void PlannerHealth::addEmergencyStop(double t) {
  std::lock_guard<std::mutex> lock(mutex_);
  stops_.add(t);
  ++stops_total_;
}

void PlannerHealth::addGiveUp(double t, const std::string& why) {
  std::lock_guard<std::mutex> lock(mutex_);
  give_up_t_ = t;
  give_up_why_ = why;
  ++give_ups_total_;
}

HealthReport PlannerHealth::report(double now, const Inputs& in) {
  std::lock_guard<std::mutex> lock(mutex_);
  calls_.prune(now);
  failures_.prune(now);
  stops_.prune(now);
  HealthReport r;
  r.message = "state " + in.state;
  if (!in.have_odometry) r.raise(HealthLevel::kWarn, "waiting for odometry");
  else if (!in.inputs_ok && (in.odom_age_s < 0.0 || in.depth_age_s < 0.0))
    r.raise(HealthLevel::kWarn, "waiting for inputs: " + in.inputs_why);  // at start-up: none yet
  else if (!in.inputs_ok)
    r.raise(HealthLevel::kError, "inputs stale: " + in.inputs_why + " (no planning; a moving vehicle stops)");
  if (give_up_t_ >= 0.0 && now >= give_up_t_ && now - give_up_t_ <= config_.give_up_hold_s)
    r.raise(HealthLevel::kWarn, "mission given up: " + give_up_why_);
  if (stops_.size() > 0) r.raise(HealthLevel::kWarn, "emergency stop in the last " + std::to_string(int(config_.window_s)) + " s");
  const size_t calls = calls_.size(), failed = failures_.size();
  if (int(calls) >= config_.min_calls && double(failed) > config_.max_failure_fraction * double(calls))
    r.raise(HealthLevel::kWarn, std::to_string(failed) + " of " + std::to_string(calls) + " planning calls failed in the last " +
                                    std::to_string(int(config_.window_s)) + " s");
  r.add("state", in.state);
  r.add("inputs", in.inputs_ok ? std::string("fresh") : in.inputs_why);
  r.add("odometry age [s]", in.odom_age_s >= 0.0 ? in.odom_age_s : kNaN);
  r.add("depth age [s]", in.depth_age_s >= 0.0 ? in.depth_age_s : kNaN);
  r.add("planning calls in window", double(calls), 0);
  r.add("failed calls in window", double(failed), 0);
  r.add("planning rate [Hz]", double(calls) / config_.window_s, 2);
  r.add("planning time median [ms]", calls_.median(), 2);
  r.add("planning time max [ms]", calls_.max(), 2);
  r.add("planning calls total", double(calls_total_), 0);
  r.add("trajectories published total", double(published_total_), 0);
  r.add("emergency stops total", double(stops_total_), 0);
  r.add("missions given up total", double(give_ups_total_), 0);
  return r;
}

MappingHealth::MappingHealth(const Config& config) : config_(config), fused_(config.window_s), refused_(config.window_s) {}

HealthReport MappingHealth::report(double now, const Inputs& in) {
  std::lock_guard<std::mutex> lock(mutex_);
  fused_.add(now, double(in.frames_fused));
  refused_.add(now, double(in.frames_refused));
  HealthReport r;
  r.message = "map updated";
  const double map_age = in.depth_arrival_s >= 0.0 ? now - in.depth_arrival_s : kNaN;
  if (in.depth_arrival_s < 0.0) {
    r.raise(HealthLevel::kWarn, "no depth frame yet");
  } else if (map_age > config_.stale_s) {
    char text[96];
    std::snprintf(text, sizeof(text), "no depth frame for %.2f s (limit %.2f s): the map is not updated", map_age,
                  config_.stale_s);
    r.raise(HealthLevel::kError, text);
  }
  const double refused = refused_.increase();
  if (refused > 0.0)
    r.raise(HealthLevel::kWarn, std::to_string(int64_t(refused)) + " depth frames refused in the last " +
                                    std::to_string(int(config_.window_s)) + " s");
  r.add("depth frames fused", double(in.frames_fused), 0);
  r.add("depth frames refused", double(in.frames_refused), 0);
  r.add("fusion rate [Hz]", fused_.increasePerSecond(), 2);
  r.add("refusal rate [Hz]", refused_.increasePerSecond(), 2);
  r.add("map age [s]", map_age);
  r.add("depth stamp age [s]", in.depth_stamp_s >= 0.0 ? now - in.depth_stamp_s : kNaN);
  r.add("pose age [s]", in.pose_arrival_s >= 0.0 ? now - in.pose_arrival_s : kNaN);
  r.add("last fusion [ms]", in.last_fusion_ms, 2);
  r.add("last ESDF update [ms]", in.last_esdf_ms, 2);
  return r;
}

}  // namespace topo_planner
