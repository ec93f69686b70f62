// OctoMap map files (.bt binary and .ot full trees) through readMapFile and insertMapFile. The first
// byte picks the extension (even: .bt, odd: .ot), the rest is the file.
#include "map_file_harness.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  return topo_planner::fuzz::fuzzMapFile(data + 1, size - 1, (data[0] & 1) ? "ot" : "bt");
}
