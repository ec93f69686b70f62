// PCD point clouds (ASCII, binary, binary_compressed) through readMapFile and insertMapFile; the
// input is the file.
#include "map_file_harness.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return topo_planner::fuzz::fuzzMapFile(data, size, "pcd");
}
