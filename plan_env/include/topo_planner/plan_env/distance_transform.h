#pragma once
// 1-D squared Euclidean distance transforms on integer squared distances (in voxels^2), after
// Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions", Theory of Computing 8
// (2012). Applied along x, y and z in turn they give the exact 3-D squared Euclidean distance
// transform in time linear in the number of voxels. Squared voxel distances are integers, so the
// parabola intersections are compared exactly by cross-multiplication, with no division.

#include <cstdint>

namespace topo_planner {

/// "No site on this line": larger than any squared distance of a grid that fits in memory.
constexpr int32_t kNoSite = int32_t(1) << 30;

/// d[q] = min_p (q - p)^2 + f[p] over the samples with f[p] < kNoSite, for q in [0, n); kNoSite
/// when there are none. Scratch: v (n ints), zn and zd (n + 1 each). f and d may not alias.
void lowerEnvelopeTransform(const int32_t* f, int32_t* d, int n, int32_t* v, int64_t* zn, int64_t* zd);

/// Squared distance along a line of n cells to the nearest cell with site[i] != 0 (kNoSite if
/// none, and for distances of `cap` or more).
void binaryLineTransform(const uint8_t* site, int32_t* d, int n, int32_t cap);

/// Both fields of a site line in one go, as floats: pos[i] = squared distance to the nearest site,
/// neg[i] = to the nearest non-site; +inf when there is none closer than sqrt(cap) cells.
void binaryLineTransformPair(const uint8_t* site, float* pos, float* neg, int n, int32_t cap);

/// d[q] = min(lowerEnvelopeTransform(f)[q], cap), by a search around each sample that stops once
/// (q - p)^2 reaches the best value. Linear-time when values are small, as in the negative field,
/// where most samples are 0 and the rest are near a 0; a sample with f[q] == 0 costs nothing.
void boundedLineTransform(const int32_t* f, int32_t* d, int n, int32_t cap);

}  // namespace topo_planner
