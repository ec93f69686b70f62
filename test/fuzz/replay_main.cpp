// Replays a fuzz harness's corpus and regression inputs as a gtest (make test): every file of the
// TOPO_PLANNER_FUZZ_CORPUS_DIR and TOPO_PLANNER_FUZZ_REGRESSION_DIR (folders set at compile time) goes through
// the harness's LLVMFuzzerTestOneInput once, in name order. A crash, a sanitizer report (in the
// sanitizer builds) or a violated property (TOPO_PLANNER_FUZZ_CHECK aborts) fails the test.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

std::vector<std::string> replayDirs() { return {TOPO_PLANNER_FUZZ_CORPUS_DIR, TOPO_PLANNER_FUZZ_REGRESSION_DIR}; }

std::vector<std::filesystem::path> filesIn(const std::string& dir) {
  std::vector<std::filesystem::path> files;
  if (!std::filesystem::is_directory(dir)) return files;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

TEST(FuzzReplay, CorpusAndRegressions) {
  size_t replayed = 0;
  for (const std::string& dir : replayDirs()) {
    for (const auto& path : filesIn(dir)) {
      std::ifstream in(path, std::ios::binary);
      ASSERT_TRUE(in.good()) << path;
      const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      SCOPED_TRACE(path.string());
      EXPECT_EQ(LLVMFuzzerTestOneInput(bytes.data(), bytes.size()), 0) << path;
      ++replayed;
    }
  }
  // The corpus folder always holds seeds: an empty replay means a wrong path, not a pass.
  EXPECT_GT(replayed, 0u) << "no input found in " << TOPO_PLANNER_FUZZ_CORPUS_DIR;
  RecordProperty("inputs", int(replayed));
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
