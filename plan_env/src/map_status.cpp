#include "topo_planner/plan_env/map_status.h"

namespace topo_planner {

const char* toString(MapStatus status) {
  switch (status) {
    case MapStatus::kSuccess: return "success";
    case MapStatus::kInvalidConfig: return "invalid config";
    case MapStatus::kTooLarge: return "map too large for the memory budget";
    case MapStatus::kInvalidPose: return "invalid sensor pose (NaN/inf or non-orthonormal rotation)";
    case MapStatus::kInvalidIntrinsics: return "invalid camera intrinsics";
    case MapStatus::kEmptyImage: return "empty image";
    case MapStatus::kImageSizeMismatch: return "image size does not match the intrinsics or row step";
    case MapStatus::kImageTooLarge: return "image larger than the configured maximum";
    case MapStatus::kNoValidData: return "no valid depth or point in the input";
    case MapStatus::kOutOfMap: return "sensor data does not intersect the map";
    case MapStatus::kFileNotFound: return "file not found";
    case MapStatus::kParseError: return "file could not be parsed";
    case MapStatus::kWriteError: return "file could not be written";
  }
  return "unknown status";
}

const char* toString(QueryStatus status) {
  switch (status) {
    case QueryStatus::kOk: return "ok";
    case QueryStatus::kUnknown: return "unknown space";
    case QueryStatus::kOutOfMap: return "out of map";
    case QueryStatus::kInvalidInput: return "invalid query (NaN/inf)";
  }
  return "unknown status";
}

}  // namespace topo_planner
