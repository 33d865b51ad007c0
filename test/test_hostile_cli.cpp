// Hostile input through the `hpds` CLI, row by row of docs/reliability.md (exit code and message): truncated and
// garbage files of every format, unusual field types, NaN/Inf, empty frames, invalid configs, unbounded inputs,
// and the fuzzer finds that made PCL abort (run in a subprocess). Complements test_cli (basic bad files and flags)
// and test_io_* (reader details); the core Pipeline's side is test_hostile_pipeline.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "HostileTestSupport.hpp"
#include "TestData.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;
using test::gridPoints;
using test::readText;
using test::typedCloud;
using test::writeText;

std::string q(const fs::path &p) { return "'" + p.string() + "'"; }
int hpds(const std::string &args, std::string *out = nullptr) {
  return test::runCommand(test::cliPath() + " " + args, out);
}

struct CliCase {
  std::string args;
  int code;
  std::string message;  ///< must appear in stdout+stderr
};

void runCases(const std::vector<CliCase> &cases) {
  for (const CliCase &c : cases) {
    std::string log;
    EXPECT_EQ(hpds(c.args, &log), c.code) << c.args << "\n" << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
    // Every error, a bad command line (2) included, is said as "hpds: error: ..." (README).
    if (c.code != 0) {
      EXPECT_NE(log.find("hpds: error: "), std::string::npos) << log;
    }
  }
}

TEST(HostileCli, TruncatedAndGarbageFilesOfEveryFormat) {
  const auto tmp = test::scratchDir("hostile_files");
  const PointBuffer cloud = typedCloud(FieldType::Float32, gridPoints(10, 0.5));
  writePly((tmp / "good.ply").string(), cloud);
  writePcd((tmp / "good.pcd").string(), cloud);
  const std::string ply = readText(tmp / "good.ply"), pcd = readText(tmp / "good.pcd");
  writeText(tmp / "cut.ply", ply.substr(0, ply.size() - 7));
  writeText(tmp / "cut_header.ply", ply.substr(0, ply.find("end_header")));
  writeText(tmp / "cut.pcd", pcd.substr(0, pcd.size() - 1));
  std::mt19937 rng(7);
  std::string noise(4096, '\0');
  for (char &c : noise) c = static_cast<char>(rng());
  writeText(tmp / "garbage.ply", noise);
  writeText(tmp / "garbage_after_magic.ply", "ply\n" + noise);
  writeText(tmp / "garbage_after_header.pcd", pcd.substr(0, pcd.find("DATA")) + "DATA ascii\n" + noise);
  writeText(tmp / "odd.bin", noise.substr(0, 4095));
  writeText(tmp / "poses_garbage.txt", noise);
  writeText(tmp / "poses_cut.txt", "1 0 0 0 0 1 0 0 0 0 1\n");
  writeText(tmp / "poses_inf.txt", "1 0 0 inf 0 1 0 0 0 0 1 0\n");
  writeText(tmp / "poses_scaled.txt", "2 0 0 0 0 2 0 0 0 0 2 0\n");
  fs::create_directory(tmp / "adir.pcd");
  const std::string out = " -o " + q(tmp / "out.ply");
  const std::string good = q(tmp / "good.pcd");
  runCases({
      {"sample " + q(tmp / "cut.ply") + out, 1, "truncated"},
      {"sample " + q(tmp / "cut_header.ply") + out, 1, "cut_header.ply: truncated PLY header"},
      {"sample " + q(tmp / "cut.pcd") + out, 1, "cut.pcd: truncated"},
      {"sample " + q(tmp / "garbage.ply") + out, 1, "garbage.ply: not a PLY file"},
      {"sample " + q(tmp / "garbage_after_magic.ply") + out, 1, "garbage_after_magic.ply: "},
      {"sample " + q(tmp / "garbage_after_header.pcd") + out, 1, "garbage_after_header.pcd: "},
      {"sample " + q(tmp / "odd.bin") + out, 1, "multiple of 16"},
      {"sample " + q(tmp / "adir.pcd") + out, 1, "adir.pcd' holds no .pcd, .ply or .bin frame"},  // a folder: its frames
      {"sample " + good + " --poses " + q(tmp / "poses_garbage.txt") + out, 1, "poses_garbage.txt:1: "},
      {"sample " + good + " --poses " + q(tmp / "poses_cut.txt") + out, 1, "or 8 (TUM: time x y z qx qy qz qw), found 11"},
      {"sample " + good + " --poses " + q(tmp / "poses_inf.txt") + out, 1, "non-finite"},
      {"sample " + good + " --poses " + q(tmp / "poses_scaled.txt") + out, 1, "not a rotation"},
      {"verify " + q(tmp / "cut.ply") + " --cell-size 4", 1, "truncated"},
      // --input takes every path after it: the sampling given after it is said to have been taken as an input.
      {"verify --input " + good + " " + q(tmp / "cut.ply") + " --cell-size 4", 2,
       "SAMPLING is missing: --input takes every path after it, so '" + (tmp / "cut.ply").string() + "' was read"},
      {"verify --cell-size 4", 2, "SAMPLING is required"},
  });
  // A failed run leaves no partial output behind.
  EXPECT_FALSE(fs::exists(tmp / "out.ply"));
  runCases({
      {"sample " + good + " -o " + q(tmp / "no_dir" / "out.ply"), 1, "out.ply"},
      {"sample " + good + out + " --stats " + q(tmp / "no_dir" / "s.json"), 1, "s.json"},
  });
}

TEST(HostileCli, RandomBytesInABinFileAreJustPoints) {
  // A .bin has no header: any 16-byte multiple is a valid cloud, so noise is sampled, its NaN/Inf counted.
  const auto tmp = test::scratchDir("hostile_bin_noise");
  std::mt19937 rng(3);
  std::string noise(16 * 5000, '\0');
  for (char &c : noise) c = static_cast<char>(rng());
  writeText(tmp / "noise.bin", noise);
  std::string log;
  ASSERT_EQ(hpds("sample " + q(tmp / "noise.bin") + " -o " + q(tmp / "o.ply") + " --stats " + q(tmp / "s.json"), &log),
            0)
      << log;
  const std::string stats = readText(tmp / "s.json");
  EXPECT_NE(stats.find("\"skipped_invalid\""), std::string::npos);
  EXPECT_NE(stats.find("\"out_of_range\""), std::string::npos);
}

TEST(HostileCli, AnyNumericFieldTypeForXyzIsSampledWithItsValues) {
  const auto tmp = test::scratchDir("hostile_types");
  const auto pts = gridPoints(12, 1.0, 2.0);  // integers 2..13: exact in every type
  for (FieldType t : {FieldType::UInt8, FieldType::Int8, FieldType::UInt16, FieldType::Int16, FieldType::Int32,
                      FieldType::UInt32, FieldType::Float32, FieldType::Float64}) {
    SCOPED_TRACE(fieldTypeName(t));
    const fs::path in = tmp / (std::string("xyz_") + fieldTypeName(t) + ".pcd");
    writePcd(in.string(), typedCloud(t, pts));
    std::string log;
    ASSERT_EQ(hpds("sample " + q(in) + " -o " + q(tmp / "o.ply") + " --cell-size 2 --max-depth 3", &log), 0) << log;
    const PointBuffer s = readPointCloud((tmp / "o.ply").string());
    ASSERT_GT(s.size(), 10u);
    // float64 input keeps its digits; any other type fits float32 exactly.
    EXPECT_EQ(s.layout().find("x")->type, t == FieldType::Float64 ? FieldType::Float64 : FieldType::Float32);
    std::set<std::array<double, 3>> input(pts.begin(), pts.end());
    for (std::size_t i = 0; i < s.size(); ++i) {
      std::array<double, 3> p;
      for (int a = 0; a < 3; ++a) p[a] = readAsDouble(s.record(i), s.layout().fields[a]);
      ASSERT_TRUE(input.count(p)) << p[0] << " " << p[1] << " " << p[2];
    }
    ASSERT_EQ(hpds("verify " + q(tmp / "o.ply") + " --cell-size 2 --input " + q(in), &log), 0) << log;
  }
  // Negative values in a signed 8-bit field stay negative (no unsigned reinterpretation).
  writePcd((tmp / "neg.pcd").string(), typedCloud(FieldType::Int8, {{-100, -5, -1}, {100, 5, 1}}));
  ASSERT_EQ(hpds("sample " + q(tmp / "neg.pcd") + " -o " + q(tmp / "neg.ply")), 0);
  const PointBuffer neg = readPointCloud((tmp / "neg.ply").string());
  ASSERT_EQ(neg.size(), 2u);
  std::set<double> xs = {readAsDouble(neg.record(0), neg.layout().fields[0]),
                         readAsDouble(neg.record(1), neg.layout().fields[0])};
  EXPECT_EQ(xs, (std::set<double>{-100.0, 100.0}));
}

TEST(HostileCli, GeoreferencedCoordinatesKeepTheirPrecisionOrAreSaidToLoseIt) {
  // Found by sampling a frame at UTM coordinates (x ~ 5e6 m): float32 output positions were off by up to 0.25 m,
  // samples came out closer than r_D, and verify's float32 tolerance (1.2 m there) let it pass.
  const auto tmp = test::scratchDir("hostile_utm");
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 20.0);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < 20000; ++i) pts.push_back({5e6 + u(rng), 4e6 + u(rng), 100.0 + 0.05 * u(rng)});
  const fs::path f8 = tmp / "utm_f8.pcd", f4 = tmp / "local_f4.pcd", poses = tmp / "poses.txt";
  writePcd(f8.string(), typedCloud(FieldType::Float64, pts));
  // 1. float64 input: float64 output, every sample bit for bit an input point, verified to float64 precision.
  std::string log;
  ASSERT_EQ(hpds("sample " + q(f8) + " -o " + q(tmp / "f8.ply") + " --spacing 0.1 --no-normals", &log), 0) << log;
  EXPECT_EQ(log.find("float64_xyz"), std::string::npos) << log;
  const PointBuffer s = readPointCloud((tmp / "f8.ply").string());
  ASSERT_GT(s.size(), 1000u);
  ASSERT_EQ(s.layout().find("x")->type, FieldType::Float64);
  const std::set<std::array<double, 3>> input(pts.begin(), pts.end());
  for (std::size_t i = 0; i < s.size(); ++i) {
    std::array<double, 3> p;
    for (int a = 0; a < 3; ++a) p[a] = readAsDouble(s.record(i), s.layout().fields[a]);
    ASSERT_TRUE(input.count(p)) << "sample " << i << " is no input point";
  }
  ASSERT_EQ(hpds("verify " + q(tmp / "f8.ply") + " --spacing 0.1 --input " + q(f8), &log), 0) << log;
  // 2. float32 points posed into UTM coordinates: float32 output (asked for: by default such poses give float64) is
  //    said to round them, and verify refuses to call levels it cannot resolve valid; with output.float64_xyz the
  //    output is exact again.
  std::vector<std::array<double, 3>> local;
  for (const auto &p : pts) local.push_back({p[0] - 5e6, p[1] - 4e6, p[2] - 100.0});
  writePcd(f4.string(), typedCloud(FieldType::Float32, local));
  writeText(poses, "1 0 0 5000000 0 1 0 4000000 0 0 1 100\n");
  const std::string posed = "sample " + q(f4) + " --poses " + q(poses) + " --mode map --spacing 0.1 --no-normals";
  ASSERT_EQ(hpds(posed + " --float32-xyz -o " + q(tmp / "f4.ply"), &log), 0) << log;
  EXPECT_NE(log.find("set output.float64_xyz: true"), std::string::npos) << log;
  EXPECT_EQ(readPointCloud((tmp / "f4.ply").string()).layout().find("x")->type, FieldType::Float32);
  EXPECT_EQ(hpds("verify " + q(tmp / "f4.ply") + " --spacing 0.1", &log), 1) << log;
  EXPECT_NE(log.find("cannot be checked"), std::string::npos) << log;
  writeText(tmp / "f64.yaml", "output: {float64_xyz: true}\n");
  ASSERT_EQ(hpds(posed + " --config " + q(tmp / "f64.yaml") + " -o " + q(tmp / "f64.ply"), &log), 0) << log;
  EXPECT_EQ(log.find("float64_xyz"), std::string::npos) << log;
  EXPECT_EQ(readPointCloud((tmp / "f64.ply").string()).layout().find("x")->type, FieldType::Float64);
  EXPECT_EQ(hpds("verify " + q(tmp / "f64.ply") + " --spacing 0.1", &log), 0) << log;
  // The flag does what the key does.
  ASSERT_EQ(hpds(posed + " --float64-xyz -o " + q(tmp / "f64_flag.ply"), &log), 0) << log;
  EXPECT_EQ(log.find("float64_xyz"), std::string::npos) << log;
  EXPECT_EQ(readPointCloud((tmp / "f64_flag.ply").string()).layout().find("x")->type, FieldType::Float64);
  // Covariances need normals: asking for both and for no normals is an error, not a silent choice.
  EXPECT_NE(hpds("sample " + q(f4) + " --covariances --no-normals -o " + q(tmp / "cov.ply"), &log), 0) << log;
  EXPECT_NE(log.find("--covariances"), std::string::npos) << log;
}

// A robot's config with covariances on (for GICP) and a quick `--no-normals` run failed with
// "normals.covariances: needs normals.enabled", naming keys the command line never touched. Flags override the
// config: no normals means no covariances either, and stderr says so.
TEST(HostileCli, NoNormalsOverridesTheConfigsCovariancesAndSaysSo) {
  const auto tmp = test::scratchDir("hostile_cov_config");
  writePcd((tmp / "f.pcd").string(), typedCloud(FieldType::Float32, gridPoints(20, 0.3)));
  writeText(tmp / "gicp.yaml", "normals: {covariances: true}\n");
  const std::string run = "sample " + q(tmp / "f.pcd") + " --config " + q(tmp / "gicp.yaml") + " -o ";
  std::string log;
  ASSERT_EQ(hpds(run + q(tmp / "cov.ply"), &log), 0) << log;
  EXPECT_NE(readPointCloud((tmp / "cov.ply").string()).layout().find("cov_xx"), nullptr);
  ASSERT_EQ(hpds(run + q(tmp / "none.ply") + " --no-normals", &log), 0) << log;
  EXPECT_NE(log.find("--no-normals also turns off normals.covariances: true of --config"), std::string::npos) << log;
  const PointLayout none = readPointCloud((tmp / "none.ply").string()).layout();
  EXPECT_EQ(none.find("normal_x"), nullptr);
  EXPECT_EQ(none.find("cov_xx"), nullptr);
  // Where the config itself contradicts (no flag to override it), the error says what to set.
  writeText(tmp / "bad.yaml", "normals: {enabled: false, covariances: true}\n");
  EXPECT_EQ(hpds("sample " + q(tmp / "f.pcd") + " --config " + q(tmp / "bad.yaml") + " -o " + q(tmp / "bad.ply"), &log),
            1)
      << log;
  EXPECT_NE(log.find("set normals.enabled: true, or normals.covariances: false"), std::string::npos) << log;
}

TEST(HostileCli, MissingXyzAndUnrepresentableFieldsAreRefused) {
  const auto tmp = test::scratchDir("hostile_fields");
  writeText(tmp / "no_z.pcd",
            "VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2\n");
  writeText(tmp / "int64.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 8 4 4\nTYPE I F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
                               "POINTS 1\nDATA ascii\n1 2 3\n");
  writeText(tmp / "list.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\n"
                              "property float z\nend_header\n1 0.5 2 3\n");
  // Found by fuzz_pcd: a multi-element x was sampled by its first element, and the output then had no x at all.
  // Refused on reading now, with the file and the field named.
  writeText(tmp / "x_count_2.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 2 1 1\nWIDTH 1\nHEIGHT 1\n"
                                   "POINTS 1\nDATA ascii\n1 2 3 4\n");
  const std::string out = " -o " + q(tmp / "o.ply");
  runCases({
      {"sample " + q(tmp / "x_count_2.pcd") + out, 1, "x_count_2.pcd: field 'x' has count 2"},
      {"sample " + q(tmp / "no_z.pcd") + out, 1, "no x/y/z fields"},
      {"sample " + q(tmp / "int64.pcd") + out, 1, "64-bit"},
      {"sample " + q(tmp / "list.ply") + out, 1, "list"},
  });
}

TEST(HostileCli, NanInfEverywhereOriginOnlyAndEmptyFrames) {
  const auto tmp = test::scratchDir("hostile_values");
  // NaN and Inf in every field, including the non-coordinate ones.
  PointBuffer all_bad = typedCloud(FieldType::Float32, gridPoints(5, 1.0));
  for (std::size_t i = 0; i < all_bad.size(); ++i)
    for (const auto &f : all_bad.layout().fields)
      writeFromDouble(all_bad.record(i), f, i % 3 == 0 ? NAN : (i % 3 == 1 ? INFINITY : -INFINITY));
  writePcd((tmp / "allbad.pcd").string(), all_bad);
  // NaN only in intensity: the points are fine, the NaN is carried to the output as it was.
  PointBuffer nan_attr = typedCloud(FieldType::Float32, gridPoints(5, 1.0));
  for (std::size_t i = 0; i < nan_attr.size(); ++i) writeFromDouble(nan_attr.record(i), nan_attr.layout().fields[3], NAN);
  writePcd((tmp / "nan_attr.pcd").string(), nan_attr);
  writePcd((tmp / "origin.pcd").string(), typedCloud(FieldType::Float32, std::vector<std::array<double, 3>>(1000, {0, 0, 0})));
  writePcd((tmp / "empty.pcd").string(), typedCloud(FieldType::Float32, {}));
  writePly((tmp / "empty.ply").string(), typedCloud(FieldType::Float32, {}));
  writeText(tmp / "keep_zero.yaml", "input: {skip_zero_points: false}\n");

  std::string log;
  ASSERT_EQ(hpds("sample " + q(tmp / "allbad.pcd") + " -o " + q(tmp / "a.ply") + " --stats " + q(tmp / "a.json"), &log), 0)
      << log;
  EXPECT_NE(readText(tmp / "a.json").find("\"skipped_invalid\": 25"), std::string::npos) << readText(tmp / "a.json");
  EXPECT_EQ(readPointCloud((tmp / "a.ply").string()).size(), 0u);

  ASSERT_EQ(hpds("sample " + q(tmp / "nan_attr.pcd") + " -o " + q(tmp / "n.ply") + " --normals", &log), 0) << log;
  const PointBuffer n = readPointCloud((tmp / "n.ply").string());
  ASSERT_EQ(n.size(), 25u);
  for (std::size_t i = 0; i < n.size(); ++i) EXPECT_TRUE(std::isnan(readAsDouble(n.record(i), *n.layout().find("intensity"))));

  ASSERT_EQ(hpds("sample " + q(tmp / "origin.pcd") + " -o " + q(tmp / "z.ply") + " --stats " + q(tmp / "z.json"), &log), 0)
      << log;
  EXPECT_NE(readText(tmp / "z.json").find("\"skipped_zero\": 1000"), std::string::npos);
  EXPECT_EQ(readPointCloud((tmp / "z.ply").string()).size(), 0u);
  ASSERT_EQ(hpds("sample " + q(tmp / "origin.pcd") + " -o " + q(tmp / "z1.ply") + " --config " + q(tmp / "keep_zero.yaml"),
                 &log),
            0)
      << log;
  EXPECT_EQ(readPointCloud((tmp / "z1.ply").string()).size(), 1u);  // 1000 identical points: one sample

  for (const char *e : {"empty.pcd", "empty.ply"}) {
    ASSERT_EQ(hpds("sample " + q(tmp / e) + " -o " + q(tmp / "e.ply") + " --normals", &log), 0) << e << log;
    EXPECT_EQ(readPointCloud((tmp / "e.ply").string()).size(), 0u);
  }
  // Empty frames in the middle of a map-mode stream change nothing.
  writePcd((tmp / "a.pcd").string(), typedCloud(FieldType::Float32, gridPoints(8, 0.7)));
  ASSERT_EQ(hpds("sample " + q(tmp / "a.pcd") + " -o " + q(tmp / "m1.ply") + " --mode map", &log), 0) << log;
  ASSERT_EQ(hpds("sample " + q(tmp / "empty.pcd") + " " + q(tmp / "a.pcd") + " " + q(tmp / "empty.pcd") + " -o " +
                     q(tmp / "m2.ply") + " --mode map",
                 &log),
            0)
      << log;
  EXPECT_EQ(readPointCloud((tmp / "m1.ply").string()).size(), readPointCloud((tmp / "m2.ply").string()).size());
}

// An input field named `frame` (a frame counter some pipelines add) never reaches the output, even where hpds writes
// no frame field of its own: `hpds verify` would read it as hpds's scan-frame index and split the map by it.
TEST(HostileCli, AnInputFrameFieldIsNotTakenForHpdssOwn) {
  const auto tmp = test::scratchDir("hostile_frame_field");
  std::string body;
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j)
      body += std::to_string(0.1 * i) + " " + std::to_string(0.1 * j) + " 2 " + std::to_string((i + j) % 3) + "\n";
  writeText(tmp / "f.pcd", "VERSION 0.7\nFIELDS x y z frame\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 900\n"
                           "HEIGHT 1\nPOINTS 900\nDATA ascii\n" + body);
  std::string log;
  ASSERT_EQ(
      hpds("sample " + q(tmp / "f.pcd") + " --mode map --no-normals --spacing 0.2 -o " + q(tmp / "m.ply"), &log), 0)
      << log;
  EXPECT_NE(log.find("input field 'frame'"), std::string::npos) << log;
  EXPECT_EQ(readPointCloud((tmp / "m.ply").string()).layout().find("frame"), nullptr);
  ASSERT_EQ(hpds("verify " + q(tmp / "m.ply") + " --spacing 0.2 --input " + q(tmp / "f.pcd"), &log), 0) << log;
}

TEST(HostileCli, TheSameFrameTwiceAddsNothingInMapMode) {
  const auto tmp = test::scratchDir("hostile_dup");
  const SyntheticLidar lidar([] {
    SyntheticLidarConfig c;
    c.beams = 8;
    c.azimuth_steps = 400;
    return c;
  }());
  writePcd((tmp / "f.pcd").string(), lidar.frame(0).frame.points);
  std::string log;
  // Every level down to 8 of 4 m cells is built and written, without normals.
  const std::string levels = " --cell-size 4 --level 8 --no-normals";
  ASSERT_EQ(hpds("sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "once.ply") + " --mode map --seed 1" + levels, &log), 0) << log;
  ASSERT_EQ(hpds("sample " + q(tmp / "f.pcd") + " " + q(tmp / "f.pcd") + " -o " + q(tmp / "twice.ply") +
                     " --mode map --seed 1 --stats " + q(tmp / "s.json") + levels,
                 &log),
            0)
      << log;
  const PointBuffer once = readPointCloud((tmp / "once.ply").string());
  const PointBuffer twice = readPointCloud((tmp / "twice.ply").string());
  // Only the finest levels can take a few of the repeated points (a different random order meets other gaps).
  EXPECT_GE(twice.size(), once.size());
  EXPECT_LE(twice.size(), once.size() + once.size() / 5);
  ASSERT_EQ(hpds("verify " + q(tmp / "twice.ply") + " --cell-size 4 --input " + q(tmp / "f.pcd"), &log), 0) << log;
}

// Clouds that are already in one frame (registered tiles, georeferenced scans) merged in map mode without --poses:
// each frame's sensor is taken at the origin, so every tile farther than map.evict_distance from it was evicted by
// the next one, and the map written held the last tile only, with exit status 0 and nothing on stderr.
TEST(HostileCli, AMapThatLostSamplesToEvictionSaysSo) {
  const auto tmp = test::scratchDir("hostile_evicted_map");
  writePcd((tmp / "near.pcd").string(), typedCloud(FieldType::Float32, gridPoints(20, 0.5)));
  writePcd((tmp / "far.pcd").string(), typedCloud(FieldType::Float32, gridPoints(20, 0.5, 300.0)));
  const std::string tiles =
      "sample " + q(tmp / "far.pcd") + " " + q(tmp / "near.pcd") + " --mode map --no-normals --spacing 0.2 -o ";
  std::string log;
  ASSERT_EQ(hpds(tiles + q(tmp / "evicted.ply"), &log), 0) << log;
  EXPECT_NE(log.find("hpds: warning: "), std::string::npos) << log;
  EXPECT_NE(log.find("evicted"), std::string::npos) << log;
  EXPECT_NE(log.find("map.evict_distance"), std::string::npos) << log;
  EXPECT_NE(log.find("no --poses"), std::string::npos) << log;  // why the sensor was at the origin
  // Without eviction every tile is kept and nothing is said.
  writeText(tmp / "keep.yaml", "map: {evict_distance: 0.0}\n");
  ASSERT_EQ(hpds(tiles + q(tmp / "kept.ply") + " --config " + q(tmp / "keep.yaml"), &log), 0) << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  EXPECT_GT(readPointCloud((tmp / "kept.ply").string()).size(), readPointCloud((tmp / "evicted.ply").string()).size());
  // With poses the sensor's positions are known, and the warning says what the map holds instead.
  writeText(tmp / "poses.txt", "1 0 0 300 0 1 0 300 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0\n");
  ASSERT_EQ(hpds(tiles + q(tmp / "posed.ply") + " --poses " + q(tmp / "poses.txt"), &log), 0) << log;
  EXPECT_NE(log.find("evicted"), std::string::npos) << log;
  EXPECT_EQ(log.find("no --poses"), std::string::npos) << log;
}

TEST(HostileCli, InvalidConfigsNameTheKeyAndExitOne) {
  const auto tmp = test::scratchDir("hostile_config");
  writePcd((tmp / "f.pcd").string(), typedCloud(FieldType::Float32, gridPoints(3, 1.0)));
  const std::string base = "sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --config ";
  std::mt19937 rng(5);
  std::string noise(2000, '\0');
  for (char &c : noise) c = static_cast<char>(rng());
  writeText(tmp / "noise.yaml", noise);
  writeText(tmp / "deep.yaml", std::string(50000, '[') + "\n");
  writeText(tmp / "quoted.yaml", "hierarchy: {cell_size: '4'}\n");
  writeText(tmp / "yes.yaml", "normals: {enabled: yes}\n");
  writeText(tmp / "nan_range.yaml", "input: {max_range: .nan}\n");
  writeText(tmp / "neg_evict.yaml", "map: {evict_distance: -1}\n");
  writeText(tmp / "inf_radius.yaml", "normals: {radius: .inf}\n");
  writeText(tmp / "empty.yaml", "");
  fs::create_directory(tmp / "dir.yaml");
  runCases({
      {base + q(tmp / "noise.yaml"), 1, "noise.yaml"},
      {base + q(tmp / "deep.yaml"), 1, "(document)"},
      {base + q(tmp / "quoted.yaml"), 1, "hierarchy.cell_size"},
      {base + q(tmp / "yes.yaml"), 1, "normals.enabled"},
      {base + q(tmp / "nan_range.yaml"), 1, "input.max_range"},
      {base + q(tmp / "neg_evict.yaml"), 1, "map.evict_distance"},
      {base + q(tmp / "inf_radius.yaml"), 1, "normals.radius"},
      {base + q(tmp / "missing.yaml"), 1, "missing.yaml"},
      {base + q(tmp / "dir.yaml"), 1, "dir.yaml"},
      {base + q(tmp / "empty.yaml"), 0, "wrote"},
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --threads -3", 2, "--threads"},
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --mode both", 2, "--mode: both not in"},
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --cell-size abc", 2, "cell-size"},
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --frobnicate", 2, "frobnicate"},
  });
}

// Found by fuzz_config_yaml: yaml-cpp 0.7's LoadAll never returns on a lone ',' (yaml-cpp issue 1040), so
// `--config` with such a file hung while memory grew; the loader now counts documents itself and parses with Load.
TEST(HostileCli, ConfigOfALoneCommaIsRefusedNotHung) {
  const auto tmp = test::scratchDir("hostile_comma");
  writePcd((tmp / "f.pcd").string(), typedCloud(FieldType::Float32, gridPoints(3, 1.0)));
  writeText(tmp / "comma.yaml", ",\n");
  std::string log;
  EXPECT_EQ(test::runCommand("timeout 20 " + test::cliPath() + " sample " + q(tmp / "f.pcd") + " -o " +
                                 q(tmp / "o.ply") + " --config " + q(tmp / "comma.yaml"),
                             &log),
            1)
      << log;
}

// Inputs that grew without bound or wrapped around: a config that is a device, a negative seed (2^64 - 1 on the CLI
// while YAML refused it), a feature order on 100 000 coincident points (59 s before the feature cell cap; here it
// must simply finish, the work bound itself is tested in test_insertion_order), and input fields whose names are
// hpds's own, which must not vanish without a word.
TEST(HostileCli, UnboundedInputsAreRefusedOrBoundedAndShadowedFieldsAreSaid) {
  const auto tmp = test::scratchDir("hostile_bounds");
  writePcd((tmp / "f.pcd").string(), typedCloud(FieldType::Float32, gridPoints(3, 1.0)));
  runCases({
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --config /dev/zero", 1,
       "config file '/dev/zero': not a regular file"},
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --seed -1", 2,
       "--seed: must be an integer in 0..18446744073709551615, got '-1'"},
      {"sample " + q(tmp / "f.pcd") + " -o " + q(tmp / "o.ply") + " --threads 5000", 2, "--threads: must be an integer in 0..1024"},
  });
  EXPECT_FALSE(fs::exists(tmp / "o.ply"));

  PointLayout l;
  for (const char *a : {"x", "y", "z"}) l.append(a, FieldType::Float32);
  l.append("level", FieldType::UInt8);
  l.append("normal_x", FieldType::Float32);
  PointBuffer same(l, 100000);
  for (std::size_t i = 0; i < same.size(); ++i)
    for (int a = 0; a < 3; ++a) writeFromDouble(same.record(i), l.fields[a], 2.5);
  writePly((tmp / "same.ply").string(), same);
  std::string log;
  ASSERT_EQ(hpds("sample " + q(tmp / "same.ply") + " -o " + q(tmp / "s.ply") + " --order sphericity", &log), 0) << log;
  for (const char *name : {"level", "normal_x"})
    EXPECT_NE(log.find(std::string("hpds: warning: input field '") + name + "'"), std::string::npos) << log;
  EXPECT_NE(log.find("rename the field to keep it"), std::string::npos) << log;
  // The reason given is the true one: hpds writes its own normals, but `level` and `frame` are reserved names, and
  // a single-input output has no `frame` of hpds's (the warning used to say it had).
  EXPECT_NE(log.find("hpds writes its own 'normal_x'"), std::string::npos) << log;
  EXPECT_NE(log.find("'level' is reserved"), std::string::npos) << log;
  PointLayout fl;
  for (const char *a : {"x", "y", "z"}) fl.append(a, FieldType::Float32);
  fl.append("frame", FieldType::UInt16);
  PointBuffer framed(fl, 50);
  for (std::size_t i = 0; i < framed.size(); ++i)
    for (int a = 0; a < 3; ++a) writeFromDouble(framed.record(i), fl.fields[a], 0.3 * static_cast<double>(i) + a);
  writePly((tmp / "framed.ply").string(), framed);
  ASSERT_EQ(hpds("sample " + q(tmp / "framed.ply") + " -o " + q(tmp / "f.ply"), &log), 0) << log;
  EXPECT_NE(log.find("input field 'frame'"), std::string::npos) << log;
  EXPECT_NE(log.find("'frame' is reserved for hpds's frame index"), std::string::npos) << log;
  EXPECT_EQ(log.find("hpds writes its own 'frame'"), std::string::npos) << log;
  EXPECT_EQ(readPointCloud((tmp / "f.ply").string()).layout().find("frame"), nullptr);
}

// Found by fuzz_pcd: a uchar `red` without green/blue was sampled and written to the PLY, which the PLY reader then
// refused ("colour properties red/green/blue must all be present"; PCL's reader cannot pack such a set), so
// `hpds verify` could not read `hpds sample`'s output. Such PLY files are now read by hpds's own vertex reader,
// which keeps the field as it is.
TEST(HostileCli, ALoneColourChannelSurvivesSampleThenVerify) {
  const auto tmp = test::scratchDir("hostile_red");
  writeText(tmp / "red.pcd", "VERSION 0.7\nFIELDS x y z red\nSIZE 4 4 4 1\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\n"
                             "HEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3 200\n4 5 6 100\n");
  std::string log;
  ASSERT_EQ(hpds("sample " + q(tmp / "red.pcd") + " -o " + q(tmp / "red.ply"), &log), 0) << log;
  EXPECT_EQ(hpds("verify " + q(tmp / "red.ply") + " --cell-size 4", &log), 0) << log;
  // The field and its bytes came through: uint8, and each sample's value one of the inputs'.
  const PointBuffer out = readPointCloud((tmp / "red.ply").string());
  const PointField *red = out.layout().find("red");
  ASSERT_NE(red, nullptr);
  EXPECT_EQ(red->type, FieldType::UInt8);
  ASSERT_GT(out.size(), 0u);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double v = readAsDouble(out.record(i), *red);
    EXPECT_TRUE(v == 200.0 || v == 100.0) << v;
  }
}

// Found by fuzz_pcd (second campaign): a PCD field name with a non-ASCII byte was sampled and written into the PLY
// header, which the PLY reader refuses (non-ASCII header bytes make PCL misread it), so `hpds verify` failed on
// `hpds sample`'s output. writePly now refuses such names itself, with a printable message.
TEST(HostileCli, ANonAsciiFieldNameIsRefusedByThePlyWriter) {
  const fs::path input = fs::path(HPDS_SOURCE_DIR) / "test" / "regressions" / "pcd" / "non_ascii_field_name.pcd";
  const auto tmp = test::scratchDir("hostile_non_ascii");
  std::string log;
  EXPECT_EQ(hpds("sample " + q(input) + " -o " + q(tmp / "o.ply"), &log), 1) << log;
  EXPECT_NE(log.find("field name 'intensit?' is not a valid PLY property name"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(tmp / "o.ply"));
}

// Found by fuzz_ply (second campaign): obj_info lines after the vertex element still set the size PCL allocates
// for, unchecked: num_cols 299999999999 (wrapped to 3.6e9 points) made it allocate 36 GB, and a size below the vertex
// count makes it write past the cloud, which Debian's PCL turns into assert(false), SIGABRT. Run in a subprocess.
TEST(HostileCli, ObjInfoAfterTheVertexElementIsChecked) {
  const auto tmp = test::scratchDir("hostile_obj_info");
  writeText(tmp / "small.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                               "property float z\nobj_info num_cols 2\nend_header\n1 2 3\n4 5 6\n7 8 9\n1 1 1\n");
  std::string log;
  EXPECT_EQ(hpds("sample " + q(tmp / "small.ply") + " -o " + q(tmp / "o.ply"), &log), 1) << log;
  EXPECT_NE(log.find("obj_info num_cols/num_rows make the cloud 2 x 1 points, but element vertex has 4"),
            std::string::npos)
      << log;
  const fs::path input = fs::path(HPDS_SOURCE_DIR) / "test" / "regressions" / "ply" / "obj_info_after_vertex.ply";
  EXPECT_EQ(hpds("sample " + q(input) + " -o " + q(tmp / "o.ply"), &log), 1) << log;
  EXPECT_NE(log.find("3647256575 x 1"), std::string::npos) << log;
}

// Found by fuzz_ply: binary garbage in the header passed the reader's checks and then tripped an assert(false)
// inside PCL's PLYReader (ply_io.cpp:298), so `hpds sample` died with SIGABRT. Non-ASCII header bytes are now
// refused first. Run in a subprocess, so a regression shows as a failed exit code, not a dead test binary.
TEST(HostileCli, PlyThatTripsPclsAssertIsRefused) {
  const fs::path input = fs::path(HPDS_SOURCE_DIR) / "test" / "regressions" / "ply" / "pcl_assert.ply";
  const auto tmp = test::scratchDir("hostile_pcl_assert");
  std::string log;
  EXPECT_EQ(hpds("sample " + q(input) + " -o " + q(tmp / "o.ply"), &log), 1) << log;
}

// `hpds verify` on a raw scan (no level field) or on a file whose levels are not hpds's said only
// "verifySampling: sampling has no 'level' field", naming neither the file nor what to give instead.
TEST(HostileCli, VerifyNamesTheFileThatIsNotASampling) {
  const auto tmp = test::scratchDir("hostile_verify_not_sampling");
  writeText(tmp / "scan.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n"
                              "HEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n");
  writeText(tmp / "deep.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                              "property float z\nproperty uchar level\nend_header\n1 2 3 0\n4 5 6 99\n");
  runCases({
      {"verify " + q(tmp / "scan.pcd") + " --spacing 0.1", 1, "scan.pcd: no 'level' field"},
      {"verify " + q(tmp / "scan.pcd") + " --spacing 0.1", 1, "hpds sample"},
      {"verify " + q(tmp / "deep.ply") + " --cell-size 4", 1, "deep.ply: sample 1 has level 99"},
  });
}

// A PCD saved in a map frame keeps the sensor position in VIEWPOINT, and PCL's NormalEstimation faces it
// (use_sensor_origin_). hpds ignored it and turned every normal toward (0,0,0): here a floor 10 m above the origin,
// scanned from 10 m above the floor, came out with every normal pointing down, into the floor.
TEST(HostileCli, NormalsFaceThePcdViewpoint) {
  const auto tmp = test::scratchDir("hostile_viewpoint");
  std::string body;
  int n = 0;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j, ++n)
      body += std::to_string(0.05 * i) + " " + std::to_string(0.05 * j) + " 10\n";
  const std::string head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " +
                           std::to_string(n) + "\nHEIGHT 1\nVIEWPOINT ";
  const std::string tail = "\nPOINTS " + std::to_string(n) + "\nDATA ascii\n" + body;
  writeText(tmp / "floor.pcd", head + "+1 1 +20 1 0 0 0" + tail);  // PCL takes signed numbers
  std::string log;
  ASSERT_EQ(hpds("sample " + q(tmp / "floor.pcd") + " -o " + q(tmp / "o.ply") + " --spacing 0.2", &log), 0) << log;
  const PointBuffer out = readPointCloud((tmp / "o.ply").string());
  const PointField *nz = out.layout().find("normal_z");
  ASSERT_NE(nz, nullptr);
  std::size_t valid = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double v = readAsDouble(out.record(i), *nz);
    if (std::isnan(v)) continue;
    ++valid;
    EXPECT_GT(v, 0.9) << "sample " << i << " faces away from the VIEWPOINT above the floor";
  }
  EXPECT_GT(valid, out.size() / 2);
  // A VIEWPOINT position that cannot be faced is refused with the file and line named.
  writeText(tmp / "nan_vp.pcd", head + "nan 0 0 1 0 0 0" + tail);
  runCases({{"sample " + q(tmp / "nan_vp.pcd") + " -o " + q(tmp / "o.ply"), 1,
             "nan_vp.pcd: bad PCD header, line 8: VIEWPOINT position 'nan' is not a finite number"}});
}

}  // namespace
}  // namespace hpds
