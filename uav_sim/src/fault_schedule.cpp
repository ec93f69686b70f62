#include "topo_planner/uav_sim/fault_schedule.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace topo_planner {

namespace {

bool inAny(const std::vector<FaultSchedule::Window>& windows, double t) {
  for (const FaultSchedule::Window& w : windows)
    if (t >= w.start_s && t < w.end_s) return true;
  return false;
}

std::string fmt(double x, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", digits, x);
  return buf;
}

std::string fmtVector(const Eigen::Vector3d& v, int digits) {
  return "(" + fmt(v.x(), digits) + ", " + fmt(v.y(), digits) + ", " + fmt(v.z(), digits) + ")";
}

bool windowsFromList(const std::vector<double>& list, const char* name, std::vector<FaultSchedule::Window>* out,
                     std::ostringstream& err) {
  if (list.size() % 2 != 0) {
    err << name << " must hold [start, end] pairs (" << list.size() << " numbers given); ";
    return false;
  }
  for (size_t i = 0; i < list.size(); i += 2) out->push_back({list[i], list[i + 1]});
  return true;
}

}  // namespace

const char* FaultSchedule::toString(Kind kind) {
  switch (kind) {
    case Kind::kDepthBlackout: return "depth_blackout";
    case Kind::kOdomBlackout: return "odom_blackout";
    case Kind::kOdomJump: return "odom_jump";
    case Kind::kClockStep: return "clock_step";
  }
  return "unknown";
}

const char* FaultSchedule::toString(Event::Phase phase) {
  switch (phase) {
    case Event::Phase::kStart: return "start";
    case Event::Phase::kEnd: return "end";
    case Event::Phase::kStep: return "step";
  }
  return "unknown";
}

bool FaultSchedule::empty() const {
  return depth_blackouts.empty() && odom_blackouts.empty() && odom_jumps.empty() && clock_steps.empty();
}

bool FaultSchedule::validate(double clock_start_s, std::string* why) const {
  std::ostringstream err;
  auto time_ok = [](double t) { return std::isfinite(t) && t >= 0.0 && t <= 1e6; };
  for (const auto* list : {&depth_blackouts, &odom_blackouts}) {
    const char* name = list == &depth_blackouts ? "depth_blackouts_s" : "odom_blackouts_s";
    for (const Window& w : *list)
      if (!(time_ok(w.start_s) && time_ok(w.end_s) && w.start_s < w.end_s)) {
        err << name << ": every window needs 0 <= start < end <= 1e6 s; ";
        break;
      }
  }
  for (const OdomJump& j : odom_jumps)
    if (!time_ok(j.t_s) || !j.offset_m.allFinite() || j.offset_m.norm() > 1e3) {
      err << "odom_jumps: every jump needs a time in [0, 1e6] s and a finite offset below 1 km; ";
      break;
    }
  bool steps_ok = true;
  for (const ClockStep& c : clock_steps)
    if (!time_ok(c.t_s) || !std::isfinite(c.step_s) || std::abs(c.step_s) > 1e6) {
      err << "clock_steps: every step needs a time in [0, 1e6] s and a finite size; ";
      steps_ok = false;
      break;
    }
  if (steps_ok)
    for (const ClockStep& c : clock_steps)
      if (!(clock_start_s + c.t_s + clockOffset(c.t_s) > 1e-3)) {
        err << "clock_steps: the step at " << c.t_s << " s takes the ROS time to "
            << clock_start_s + c.t_s + clockOffset(c.t_s) << " s (must stay positive); ";
        break;
      }
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool FaultSchedule::depthBlackout(double t_s) const { return inAny(depth_blackouts, t_s); }
bool FaultSchedule::odomBlackout(double t_s) const { return inAny(odom_blackouts, t_s); }

Eigen::Vector3d FaultSchedule::odomOffset(double t_s) const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const OdomJump& j : odom_jumps)
    if (j.t_s <= t_s) sum += j.offset_m;
  return sum;
}

double FaultSchedule::clockOffset(double t_s) const {
  double sum = 0.0;
  for (const ClockStep& c : clock_steps)
    if (c.t_s <= t_s) sum += c.step_s;
  return sum;
}

std::vector<FaultSchedule::Event> FaultSchedule::eventsIn(double t0_s, double t1_s) const {
  std::vector<Event> events;
  auto inside = [&](double t) { return t > t0_s && t <= t1_s; };
  auto windows = [&](const std::vector<Window>& list, Kind kind) {
    for (const Window& w : list) {
      if (inside(w.start_s)) {
        Event e;
        e.t_s = w.start_s;
        e.kind = kind;
        e.phase = Event::Phase::kStart;
        e.end_s = w.end_s;
        events.push_back(e);
      }
      if (inside(w.end_s)) {
        Event e;
        e.t_s = w.end_s;
        e.kind = kind;
        e.phase = Event::Phase::kEnd;
        events.push_back(e);
      }
    }
  };
  windows(depth_blackouts, Kind::kDepthBlackout);
  windows(odom_blackouts, Kind::kOdomBlackout);
  for (const OdomJump& j : odom_jumps)
    if (inside(j.t_s)) {
      Event e;
      e.t_s = j.t_s;
      e.kind = Kind::kOdomJump;
      e.phase = Event::Phase::kStep;
      e.offset_m = j.offset_m;
      events.push_back(e);
    }
  for (const ClockStep& c : clock_steps)
    if (inside(c.t_s)) {
      Event e;
      e.t_s = c.t_s;
      e.kind = Kind::kClockStep;
      e.phase = Event::Phase::kStep;
      e.step_s = c.step_s;
      events.push_back(e);
    }
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    if (a.t_s != b.t_s) return a.t_s < b.t_s;
    return a.phase == Event::Phase::kEnd && b.phase != Event::Phase::kEnd;
  });
  return events;
}

double FaultSchedule::lastEventTime() const {
  double t = 0.0;
  for (const Window& w : depth_blackouts) t = std::max(t, w.end_s);
  for (const Window& w : odom_blackouts) t = std::max(t, w.end_s);
  for (const OdomJump& j : odom_jumps) t = std::max(t, j.t_s);
  for (const ClockStep& c : clock_steps) t = std::max(t, c.t_s);
  return t;
}

bool FaultSchedule::fromLists(const std::vector<double>& depth_blackouts_s, const std::vector<double>& odom_blackouts_s,
                              const std::vector<double>& odom_jumps_list, const std::vector<double>& clock_steps_list,
                              FaultSchedule* schedule, std::string* why) {
  FaultSchedule s;
  std::ostringstream err;
  windowsFromList(depth_blackouts_s, "depth_blackouts_s", &s.depth_blackouts, err);
  windowsFromList(odom_blackouts_s, "odom_blackouts_s", &s.odom_blackouts, err);
  if (odom_jumps_list.size() % 4 != 0) {
    err << "odom_jumps must hold [t, dx, dy, dz] quadruples (" << odom_jumps_list.size() << " numbers given); ";
  } else {
    for (size_t i = 0; i < odom_jumps_list.size(); i += 4)
      s.odom_jumps.push_back(
          {odom_jumps_list[i], Eigen::Vector3d(odom_jumps_list[i + 1], odom_jumps_list[i + 2], odom_jumps_list[i + 3])});
  }
  if (clock_steps_list.size() % 2 != 0) {
    err << "clock_steps must hold [t, step] pairs (" << clock_steps_list.size() << " numbers given); ";
  } else {
    for (size_t i = 0; i < clock_steps_list.size(); i += 2) s.clock_steps.push_back({clock_steps_list[i], clock_steps_list[i + 1]});
  }
  const std::string e = err.str();
  if (why) *why = e.empty() ? "" : e.substr(0, e.size() - 2);
  if (!e.empty()) return false;
  *schedule = s;
  return true;
}

std::string FaultSchedule::describe() const {
  std::vector<std::string> parts;
  for (const Window& w : depth_blackouts)
    parts.push_back("depth blackout [" + fmt(w.start_s, 2) + ", " + fmt(w.end_s, 2) + ") s");
  for (const Window& w : odom_blackouts)
    parts.push_back("odometry blackout [" + fmt(w.start_s, 2) + ", " + fmt(w.end_s, 2) + ") s");
  for (const OdomJump& j : odom_jumps)
    parts.push_back("odometry jump at " + fmt(j.t_s, 2) + " s by " + fmtVector(j.offset_m, 2) + " m");
  for (const ClockStep& c : clock_steps)
    parts.push_back("clock step at " + fmt(c.t_s, 2) + " s by " + (c.step_s >= 0 ? "+" : "") + fmt(c.step_s, 2) + " s");
  if (parts.empty()) return "none";
  std::string out;
  for (size_t i = 0; i < parts.size(); ++i) out += (i ? "; " : "") + parts[i];
  return out;
}

std::string describe(const FaultSchedule::Event& e) {
  std::string s = std::string(FaultSchedule::toString(e.kind)) + " " + FaultSchedule::toString(e.phase) +
                  " t=" + fmt(e.t_s, 3) + " s";
  if (e.kind == FaultSchedule::Kind::kOdomJump) s += " offset=" + fmtVector(e.offset_m, 3) + " m";
  if (e.kind == FaultSchedule::Kind::kClockStep) s += " step=" + fmt(e.step_s, 3) + " s";
  if (e.phase == FaultSchedule::Event::Phase::kStart) s += " until=" + fmt(e.end_s, 3) + " s";
  return s;
}

}  // namespace topo_planner
