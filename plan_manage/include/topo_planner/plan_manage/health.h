#pragma once
// Health summaries of the mapping and the planner for /diagnostics (the nodes publish them with
// diagnostic_updater, plan_manage/ros_conversions.h fills a DiagnosticStatus from a HealthReport).
// ROS-free, so the rules are tested without a roscore (test/test_health.cpp).
//
// Mapping (MappingHealth::report):
//   ERROR  no depth frame for stale_s (the map is not updated: the planner refuses goals and stops)
//   WARN   no depth frame yet; frames refused in the window (bad encoding, size, NaN pose, frame)
//   OK     otherwise
//   values: depth frames fused and refused (total, rate in the window), map age, pose age, last
//           fusion and ESDF update times.
// Planner (PlannerHealth::report):
//   ERROR  inputs stale (odometry or depth; the FSM brakes to a hover and plans nothing)
//   WARN   no odometry or no depth frame yet; a mission given up within give_up_hold_s; an emergency stop in the
//          window; more than max_failure_fraction of at least min_calls planning calls failed in it
//   OK     otherwise
//   values: FSM state, input ages, planning calls and failures in the window, their rate, median
//           and maximum planning time, emergency stops and give-ups in total.
//
// Thread-safe: the planner adds events from its planning and safety threads.

#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace topo_planner {

enum class HealthLevel { kOk = 0, kWarn = 1, kError = 2 };
const char* toString(HealthLevel level);

struct HealthReport {
  HealthLevel level = HealthLevel::kOk;
  std::string message;
  std::vector<std::pair<std::string, std::string>> values;

  /// Keeps the worst level; the messages of that level, joined with "; ".
  void raise(HealthLevel l, const std::string& why);
  void add(const std::string& key, const std::string& value);
  void add(const std::string& key, double value, int precision = 3);  // "nan" for a missing value
  /// The value of `key`, or "" without one.
  std::string value(const std::string& key) const;
};

/// Events (time, value) within the last window_s of the latest time seen. A time before the last
/// one (a simulation restart, a clock step back) starts the window afresh.
class EventWindow {
 public:
  explicit EventWindow(double window_s) : window_s_(window_s) {}
  void add(double t, double value = 0.0);
  /// Drops what is older than now - window_s.
  void prune(double now);
  size_t size() const { return events_.size(); }
  double windowSeconds() const { return window_s_; }
  double median() const;  // NaN when empty
  double max() const;     // NaN when empty
  size_t countAbove(double threshold) const;
  /// For samples of a running total: its increase per second over the window (NaN below 2 samples
  /// or no time between them).
  double increasePerSecond() const;
  /// The increase of a running total over the window (0 below 2 samples).
  double increase() const;

 private:
  double window_s_;
  std::deque<std::pair<double, double>> events_;
};

class PlannerHealth {
 public:
  struct Config {
    double window_s = 10.0;              ///< planning calls, failures and stops counted over this [s]
    double max_failure_fraction = 0.5;   ///< WARN above this fraction of failed calls ...
    int min_calls = 5;                   ///< ... out of at least this many
    double give_up_hold_s = 30.0;        ///< a give-up stays a WARN this long [s]
  };
  PlannerHealth() : PlannerHealth(Config()) {}
  explicit PlannerHealth(const Config& config);

  /// A planning call (an FSM event); `published`: its trajectory was published.
  void addPlanningCall(double t, bool published, double total_ms);
  void addEmergencyStop(double t);
  void addGiveUp(double t, const std::string& why);

  struct Inputs {
    std::string state;          ///< the FSM state (toString(FsmState))
    bool have_odometry = false; ///< any odometry so far
    bool inputs_ok = true;      ///< ReplanFsm::inputHealth
    std::string inputs_why;
    double odom_age_s = -1.0, depth_age_s = -1.0;  ///< -1: never
  };
  HealthReport report(double now, const Inputs& in);

 private:
  Config config_;
  std::mutex mutex_;
  EventWindow calls_, failures_, stops_;
  uint64_t published_total_ = 0, calls_total_ = 0, stops_total_ = 0, give_ups_total_ = 0;
  double give_up_t_ = -1.0;
  std::string give_up_why_;
};

class MappingHealth {
 public:
  struct Config {
    double window_s = 5.0;  ///< frame rates and refusals over this [s]
    double stale_s = 0.5;   ///< ERROR when no depth frame reached the map for this long [s]
  };
  MappingHealth() : MappingHealth(Config()) {}
  explicit MappingHealth(const Config& config);

  struct Inputs {
    uint64_t frames_fused = 0, frames_refused = 0;
    double depth_stamp_s = -1.0, depth_arrival_s = -1.0;  ///< -1: never
    double pose_arrival_s = -1.0;
    double last_fusion_ms = 0.0, last_esdf_ms = 0.0;
  };
  /// Called with the mapping's counters (MappingServer::Stats) at each report.
  HealthReport report(double now, const Inputs& in);

 private:
  Config config_;
  std::mutex mutex_;
  EventWindow fused_, refused_;  // (time, total) samples: the window's increase is the rate
};

}  // namespace topo_planner
