// What readPointCloud and writePointCloud do for every format alike: dispatch on the extension, concurrent reads,
// missing, empty, garbage, truncated and mutated files, and writes that must be refused or fail cleanly.

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "IoTestSupport.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace fs = std::filesystem;
using namespace hpds;
using hpds::test::ScratchDir;
using hpds::test::expectError;
using hpds::test::makeAllTypesCloud;
using hpds::test::readBytes;
using hpds::test::writeBytes;
using hpds::test::xyzLayout;
using hpds::test::xyzPcdHeader;

namespace {

// Reads a file that may be valid or not: either outcome is fine, anything else (crash, other exception) is not.
void readSurvives(const std::string &path) {
  try {
    const PointBuffer cloud = readPointCloud(path);
    EXPECT_TRUE(cloud.layout().find("x"));
  } catch (const std::runtime_error &e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

}  // namespace

TEST(WritePointCloud, DispatchesOnExtension) {
  const ScratchDir scratch("io_dispatch");
  const fs::path &dir = scratch.path;
  const PointBuffer src = makeAllTypesCloud(9, 3);
  for (const char *name : {"a.pcd", "a.ply", "a.bin"}) {
    const std::string path = (dir / name).string();
    writePointCloud(path, src);
    EXPECT_EQ(readPointCloud(path).size(), 9u) << name;
  }
  expectError([&] { writePointCloud((dir / "a.las").string(), src); }, "a.las", {"unsupported extension"});
  expectError([&] { writePcd((dir / "no_such_dir" / "a.pcd").string(), src); }, "a.pcd", {"directory"});
  expectError([&] { writePly((dir / "no_such_dir" / "a.ply").string(), src); }, "a.ply",
              {"cannot create a temporary file beside it"});
}

TEST(ReadPointCloud, ConcurrentReadsOfEveryFormat) {
  const ScratchDir scratch("io_threads");
  const PointBuffer src = makeAllTypesCloud(500, 17);
  std::vector<std::string> paths;
  for (const char *name : {"a.pcd", "a.ply", "a.bin"}) {
    paths.push_back((scratch.path / name).string());
    writePointCloud(paths.back(), src);
  }
  paths.push_back((scratch.path / "missing.pcd").string());  // failing reads run concurrently too
  std::vector<std::thread> threads;
  std::atomic<int> good{0}, failed{0};
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int k = 0; k < 20; ++k) {
        try {
          good += readPointCloud(paths[(t + k) % paths.size()]).size() == 500;
        } catch (const std::runtime_error &) {
          ++failed;
        }
      }
    });
  for (auto &th : threads) th.join();
  EXPECT_EQ(good.load(), 60);
  EXPECT_EQ(failed.load(), 20);
}

// ---------------------------------------------------------------------------------------------------------------------
// Malformed input: always std::runtime_error naming the path, never a crash, hang or huge allocation

TEST(BadInput, MissingEmptyAndUnknownFiles) {
  const ScratchDir scratch("io_bad_basic");
  const fs::path &dir = scratch.path;
  for (const char *name : {"missing.pcd", "missing.ply", "missing.bin"})
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, {"file not found"});
  for (const char *name : {"empty.pcd", "empty.ply", "empty.bin"}) {
    writeBytes(dir / name, "");
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, {"empty"});
  }
  writeBytes(dir / "cloud.xyz", "1 2 3\n");
  expectError([&] { (void)readPointCloud((dir / "cloud.xyz").string()); }, "cloud.xyz", {"unsupported extension"});
  writeBytes(dir / "noext", "1 2 3\n");
  expectError([&] { (void)readPointCloud((dir / "noext").string()); }, "noext", {"unsupported extension"});
  fs::create_directories(dir / "dir.pcd");
  expectError([&] { (void)readPointCloud((dir / "dir.pcd").string()); }, "dir.pcd", {"not a regular file"});
  // A path without a point-cloud extension that is not a file at all (a folder of frames, a mistyped name) says
  // so, not that its extension '(none)' is unsupported.
  fs::create_directories(dir / "frames");
  expectError([&] { (void)readPointCloud((dir / "frames").string()); }, "frames", {"not a regular file"});
  expectError([&] { (void)readPointCloud((dir / "no_such_frame").string()); }, "no_such_frame", {"file not found"});
  writeBytes(dir / "odd.bin", std::string(17, '\0'));
  expectError([&] { (void)readPointCloud((dir / "odd.bin").string()); }, "odd.bin", {"17", "multiple of 16"});
}

TEST(BadInput, GarbageBytesNeverCrash) {
  const ScratchDir scratch("io_bad_garbage");
  const fs::path &dir = scratch.path;
  for (std::uint32_t seed = 1; seed <= 12; ++seed) {
    std::mt19937 rng(seed);
    std::string bytes(1 + rng() % 5000, '\0');
    for (char &c : bytes) c = static_cast<char>(rng());
    for (const char *ext : {".pcd", ".ply"}) {
      const std::string name = "garbage" + std::to_string(seed) + ext;
      writeBytes(dir / name, bytes);
      expectError([&] { (void)readPointCloud((dir / name).string()); }, name,
                  {std::string("not a ") + (ext[1] == 'p' && ext[2] == 'c' ? "PCD" : "PLY") + " file"});
    }
    // Garbage behind a valid magic line gets past the first check but must still be refused.
    writeBytes(dir / "magic.ply", "ply\n" + bytes);
    expectError([&] { (void)readPointCloud((dir / "magic.ply").string()); }, "magic.ply");
    writeBytes(dir / "magic.pcd", "# .PCD v0.7\nVERSION 0.7\n" + bytes);
    expectError([&] { (void)readPointCloud((dir / "magic.pcd").string()); }, "magic.pcd");
  }
  writeBytes(dir / "text.pcd", "hello world\n");
  expectError([&] { (void)readPointCloud((dir / "text.pcd").string()); }, "text.pcd", {"not a PCD file"});
  writeBytes(dir / "isply.pcd", "ply\nformat ascii 1.0\n");
  expectError([&] { (void)readPointCloud((dir / "isply.pcd").string()); }, "isply.pcd", {"not a PCD file"});
}

TEST(BadInput, EveryTruncationAndHeaderMutationIsHandled) {
  const ScratchDir scratch("io_bad_fuzz");
  const fs::path &dir = scratch.path;
  const PointBuffer src = makeAllTypesCloud(20, 5);
  const std::string pcd_path = (dir / "src.pcd").string();
  const std::string ply_path = (dir / "src.ply").string();
  writePcd(pcd_path, src);
  writePly(ply_path, src);
  writeBytes(dir / "ascii_src.pcd", xyzPcdHeader(3, "ascii") + "1 2 3\n4 5 6\n7 8 9\n");
  // A lone colour channel: read by hpds's own PLY reader rather than PCL's.
  PointLayout red_layout = src.layout();
  red_layout.append("red", FieldType::UInt8);
  PointBuffer red(red_layout, src.size());
  for (std::size_t i = 0; i < src.size(); ++i) std::memcpy(red.record(i), src.record(i), src.layout().point_step);
  writePly((dir / "red_src.ply").string(), red);
  for (const std::string &name :
       {std::string("src.pcd"), std::string("src.ply"), std::string("ascii_src.pcd"), std::string("red_src.ply")}) {
    const std::string original = readBytes(dir / name);
    const std::string ext = fs::path(name).extension().string();
    // Every cut through the header and a sample of cuts through the body.
    // An ASCII file cut just before its final newline is still complete.
    const std::size_t end = ext == ".pcd" && name.rfind("ascii", 0) == 0 ? original.size() - 1 : original.size();
    for (std::size_t len = 1; len < end; len += (len < 1200 ? 1 : 97)) {
      SCOPED_TRACE(name + " cut to " + std::to_string(len) + " of " + std::to_string(original.size()) + " bytes");
      const std::string cut = "cut" + ext;
      writeBytes(dir / cut, original.substr(0, len));
      expectError([&] { (void)readPointCloud((dir / cut).string()); }, cut);
    }
    // Random byte mutations inside the header: may read or fail, must never crash.
    const std::size_t header_end = std::min<std::size_t>(original.size(), 600);
    std::mt19937 rng(99);
    const char interesting[] = {'0', '9', ' ', '\n', '\r', '-', 'x', '\0', '\xff', '#', '_'};
    for (int trial = 0; trial < 300; ++trial) {
      std::string mutated = original;
      for (int k = 0; k < 1 + trial % 3; ++k)
        mutated[rng() % header_end] = trial % 2 ? interesting[rng() % sizeof interesting] : static_cast<char>(rng());
      const std::string mut = "mut" + ext;
      writeBytes(dir / mut, mutated);
      readSurvives((dir / mut).string());
    }
  }
}

// ---------------------------------------------------------------------------------------------------------------------
// Writers refuse what no reader could read back, and failed writes leave nothing behind

// A field's count becomes that many PLY properties; fuzz_cloud_conversion found writePly spending hours on a (0-point)
// cloud declaring 4e9. Writers refuse counts beyond what the readers accept (2^20), at once.
TEST(WritePointCloud, FieldCountsBeyondTheReadersLimitAreRefusedAtOnce) {
  const ScratchDir scratch("io_write_count");
  const fs::path &dir = scratch.path;
  auto cloudWithCount = [](std::uint32_t count) {
    // Laid out by hand: PointLayout::append refuses such counts itself (a PointBuffer may still be handed one).
    PointLayout layout = xyzLayout();
    layout.fields.push_back(PointField{"f", layout.point_step, FieldType::UInt8, count});
    layout.point_step += count;
    return PointBuffer(layout, 0);
  };
  for (const char *name : {"huge.ply", "huge.pcd"}) {
    const auto t0 = std::chrono::steady_clock::now();
    expectError([&] { writePointCloud((dir / name).string(), cloudWithCount(4000000000u)); }, name,
                {"field 'f'", "count 4000000000", "1048576"});
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
    expectError([&] { writePointCloud((dir / name).string(), cloudWithCount((1u << 20) + 1)); }, name,
                {"count 1048577"});
    EXPECT_FALSE(fs::exists(dir / name));
  }
  // At the limit PCD writes and reads back; PLY (one property per element) would pass the property limit readers
  // apply, so it is refused too rather than written unreadable; so is a header beyond 1 MiB.
  writePcd((dir / "limit.pcd").string(), cloudWithCount(1u << 20));
  EXPECT_EQ(readPointCloud((dir / "limit.pcd").string()).layout().find("f")->count, 1u << 20);
  expectError([&] { writePly((dir / "limit.ply").string(), cloudWithCount(1u << 20)); }, "limit.ply",
              {"more than 8192 properties"});
  PointLayout long_name = xyzLayout();
  long_name.append(std::string(1 << 20, 'n'), FieldType::UInt8);
  expectError([&] { writePly((dir / "long.ply").string(), PointBuffer(long_name, 1)); }, "long.ply",
              {"header would exceed 1048576 bytes"});
  // Below the header limit a vector field still round-trips through PLY as numbered properties.
  writePly((dir / "ok.ply").string(), cloudWithCount(1000));
  EXPECT_NE(readPointCloud((dir / "ok.ply").string()).layout().find("f_999"), nullptr);
}

// A failed write removes the partial file, but never what a path only leads to: writing through a link to a full
// device fails with "write failed", and both the link and the device are left alone.
TEST(WritePointCloud, FailedWritesRemoveOnlyRegularFiles) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const ScratchDir scratch("io_write_full");
  const fs::path &dir = scratch.path;
  PointLayout layout = xyzLayout();
  const PointBuffer cloud(layout, 100);
  const std::vector<std::pair<std::string, std::function<void(const std::string &)>>> writers = {
      {"a.ply", [&](const std::string &p) { writePly(p, cloud); }},
      {"a.pcd", [&](const std::string &p) { writePcd(p, cloud); }},
      {"a.bin", [&](const std::string &p) { writeKittiBin(p, cloud); }},
      {"poses.txt", [&](const std::string &p) { writeKittiPoses(p, {Eigen::Isometry3d::Identity()}); }},
  };
  for (const auto &[name, write] : writers) {
    SCOPED_TRACE(name);
    const fs::path link = dir / name;
    fs::create_symlink("/dev/full", link);
    expectError([&] { write(link.string()); }, name, {"write failed"});
    EXPECT_TRUE(fs::is_symlink(link));
    EXPECT_TRUE(fs::exists("/dev/full"));
  }
}
