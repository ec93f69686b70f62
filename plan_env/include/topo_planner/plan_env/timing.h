#pragma once
// Wall-clock timing and percentiles for benchmarks and run-time statistics (never for decisions
// in tests: those use counts).

#include <algorithm>
#include <chrono>
#include <vector>

namespace topo_planner {

/// Milliseconds on a monotonic clock.
inline double nowMs() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// The q-quantile (0 = min, 0.5 = median, 1 = max) by nearest rank; 0 for no samples.
inline double percentile(std::vector<double> samples, double q) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const double rank = std::clamp(q, 0.0, 1.0) * double(samples.size() - 1) + 0.5;
  return samples[std::min(samples.size() - 1, size_t(rank))];
}

}  // namespace topo_planner
