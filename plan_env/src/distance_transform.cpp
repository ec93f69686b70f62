#include "topo_planner/plan_env/distance_transform.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

void lowerEnvelopeTransform(const int32_t* f, int32_t* d, int n, int32_t* v, int64_t* zn, int64_t* zd) {
  // Lower envelope of the parabolas y = (x - p)^2 + f[p]. Parabola k is lowest on
  // [zn[k]/zd[k], zn[k+1]/zd[k+1]); the first one from -infinity.
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] >= kNoSite) continue;
    const int64_t hq = int64_t(f[q]) + int64_t(q) * q;
    int64_t num = 0, den = 1;
    while (k >= 0) {
      const int p = v[k];
      num = hq - (int64_t(f[p]) + int64_t(p) * p);
      den = 2 * int64_t(q - p);
      // Pop parabola k while the new one is lower from its start on: num/den <= zn[k]/zd[k].
      if (k > 0 && num * zd[k] <= zn[k] * den) {
        --k;
        continue;
      }
      break;
    }
    ++k;
    v[k] = q;
    zn[k] = num;  // unused for k == 0
    zd[k] = den;
  }
  if (k < 0) {
    std::fill(d, d + n, kNoSite);
    return;
  }
  const int last = k;
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (k < last && zn[k + 1] < int64_t(q) * zd[k + 1]) ++k;
    const int64_t dq = q - v[k];
    d[q] = int32_t(std::min<int64_t>(dq * dq + f[v[k]], kNoSite));
  }
}

void binaryLineTransform(const uint8_t* site, int32_t* d, int n, int32_t cap) {
  // Distance in cells to the nearest site: forward sweep, then backward sweep, then squared.
  constexpr int kFar = 1 << 20;
  int last = -kFar;
  for (int i = 0; i < n; ++i) {
    if (site[i]) last = i;
    d[i] = i - last;
  }
  last = n + kFar;
  for (int i = n - 1; i >= 0; --i) {
    if (site[i]) last = i;
    const int64_t r = std::min(d[i], last - i);
    const int64_t r2 = r * r;
    d[i] = r2 >= cap ? kNoSite : int32_t(r2);
  }
}

void binaryLineTransformPair(const uint8_t* site, float* pos, float* neg, int n, int32_t cap) {
  // Forward sweep: distance to the last site / non-site seen; backward sweep: the next one.
  constexpr int kFar = 1 << 20;
  int last_site = -kFar, last_free = -kFar;
  for (int i = 0; i < n; ++i) {
    if (site[i]) {
      last_site = i;
    } else {
      last_free = i;
    }
    pos[i] = float(i - last_site);
    neg[i] = float(i - last_free);
  }
  int next_site = n + kFar, next_free = n + kFar;
  const float fcap = float(cap);
  for (int i = n - 1; i >= 0; --i) {
    if (site[i]) {
      next_site = i;
    } else {
      next_free = i;
    }
    const float p = std::min(pos[i], float(next_site - i));
    const float q = std::min(neg[i], float(next_free - i));
    pos[i] = p * p < fcap ? p * p : INFINITY;
    neg[i] = q * q < fcap ? q * q : INFINITY;
  }
}

void boundedLineTransform(const int32_t* f, int32_t* d, int n, int32_t cap) {
  for (int q = 0; q < n; ++q) {
    int32_t best = std::min(f[q], cap);
    for (int r = 1; r * r < best; ++r) {
      const int32_t r2 = r * r;
      if (q - r >= 0) best = std::min(best, r2 + f[q - r]);
      if (q + r < n) best = std::min(best, r2 + f[q + r]);
    }
    d[q] = best;
  }
}

}  // namespace topo_planner
