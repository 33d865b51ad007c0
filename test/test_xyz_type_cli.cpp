// The type of the output's x y z through `hpds sample`: float32 from float64 input when asked (output.float32_xyz,
// --float32-xyz), and a rounding warning that gives the advice that helps: float64 output when the output's float32
// lost the digits, a local frame when the input's own float32 never had them.
#include <gtest/gtest.h>

#include <array>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "HostileTestSupport.hpp"
#include "TestData.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;
using test::typedCloud;
using test::writeText;

std::string q(const fs::path &p) { return "'" + p.string() + "'"; }
int hpds(const std::string &args, std::string *out = nullptr) {
  return test::runCommand(test::cliPath() + " " + args, out);
}
FieldType xType(const fs::path &ply) { return readPointCloud(ply.string()).layout().find("x")->type; }

// 20 000 points in a 20 m square about `origin`.
std::vector<std::array<double, 3>> patchAt(const std::array<double, 3> &origin) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 20.0);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < 20000; ++i) pts.push_back({origin[0] + u(rng), origin[1] + u(rng), origin[2] + 0.05 * u(rng)});
  return pts;
}

// Found with an Open3D PLY (`property double x`): the output's x y z were float64 whatever the config said, and PCL's
// fromPCLPointCloud2 into pcl::PointXYZ refuses float64 fields, so such a cloud could not be read back as one.
TEST(XyzTypeCli, Float64InputGivesFloat32OutputWhenAsked) {
  const auto tmp = test::scratchDir("xyz_float32");
  const fs::path local = tmp / "local_f8.pcd", utm = tmp / "utm_f8.pcd";
  writePcd(local.string(), typedCloud(FieldType::Float64, patchAt({0.0, 0.0, 1.0})));
  writePcd(utm.string(), typedCloud(FieldType::Float64, patchAt({5e6, 4e6, 100.0})));
  const std::string sample = "sample " + q(local) + " --spacing 0.1 --no-normals -o ";
  std::string log;
  // The default keeps the input's digits.
  ASSERT_EQ(hpds(sample + q(tmp / "default.ply"), &log), 0) << log;
  EXPECT_EQ(xType(tmp / "default.ply"), FieldType::Float64);
  // The flag and the key give float32, which verifies (local coordinates lose nothing that matters).
  ASSERT_EQ(hpds(sample + q(tmp / "flag.ply") + " --float32-xyz", &log), 0) << log;
  EXPECT_EQ(xType(tmp / "flag.ply"), FieldType::Float32);
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  EXPECT_EQ(hpds("verify " + q(tmp / "flag.ply") + " --spacing 0.1 --input " + q(local), &log), 0) << log;
  writeText(tmp / "f32.yaml", "output: {float32_xyz: true}\n");
  ASSERT_EQ(hpds(sample + q(tmp / "key.ply") + " --config " + q(tmp / "f32.yaml"), &log), 0) << log;
  EXPECT_EQ(xType(tmp / "key.ply"), FieldType::Float32);
  // A flag overrides the config's choice; both flags, or both keys, contradict each other.
  ASSERT_EQ(hpds(sample + q(tmp / "override.ply") + " --config " + q(tmp / "f32.yaml") + " --float64-xyz", &log), 0)
      << log;
  EXPECT_EQ(xType(tmp / "override.ply"), FieldType::Float64);
  EXPECT_EQ(hpds(sample + q(tmp / "both.ply") + " --float32-xyz --float64-xyz", &log), 2) << log;
  EXPECT_NE(log.find("--float64-xyz and --float32-xyz contradict each other"), std::string::npos) << log;
  writeText(tmp / "both.yaml", "output: {float32_xyz: true, float64_xyz: true}\n");
  EXPECT_EQ(hpds(sample + q(tmp / "both.ply") + " --config " + q(tmp / "both.yaml"), &log), 1) << log;
  EXPECT_NE(log.find("output.float32_xyz: cannot go with output.float64_xyz: true"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(tmp / "both.ply"));
  // At UTM coordinates float32 rounds: the warning still comes, and its advice replaces the flag given.
  ASSERT_EQ(hpds("sample " + q(utm) + " --spacing 0.1 --no-normals --float32-xyz -o " + q(tmp / "utm.ply"), &log), 0)
      << log;
  EXPECT_EQ(xType(tmp / "utm.ply"), FieldType::Float32);
  EXPECT_NE(log.find("the output's float32 x y z round positions"), std::string::npos) << log;
  EXPECT_NE(log.find("--float64-xyz instead of --float32-xyz"), std::string::npos) << log;
}

// Found sampling a float32 PCD at UTM coordinates: the warning advised --float64-xyz, which wrote the same rounded
// values in wider fields; the digits were lost when the input was written.
TEST(XyzTypeCli, Float32InputAtLargeCoordinatesIsSaidToHaveLostItsDigits) {
  const auto tmp = test::scratchDir("xyz_input_f32");
  const fs::path utm = tmp / "utm_f4.pcd";
  writePcd(utm.string(), typedCloud(FieldType::Float32, patchAt({5e6, 4e6, 100.0})));
  for (const std::string &flags : {std::string(), std::string(" --float64-xyz")}) {
    SCOPED_TRACE(flags);
    std::string log;
    ASSERT_EQ(hpds("sample " + q(utm) + " --spacing 0.1 --no-normals -o " + q(tmp / "o.ply") + flags, &log), 0) << log;
    EXPECT_NE(log.find("the input's own float32 x y z round positions by up to"), std::string::npos) << log;
    EXPECT_NE(log.find("float64 output cannot restore them"), std::string::npos) << log;
    EXPECT_NE(log.find("local frame"), std::string::npos) << log;
    EXPECT_EQ(log.find("set output.float64_xyz"), std::string::npos) << log;
  }
  // The same points in a local float32 frame, posed into UTM: the output's float32 is what rounds, and float64 output
  // is the advice (HostileCli.GeoreferencedCoordinatesKeepTheirPrecisionOrAreSaidToLoseIt checks that it helps).
  std::vector<std::array<double, 3>> local = patchAt({0.0, 0.0, 0.0});
  writePcd((tmp / "local_f4.pcd").string(), typedCloud(FieldType::Float32, local));
  writeText(tmp / "poses.txt", "1 0 0 5000000 0 1 0 4000000 0 0 1 100\n");
  // Found by a user's posed UTM drive: the map came out float32, rounded by 0.3 m, and failed verify. Poses that far
  // out now give float64 x y z, said once; --float32-xyz keeps float32 and gets the warning.
  const std::string posed = "sample " + q(tmp / "local_f4.pcd") + " --poses " + q(tmp / "poses.txt") +
                            " --mode map --spacing 0.1 --no-normals -o ";
  std::string log;
  ASSERT_EQ(hpds(posed + q(tmp / "posed.ply"), &log), 0) << log;
  EXPECT_EQ(xType(tmp / "posed.ply"), FieldType::Float64);
  EXPECT_NE(log.find("hpds: note: x y z are written as float64: the poses' coordinates reach 5e+06 m"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("set --float32-xyz for a reader that takes float32 only"), std::string::npos) << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  EXPECT_EQ(hpds("verify " + q(tmp / "posed.ply") + " --spacing 0.1", &log), 0) << log;
  ASSERT_EQ(hpds(posed + q(tmp / "posed_f4.ply") + " --float32-xyz", &log), 0) << log;
  EXPECT_EQ(xType(tmp / "posed_f4.ply"), FieldType::Float32);
  EXPECT_NE(log.find("set output.float64_xyz: true instead of output.float32_xyz"), std::string::npos) << log;
  EXPECT_EQ(log.find("the input's own"), std::string::npos) << log;
  EXPECT_EQ(log.find("note:"), std::string::npos) << log;
  // Poses near the origin change nothing: the input's type stays.
  writeText(tmp / "near.txt", "1 0 0 500 0 1 0 400 0 0 1 10\n");
  ASSERT_EQ(hpds("sample " + q(tmp / "local_f4.pcd") + " --poses " + q(tmp / "near.txt") +
                     " --spacing 0.1 --no-normals -o " + q(tmp / "near.ply"),
                 &log),
            0)
      << log;
  EXPECT_EQ(xType(tmp / "near.ply"), FieldType::Float32);
  EXPECT_EQ(log.find("note:"), std::string::npos) << log;
}

// Found on a KITTI .bin with a few 3e38 outliers: they were dropped as out of range, yet the warning said the input's
// float32 rounded positions by up to 1.8e31 m, for an output that was fine.
TEST(XyzTypeCli, DroppedOutliersDoNotMakeARoundingWarning) {
  const auto tmp = test::scratchDir("xyz_outliers");
  std::vector<std::array<double, 3>> pts = patchAt({0.0, 0.0, 1.0});
  pts.push_back({3e38, 1.0, 1.0});
  pts.push_back({1.0, -3e38, 1.0});
  writePcd((tmp / "outliers.pcd").string(), typedCloud(FieldType::Float32, pts));
  std::string log;
  ASSERT_EQ(hpds("sample " + q(tmp / "outliers.pcd") + " --spacing 0.1 --no-normals -o " + q(tmp / "o.ply"), &log), 0)
      << log;
  EXPECT_EQ(log.find("round positions"), std::string::npos) << log;
  EXPECT_NE(log.find("beyond the exact key range"), std::string::npos) << log;
}

}  // namespace
}  // namespace hpds
