#pragma once
// Status values of the mapping core: expected failures are values, not crashes (STYLE.md).

namespace topo_planner {

/// Outcome of a map operation (fusion, loading, saving, creation).
enum class MapStatus {
  kSuccess,
  kInvalidConfig,      ///< a config field is out of range (see the error message)
  kTooLarge,           ///< the map would not fit the configured memory budget
  kInvalidPose,        ///< sensor pose or origin is NaN/inf or its rotation is not orthonormal
  kInvalidIntrinsics,  ///< focal lengths/principal point not finite or not positive
  kEmptyImage,         ///< zero width/height or no pixel data
  kImageSizeMismatch,  ///< image size differs from the intrinsics, or the row step is too short
  kImageTooLarge,      ///< more pixels than OccupancyMap::Config::max_image_pixels
  kNoValidData,        ///< every pixel/point was NaN, inf, zero or out of range; nothing fused
  kOutOfMap,           ///< the sensor rays never intersect the map window
  kFileNotFound,
  kParseError,
  kWriteError,
};

const char* toString(MapStatus status);

/// Outcome of a point or voxel query.
enum class QueryStatus {
  kOk,
  kUnknown,    ///< inside the map but (some of) the voxels involved were never observed
  kOutOfMap,   ///< outside the map window (or too close to its border to interpolate)
  kInvalidInput,  ///< NaN or infinite query point
};

const char* toString(QueryStatus status);

}  // namespace topo_planner
