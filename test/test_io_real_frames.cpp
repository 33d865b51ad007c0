// The real lidar frames of ../shared/data/lidar: every file reads with its point count and fields, and the VLP-16
// frame's typed fields survive a round trip through every writer. Skipped when the data is absent.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "IoTestSupport.hpp"
#include "TestData.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace fs = std::filesystem;
using namespace hpds;
using hpds::test::ScratchDir;
using hpds::test::expectSameValues;

TEST(RealFrames, EveryFileReadsWithItsPointCountAndFields) {
  HPDS_REQUIRE_SHARED_DATA();
  const fs::path dir = test::sharedLidarDir();
  struct Expect {
    const char *file;
    std::size_t points;
    std::vector<std::string> fields;
  };
  const std::vector<std::string> xyz = {"x", "y", "z"};
  const std::vector<Expect> expected = {
      {"hdl32_a.pcd", 69088, {"x", "y", "z", "intensity"}},
      {"hdl32_b.pcd", 69792, {"x", "y", "z", "intensity"}},
      {"velodyne_vlp16.pcd",
       14831,
       {"x", "y", "z", "intensity", "return_type", "channel", "azimuth", "elevation", "distance", "time_stamp"}},
      {"velodyne_vlp32.pcd", 26216, xyz},
      {"velodyne_vls128.pcd", 208680, xyz},
      {"hesai_xt32.pcd", 63021, xyz},
      {"hesai_64.pcd", 93591, xyz},
      {"hesai_ot128.pcd", 72240, xyz},
  };
  for (const auto &e : expected) {
    SCOPED_TRACE(e.file);
    const PointBuffer cloud = readPointCloud((dir / e.file).string());
    EXPECT_EQ(cloud.size(), e.points);
    EXPECT_EQ(cloud.width(), e.points);
    EXPECT_EQ(cloud.height(), 1u);
    ASSERT_EQ(cloud.layout().fields.size(), e.fields.size());
    for (std::size_t i = 0; i < e.fields.size(); ++i) EXPECT_EQ(cloud.layout().fields[i].name, e.fields[i]);
    std::size_t finite = 0;
    const PointField &x = *cloud.layout().find("x");
    for (std::size_t i = 0; i < cloud.size(); ++i) finite += std::isfinite(readAsDouble(cloud.record(i), x));
    EXPECT_GT(finite, cloud.size() / 2);
  }
}

TEST(RealFrames, Hdl32HasItsNoReturnPointsAtTheOrigin) {
  HPDS_REQUIRE_SHARED_DATA();
  const PointBuffer cloud = readPointCloud((test::sharedLidarDir() / "hdl32_a.pcd").string());
  ASSERT_EQ(cloud.size(), 69088u);
  const PointField &x = *cloud.layout().find("x");
  const PointField &y = *cloud.layout().find("y");
  const PointField &z = *cloud.layout().find("z");
  std::size_t at_origin = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::uint8_t *r = cloud.record(i);
    at_origin += readAsDouble(r, x) == 0.0 && readAsDouble(r, y) == 0.0 && readAsDouble(r, z) == 0.0;
  }
  EXPECT_EQ(at_origin, 5032u);
}

TEST(RealFrames, Vlp16KeepsItsTypedFieldsAndRoundTripsThroughEveryFormat) {
  HPDS_REQUIRE_SHARED_DATA();
  const PointBuffer cloud = readPointCloud((test::sharedLidarDir() / "velodyne_vlp16.pcd").string());
  ASSERT_EQ(cloud.size(), 14831u);
  const PointLayout &l = cloud.layout();
  EXPECT_EQ(l.point_step, 32u);
  EXPECT_EQ(l.find("intensity")->type, FieldType::UInt8);
  EXPECT_EQ(l.find("return_type")->type, FieldType::UInt8);
  EXPECT_EQ(l.find("time_stamp")->type, FieldType::UInt32);
  const PointField &channel = *l.find("channel");
  EXPECT_EQ(channel.type, FieldType::UInt16);
  EXPECT_EQ(channel.offset, 14u);
  std::vector<int> seen(16, 0);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const double c = readAsDouble(cloud.record(i), channel);
    ASSERT_GE(c, 0.0);
    ASSERT_LE(c, 15.0);
    seen[static_cast<int>(c)] = 1;
  }
  EXPECT_GE(std::count(seen.begin(), seen.end(), 1), 12);  // a frame need not hit every ring, but most

  const ScratchDir scratch("io_vlp16");
  const fs::path &dir = scratch.path;
  for (const char *name : {"vlp16.pcd", "vlp16.ply"}) {
    SCOPED_TRACE(name);
    const std::string path = (dir / name).string();
    writePointCloud(path, cloud);
    const PointBuffer back = readPointCloud(path);
    ASSERT_EQ(back.size(), cloud.size());
    for (const PointField &f : l.fields) {
      const PointField *g = back.layout().find(f.name);
      ASSERT_NE(g, nullptr) << f.name;
      EXPECT_EQ(g->type, f.type) << f.name;
      expectSameValues(cloud, f, back, *g);
    }
  }
}
