// KITTI files: velodyne .bin clouds (any field types converted, intensity defaulted) and pose files (bit-exact
// round trips, KITTI's 7-digit precision made orthonormal), and malformed pose files.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "IoTestSupport.hpp"
#include "TestData.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace fs = std::filesystem;
using namespace hpds;
using hpds::test::ScratchDir;
using hpds::test::expectError;
using hpds::test::expectSameValues;
using hpds::test::sameBits;
using hpds::test::writeBytes;
using hpds::test::xyzLayout;

// ---------------------------------------------------------------------------------------------------------------------
// Round trips

TEST(KittiBin, RoundTripConvertsAnyTypesAndDefaultsIntensity) {
  const ScratchDir scratch("io_kitti");
  const fs::path &dir = scratch.path;
  PointLayout layout;
  layout.append("intensity", FieldType::UInt16);
  layout.append("z", FieldType::Float64);
  layout.append("x", FieldType::Int32);
  layout.append("y", FieldType::Float32);
  PointBuffer src(layout, 100);
  for (std::size_t i = 0; i < 100; ++i) {
    writeFromDouble(src.record(i), *layout.find("x"), double(i) - 50);
    writeFromDouble(src.record(i), *layout.find("y"), 0.5 * double(i));
    writeFromDouble(src.record(i), *layout.find("z"), 1.25 * double(i));
    writeFromDouble(src.record(i), *layout.find("intensity"), double(i * 3));
  }
  src.setOrganization(10, 10);
  const std::string path = (dir / "scan.bin").string();
  writeKittiBin(path, src);
  EXPECT_EQ(fs::file_size(path), 100u * 16u);
  const PointBuffer back = readPointCloud(path);
  ASSERT_EQ(back.size(), 100u);
  EXPECT_EQ(back.layout().point_step, 16u);
  for (const char *name : {"x", "y", "z", "intensity"}) {
    const PointField *g = back.layout().find(name);
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(g->type, FieldType::Float32);
    expectSameValues(src, *src.layout().find(name), back, *g);
  }

  PointLayout xyz = xyzLayout();
  PointBuffer plain(xyz, 2);
  writeFromDouble(plain.record(1), xyz.fields[0], 4.0);
  const std::string plain_path = (dir / "plain.BIN").string();
  writeKittiBin(plain_path, plain);
  const PointBuffer plain_back = readKittiBin(plain_path);
  EXPECT_EQ(readAsDouble(plain_back.record(1), *plain_back.layout().find("x")), 4.0);
  EXPECT_EQ(readAsDouble(plain_back.record(1), *plain_back.layout().find("intensity")), 0.0);

  PointLayout no_xyz;
  no_xyz.append("x", FieldType::Float32);
  expectError([&] { writeKittiBin((dir / "bad.bin").string(), PointBuffer(no_xyz, 1)); }, "bad.bin", {"x/y/z"});
}

// numpy's default dtype is float64: `points.tofile("scan.bin")` of a float64 array gives 32-byte records whose size
// is still a multiple of 16. They were read as float32 and sampled as garbage (most "points" 1e20 m away, the rest
// scattered), exit code 0. The same values as float32 records must still read.
TEST(KittiBin, Float64RecordsAreRefusedNotSampledAsGarbage) {
  const ScratchDir scratch("io_kitti_f64");
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> coord(-50.0, 50.0), intensity(0.0, 1.0);
  std::vector<double> f64;
  std::vector<float> f32;
  for (int i = 0; i < 1000; ++i) {
    const double p[4] = {coord(rng), coord(rng), 0.2 * coord(rng), intensity(rng)};
    for (double v : p) {
      f64.push_back(v);
      f32.push_back(static_cast<float>(v));
    }
  }
  const fs::path wide = scratch.path / "numpy_float64.bin", narrow = scratch.path / "float32.bin";
  writeBytes(wide, hpds::test::bytesOf(f64));
  writeBytes(narrow, hpds::test::bytesOf(f32));
  expectError([&] { (void)readPointCloud(wide.string()); }, wide.string(),
              {"not a KITTI .bin file", "float64", "1000 of its 1000 points are plausible", "astype(numpy.float32)"});
  EXPECT_EQ(readPointCloud(narrow.string()).size(), 1000u);
}

TEST(Poses, RoundTripIsBitExact) {
  const ScratchDir scratch("io_poses");
  const fs::path &dir = scratch.path;
  std::mt19937_64 rng(42);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Eigen::Isometry3d> poses;
  poses.push_back(Eigen::Isometry3d::Identity());
  for (int i = 0; i < 200; ++i) {
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
    p.translation() = Eigen::Vector3d(g(rng) * 1e3, g(rng) * 1e-9, std::ldexp(g(rng), 40));
    poses.push_back(p);
  }
  const std::string path = (dir / "poses.txt").string();
  writeKittiPoses(path, poses);
  const auto back = readKittiPoses(path);
  ASSERT_EQ(back.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i)
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        ASSERT_TRUE(sameBits(back[i].matrix()(r, c), poses[i].matrix()(r, c)))
            << "pose " << i << " (" << r << "," << c << ")";
}

TEST(Poses, KittiPrecisionIsAcceptedAndMadeExactlyOrthonormal) {
  const ScratchDir scratch("io_poses_kitti");
  const fs::path &dir = scratch.path;
  const std::string path = (dir / "00.txt").string();
  // Two lines in the style of KITTI odometry poses (7 significant digits), a blank line between them.
  writeBytes(path,
             "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 "
             "3.330669e-16 2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16\n"
             "  \n"
             "9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 -1.154865e-03 "
             "-2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01\r\n");
  const auto poses = readKittiPoses(path);
  ASSERT_EQ(poses.size(), 2u);
  for (const auto &p : poses) {
    const Eigen::Matrix3d r = p.linear();
    EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-14);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-14);
  }
  EXPECT_DOUBLE_EQ(poses[1].translation().z(), 8.586941e-01);
  EXPECT_NEAR(poses[1].linear()(0, 1), 5.272628e-04, 1e-6);
}

// The nearest-rotation projection moves points: by as much as printing rounds (no word), or, for a scaled or cut-short
// rotation, by more (a warning naming the line and how far a point 100 m out moves). The reported correction is the
// largest distance a unit vector moves, checked against a brute force over many directions.
TEST(Poses, RotationCorrectionsAreMeasuredAndWarnedAboutBeyondRounding) {
  const ScratchDir scratch("io_poses_correction");
  const std::string path = (scratch.path / "poses.txt").string();
  const auto line = [](const Eigen::Matrix3d &r) {
    std::ostringstream o;
    o.precision(17);
    for (int row = 0; row < 3; ++row) o << r(row, 0) << " " << r(row, 1) << " " << r(row, 2) << " " << row << " ";
    return o.str() + "\n";
  };
  const Eigen::Matrix3d exact = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  Eigen::Matrix3d printed = exact;  // 6 significant digits
  for (int i = 0; i < 9; ++i) printed(i / 3, i % 3) = std::round(exact(i / 3, i % 3) * 1e6) / 1e6;
  Eigen::Matrix3d scaled = exact;
  scaled.row(1) *= 1.0003;  // off by 3e-4: within the 1e-3 the reader accepts
  for (const auto &[text, warned, expected_line] :
       {std::tuple<std::string, bool, std::size_t>{line(exact) + line(printed), false, 2},
        {line(exact) + line(printed) + "# scaled\n" + line(scaled) + line(printed), true, 4}}) {
    writeBytes(path, text);
    PoseCorrection c;
    const std::vector<Eigen::Isometry3d> poses = readKittiPoses(path, c);
    // Brute force: the largest distance any of many unit vectors moves between the file's matrix and the pose.
    std::vector<Eigen::Matrix3d> written;
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);) {
      if (l.empty() || l[0] == '#') continue;
      std::istringstream v(l);
      Eigen::Matrix3d m;
      double t;
      for (int row = 0; row < 3; ++row) v >> m(row, 0) >> m(row, 1) >> m(row, 2) >> t;
      written.push_back(m);
    }
    ASSERT_EQ(written.size(), poses.size());
    double largest = 0.0;
    std::mt19937 rng(3);
    std::normal_distribution<double> g;
    for (std::size_t k = 0; k < poses.size(); ++k)
      for (int trial = 0; trial < 20000; ++trial) {
        const Eigen::Vector3d u = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
        largest = std::max(largest, ((written[k] - poses[k].linear()) * u).norm());
      }
    EXPECT_LE(largest, c.largest * (1.0 + 1e-9));
    EXPECT_GT(largest, c.largest * 0.99);
    EXPECT_EQ(c.line, expected_line);
    const std::string w = poseCorrectionWarning(path, c);
    EXPECT_EQ(!w.empty(), warned) << w;
    if (warned) {
      EXPECT_NE(w.find("line 4"), std::string::npos) << w;
      EXPECT_NE(w.find("by up to 0.03 m"), std::string::npos) << w;
    }
  }
  // A rotation exact to double precision is kept bit for bit and corrects nothing.
  writeBytes(path, "1 0 0 0 0 1 0 0 0 0 1 0\n");
  PoseCorrection none;
  (void)readKittiPoses(path, none);
  EXPECT_EQ(none.largest, 0.0);
  EXPECT_EQ(none.line, 0u);
}

// A TUM trajectory (time x y z qx qy qz qw, '#' comment lines, as evo and SLAM tools write them) gives the poses of the
// same KITTI file, in file order.
TEST(Poses, TumTrajectoriesReadAsTheSameKittiPoses) {
  const ScratchDir scratch("io_poses_tum");
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Eigen::Isometry3d> poses;
  std::string tum = "# timestamp tx ty tz qx qy qz qw\n";
  for (int i = 0; i < 50; ++i) {
    const Eigen::Quaterniond q = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized();
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = q.toRotationMatrix();
    p.translation() = Eigen::Vector3d(g(rng) * 1e3, g(rng), 4e5 + g(rng));
    poses.push_back(p);
    char line[256];
    // 7 digits in the quaternion, as trajectories are often printed: normalised on reading.
    std::snprintf(line, sizeof line, "%.6f %.17g %.17g %.17g %.7f %.7f %.7f %.7f\n", 1.6e9 + 0.1 * i,
                  p.translation().x(), p.translation().y(), p.translation().z(), q.x(), q.y(), q.z(), q.w());
    tum += line;
    if (i == 20) tum += "\n  # a comment after a blank line\n";
  }
  const std::string kitti_path = (scratch.path / "kitti.txt").string(), tum_path = (scratch.path / "tum.txt").string();
  writeKittiPoses(kitti_path, poses);
  writeBytes(tum_path, tum);
  const auto from_kitti = readKittiPoses(kitti_path), from_tum = readKittiPoses(tum_path);
  ASSERT_EQ(from_tum.size(), poses.size());
  ASSERT_EQ(from_kitti.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EXPECT_LT((from_tum[i].linear() - from_kitti[i].linear()).cwiseAbs().maxCoeff(), 1e-6) << i;
    EXPECT_EQ(from_tum[i].translation(), from_kitti[i].translation()) << i;
    EXPECT_TRUE(rigidPoseProblem(from_tum[i]).empty()) << i << ": " << rigidPoseProblem(from_tum[i]);
  }
  // Comments in a KITTI file are skipped too.
  writeBytes(scratch.path / "commented.txt", "# poses of drive 0\n" + hpds::test::readText(kitti_path));
  EXPECT_EQ(readKittiPoses((scratch.path / "commented.txt").string()).size(), poses.size());
}

// ---------------------------------------------------------------------------------------------------------------------
// Malformed input: always std::runtime_error naming the path, never a crash, hang or huge allocation

TEST(BadInput, PoseFiles) {
  const ScratchDir scratch("io_bad_poses");
  const fs::path &dir = scratch.path;
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  auto check = [&](const std::string &name, const std::string &content, std::vector<std::string> parts) {
    writeBytes(dir / name, content);
    expectError([&] { (void)readKittiPoses((dir / name).string()); }, name, parts);
  };
  check("eleven.txt", good + "1 0 0 0 0 1 0 0 0 0 1\n", {":2:", "expected 12 numbers", "or 8 (TUM", "found 11"});
  check("seven.txt", "# t x y z qx qy qz qw\n0 1 2 3 0 0 0\n", {":2:", "found 7"});
  check("mixed.txt", "\n" + good + "0.1 1 2 3 0 0 0 1\n", {":3:", "8 numbers (TUM), but line 2 had 12 (KITTI)"});
  check("quaternion.txt", "0.1 1 2 3 0 0 0 1\n0.2 1 2 3 0 0 0.1 1\n", {":2:", "quaternion", "norm 1.00499"});
  check("zero_quaternion.txt", "0.1 1 2 3 0 0 0 0\n", {":1:", "norm 0,"});
  check("thirteen.txt", good + good + "1 0 0 0 0 1 0 0 0 0 1 0 5\n", {":3:", "found 13"});
  check("abc.txt", good + "\n1 0 0 0 0 1 0 abc 0 0 1 0\n", {":3:", "'abc' is not a number"});
  check("comma.txt", "1,0 0 0 0 1 0 0 0 0 1 0\n", {":1:", "'1,0'"});
  // A NUL in a token is shown as '?': it cut the message short ("'3.5" and nothing more).
  check("nul.txt", good + "1 0 0 0 0 1 0 3.5" + std::string(1, '\0') + " 0 0 1 0\n", {":2:", "'3.5?' is not a number"});
  check("nan.txt", "1 0 0 nan 0 1 0 0 0 0 1 0\n", {":1:", "non-finite"});
  check("inf.txt", "1 0 0 0 0 1 0 -inf 0 0 1 0\n", {":1:", "non-finite"});
  check("huge.txt", "1 0 0 1e999 0 1 0 0 0 0 1 0\n", {":1:", "out of range"});
  check("scaled.txt", "2 0 0 0 0 2 0 0 0 0 2 0\n", {":1:", "not a rotation"});
  check("reflection.txt", "-1 0 0 0 0 1 0 0 0 0 1 0\n", {":1:", "not a rotation", "det = -1"});
  check("sheared.txt", "1 0.01 0 0 0 1 0 0 0 0 1 0\n", {":1:", "not a rotation"});
  expectError([&] { (void)readKittiPoses((dir / "missing.txt").string()); }, "missing.txt", {"file not found"});

  writeBytes(dir / "empty.txt", "");
  EXPECT_TRUE(readKittiPoses((dir / "empty.txt").string()).empty());

  Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
  bad.translation().x() = std::numeric_limits<double>::quiet_NaN();
  expectError([&] { writeKittiPoses((dir / "out.txt").string(), {bad}); }, "out.txt", {"non-finite"});
  expectError([&] { writeKittiPoses((dir / "no_dir" / "out.txt").string(), {}); }, "out.txt",
              {"cannot create a temporary file beside it"});
}
