// Every crash input the fuzzers found (test/regressions/<target>/), replayed through the same entry point the
// fuzzer used.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "HostileTestSupport.hpp"
#include "TestData.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;
using test::frameOf;
using test::readText;
using test::writeText;

// Each file under test/regressions/<target>/ once crashed fuzz_<target>; it must now be refused cleanly or
// accepted (whichever the fix decided), through the same entry point.
TEST(Regressions, EveryFuzzerCrashInputIsHandled) {
  const fs::path root = fs::path(HPDS_SOURCE_DIR) / "test" / "regressions";
  if (!fs::is_directory(root)) GTEST_SKIP() << "no regression inputs";
  const auto tmp = test::scratchDir("regressions");
  std::size_t replayed = 0;
  for (const auto &dir : fs::directory_iterator(root)) {
    if (!dir.is_directory() || dir.path().filename() == "pending") continue;  // pending: see the DISABLED_ test
    const std::string target = dir.path().filename().string();
    for (const auto &entry : fs::directory_iterator(dir.path())) {
      if (!entry.is_regular_file() || entry.path().filename().string().front() == '.' ||
          entry.path().extension() == ".md")
        continue;
      SCOPED_TRACE(entry.path().string());
      const std::string bytes = readText(entry.path());
      ++replayed;
      auto through = [&](const std::string &ext) {
        const fs::path copy = tmp / ("input" + ext);
        writeText(copy, bytes);
        return copy.string();
      };
      try {
        if (target == "pcd" || target == "ply" || target == "kitti_bin") {
          const PointBuffer cloud = readPointCloud(through(target == "kitti_bin" ? ".bin" : "." + target));
          HpdsConfig c;
          c.mode = Mode::Map;
          c.hierarchy.max_depth = 5;
          c.normals.enabled = true;
          Pipeline p(c);
          try {
            p.addFrame(frameOf(cloud));
          } catch (const std::invalid_argument &) {
            continue;  // the pipeline's documented refusal
          }
          (void)p.makeCloud(p.outputSamples(), false);
          // As the fuzzers do: what was read either is refused by writePly or reads back with its point count.
          const std::string ply = (tmp / "roundtrip.ply").string();
          try {
            writePly(ply, cloud);
          } catch (const std::runtime_error &) {
            continue;
          }
          try {
            EXPECT_EQ(readPointCloud(ply).size(), cloud.size());
          } catch (const std::runtime_error &e) {
            ADD_FAILURE() << "writePly wrote a file readPointCloud refuses: " << e.what();
          }
        } else if (target == "poses") {
          (void)readKittiPoses(through(".txt"));
        } else if (target == "config_yaml") {
          try {
            const HpdsConfig c = loadConfigString(bytes);
            Pipeline p(c);
          } catch (const std::invalid_argument &) {
          }
        } else if (target == "map") {
          const LoadedHierarchy l =
              loadHierarchyBytes(reinterpret_cast<const std::uint8_t *>(bytes.data()), bytes.size(), "regression");
          saveHierarchy((tmp / "again.hpdsmap").string(), l.hierarchy, l.next_frame);
          EXPECT_EQ(loadHierarchy((tmp / "again.hpdsmap").string()).hierarchy.sampleCount(), l.hierarchy.sampleCount());
        } else {
          ADD_FAILURE() << "unknown regression target " << target;
        }
      } catch (const std::runtime_error &) {
        // refused with a message: fine
      }
    }
  }
  if (replayed == 0) GTEST_SKIP() << "no regression inputs";
}

}  // namespace
}  // namespace hpds
