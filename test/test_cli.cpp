// The `hpds` command as users run it: real frames sampled and verified, the PLY contract, map and scan streams,
// determinism, stats, and every class of bad input giving a clear error and a non-zero exit.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "TestData.hpp"
#include "hpds/config/Config.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/io/SamplingRecord.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds {
namespace {

using test::readText;
using test::runHpds;
using test::shellQuote;

// A flat square of n x n float32 points `step` apart at z = 1, as a PCD.
void writePlanePcd(const std::filesystem::path &path, int n, double step) {
  PointLayout l;
  for (const char *axis : {"x", "y", "z"}) l.append(axis, FieldType::Float32);
  PointBuffer plane(l, 0);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      plane.resize(plane.size() + 1);
      const double p[3] = {step * i, step * j, 1.0};
      for (int a = 0; a < 3; ++a) writeFromDouble(plane.record(plane.size() - 1), l.fields[a], p[a]);
    }
  writePcd(path.string(), plane);
}

int maxLevel(const PointBuffer &b) {
  const PointField *l = b.layout().find("level");
  int m = -1;
  for (std::size_t i = 0; i < b.size(); ++i) m = std::max(m, static_cast<int>(readAsDouble(b.record(i), *l)));
  return m;
}

TEST(Cli, EveryRealSensorFrameSamplesVerifiesAndKeepsItsFields) {
  HPDS_REQUIRE_SHARED_DATA();
  const auto dir = test::sharedLidarDir();
  const auto tmp = test::scratchDir("cli_real");
  for (const char *name : {"hdl32_a.pcd", "hdl32_b.pcd", "velodyne_vlp16.pcd", "velodyne_vlp32.pcd",
                           "velodyne_vls128.pcd", "hesai_xt32.pcd", "hesai_64.pcd", "hesai_ot128.pcd"}) {
    SCOPED_TRACE(name);
    const auto out = tmp / (std::string(name) + ".ply");
    std::string log;
    ASSERT_EQ(runHpds("sample " + shellQuote(dir / name) + " -o " + shellQuote(out) + " --normals --spacing 0.1", &log), 0) << log;
    // The cell is derived from the spacing (hierarchy.cell_size 0): verify derives it the same way.
    ASSERT_EQ(runHpds("verify " + shellQuote(out) + " --spacing 0.1 --input " + shellQuote(dir / name), &log), 0) << log;
    EXPECT_NE(log.find("OK: no violations"), std::string::npos) << log;
    const PointBuffer in = readPointCloud((dir / name).string());
    const PointBuffer s = readPointCloud(out.string());
    ASSERT_GT(s.size(), 100u);
    ASSERT_LT(s.size(), in.size());
    // Layout contract: x y z float, normals, then the other fields by element size (level uchar, every other input
    // field with its type).
    const std::vector<std::string> head = {"x", "y", "z", "normal_x", "normal_y", "normal_z", "curvature"};
    for (std::size_t i = 0; i < head.size(); ++i) EXPECT_EQ(s.layout().fields[i].name, head[i]);
    EXPECT_EQ(s.layout().find("level")->type, FieldType::UInt8);
    EXPECT_EQ(s.layout().find("x")->type, FieldType::Float32);
    for (const auto &f : in.layout().fields) {
      if (f.name == "x" || f.name == "y" || f.name == "z") continue;
      const PointField *o = s.layout().find(f.name);
      ASSERT_NE(o, nullptr) << f.name << " lost";
      EXPECT_EQ(o->type, f.type) << f.name;
    }
    EXPECT_EQ(maxLevel(s), 5);  // r_5 = 0.1 m exactly, with a level-0 cell of 2 * 0.1 / sqrt(3) * 2^5 = 3.695 m
  }
}

TEST(Cli, LevelAndSpacingSelectTheWrittenLevels) {
  HPDS_REQUIRE_SHARED_DATA();
  const auto in = test::sharedLidarDir() / "hesai_xt32.pcd";
  const auto tmp = test::scratchDir("cli_levels");
  ASSERT_EQ(runHpds("sample " + shellQuote(in) + " -o " + shellQuote(tmp / "l3.ply") + " --level 3"), 0);
  EXPECT_EQ(maxLevel(readPointCloud((tmp / "l3.ply").string())), 3);
  ASSERT_EQ(runHpds("sample " + shellQuote(in) + " -o " + shellQuote(tmp / "s.ply") + " --spacing 0.5 --cell-size 2"), 0);
  // r_D = sqrt(3)/2 * 2 / 2^D: r_1 = 0.866, r_2 = 0.433 <= 0.5 -> level 2.
  EXPECT_EQ(maxLevel(readPointCloud((tmp / "s.ply").string())), 2);
  std::string log;
  EXPECT_EQ(runHpds("sample " + shellQuote(in) + " -o " + shellQuote(tmp / "x.ply") + " --level 2 --spacing 0.5", &log), 2) << log;
}

TEST(Cli, Hdl32PairInMapModeWithPosesVerifies) {
  HPDS_REQUIRE_SHARED_DATA();
  const auto dir = test::sharedLidarDir();
  const auto tmp = test::scratchDir("cli_map");
  // KITTI pose file: frame a is the map frame, frame b's pose is the relative transform (3x4 of the 4x4).
  std::ifstream rel(dir / "hdl32_relative.txt");
  double m[16];
  for (double &v : m) rel >> v;
  ASSERT_TRUE(rel);
  {
    std::ofstream poses(tmp / "poses.txt");
    poses << "1 0 0 0 0 1 0 0 0 0 1 0\n";
    poses.precision(17);
    for (int i = 0; i < 12; ++i) poses << m[i] << (i == 11 ? "\n" : " ");
  }
  std::string log;
  ASSERT_EQ(runHpds("sample " + shellQuote(dir / "hdl32_a.pcd") + " " + shellQuote(dir / "hdl32_b.pcd") + " --mode map --poses " +
                     shellQuote(tmp / "poses.txt") + " --normals --spacing 0.2 -o " + shellQuote(tmp / "map.ply") + " --stats " +
                     shellQuote(tmp / "stats.json"),
                 &log),
            0)
      << log;
  ASSERT_EQ(runHpds("verify " + shellQuote(tmp / "map.ply") + " --spacing 0.2", &log), 0) << log;
  const PointBuffer map = readPointCloud((tmp / "map.ply").string());
  EXPECT_EQ(map.layout().find("frame"), nullptr);
  const std::string stats = readText(tmp / "stats.json");
  std::size_t zeros = 0;  // no-return points of both frames (5032 in hdl32_a per the data README)
  for (const char *name : {"hdl32_a.pcd", "hdl32_b.pcd"}) {
    const PointBuffer in = readPointCloud((dir / name).string());
    for (std::size_t i = 0; i < in.size(); ++i) {
      bool zero = true;
      for (int k = 0; k < 3; ++k) zero = zero && readAsDouble(in.record(i), in.layout().fields[k]) == 0.0;
      zeros += zero ? 1 : 0;
    }
  }
  EXPECT_GT(zeros, 5032u);
  const std::string zero_key = "\"skipped_zero\": " + std::to_string(zeros);
  for (const std::string &key : {std::string("\"seconds\""), std::string("\"read\""), std::string("\"insert\""),
                                std::string("\"normals\""), std::string("\"write\""), std::string("\"peak_memory_bytes\""),
                                std::string("\"levels\""), zero_key, std::string("\"frames\": 2"), std::string("\"mode\": \"map\"")})
    EXPECT_NE(stats.find(key), std::string::npos) << key << " missing in " << stats;
  // One pose too few is an error, not a silent identity.
  {
    std::ofstream one(tmp / "one.txt");
    one << "1 0 0 0 0 1 0 0 0 0 1 0\n";
  }
  EXPECT_EQ(runHpds("sample " + shellQuote(dir / "hdl32_a.pcd") + " " + shellQuote(dir / "hdl32_b.pcd") + " --mode map --poses " +
                     shellQuote(tmp / "one.txt") + " -o " + shellQuote(tmp / "x.ply"),
                 &log),
            1);
  EXPECT_NE(log.find("one pose per input"), std::string::npos) << log;
}

// Found: a second `synth` with fewer frames into the same folder left the first run's extra frames beside the new
// poses.txt. A run that would leave frames it does not write is refused, and changes nothing.
TEST(Cli, SynthRefusesAFolderWithFramesItWouldNotReplace) {
  const auto tmp = test::scratchDir("cli_synth_stale");
  const std::string dir = shellQuote(tmp / "s");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + dir + " --frames 3 --beams 8 --azimuth-steps 300", &log), 0) << log;
  const std::string poses = readText(tmp / "s" / "poses.txt");
  EXPECT_EQ(runHpds("synth -o " + dir + " --frames 2 --beams 8 --azimuth-steps 300 --seed 9", &log), 1) << log;
  EXPECT_NE(log.find("holds 1 frame file(s) this run would not replace (frame_000002.pcd)"), std::string::npos) << log;
  EXPECT_EQ(runHpds("synth -o " + dir + " --frames 3 --beams 8 --azimuth-steps 300 --format bin", &log), 1) << log;
  EXPECT_NE(log.find("holds 3 frame file(s)"), std::string::npos) << log;
  EXPECT_EQ(readText(tmp / "s" / "poses.txt"), poses);
  EXPECT_FALSE(std::filesystem::exists(tmp / "s" / "frame_000000.bin"));
  // The same frames again (or more): every old frame is replaced, so the folder stays one drive.
  EXPECT_EQ(runHpds("synth -o " + dir + " --frames 4 --beams 8 --azimuth-steps 300", &log), 0) << log;
  EXPECT_TRUE(std::filesystem::exists(tmp / "s" / "frame_000003.pcd"));
}

TEST(Cli, SyntheticStreamScanModeTagsFramesAndSeedsAreDeterministic) {
  const auto tmp = test::scratchDir("cli_synth");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 2 --beams 8 --azimuth-steps 600", &log), 0) << log;
  const std::string inputs = shellQuote(tmp / "s" / "frame_000000.pcd") + " " + shellQuote(tmp / "s" / "frame_000001.pcd");
  ASSERT_EQ(runHpds("sample " + inputs + " --mode scan --seed 5 -o " + shellQuote(tmp / "a.ply"), &log), 0) << log;
  ASSERT_EQ(runHpds("sample " + inputs + " --mode scan --seed 5 -o " + shellQuote(tmp / "b.ply")), 0);
  ASSERT_EQ(runHpds("sample " + inputs + " --mode scan --seed 6 -o " + shellQuote(tmp / "c.ply")), 0);
  EXPECT_EQ(readText(tmp / "a.ply"), readText(tmp / "b.ply"));
  // Scan-mode frames sampled by parallel workers: the same bytes as one thread.
  ASSERT_EQ(runHpds("sample " + inputs + " --mode scan --seed 5 --threads 2 --normals -o " + shellQuote(tmp / "p2.ply"), &log), 0) << log;
  ASSERT_EQ(runHpds("sample " + inputs + " --mode scan --seed 5 --threads 1 --normals -o " + shellQuote(tmp / "p1.ply"), &log), 0) << log;
  EXPECT_EQ(readText(tmp / "p1.ply"), readText(tmp / "p2.ply"));
  EXPECT_NE(readText(tmp / "a.ply"), readText(tmp / "c.ply"));
  const PointBuffer a = readPointCloud((tmp / "a.ply").string());
  const PointField *frame = a.layout().find("frame");
  ASSERT_NE(frame, nullptr);
  EXPECT_EQ(frame->type, FieldType::UInt32);
  std::set<double> frames;
  for (std::size_t i = 0; i < a.size(); ++i) frames.insert(readAsDouble(a.record(i), *frame));
  EXPECT_EQ(frames, (std::set<double>{0.0, 1.0}));
  for (const char *name : {"intensity", "ring", "time"}) EXPECT_NE(a.layout().find(name), nullptr) << name;
  // One sampling per frame (the frames overlap: checked as one they fail), verified frame by frame; coverage with
  // one frame's input.
  const std::string verify_a = "verify " + shellQuote(tmp / "a.ply") + " --spacing 0.1";
  EXPECT_EQ(runHpds(verify_a, &log), 0) << log;
  EXPECT_NE(log.find("2 frames checked on their own, 0 with violations"), std::string::npos) << log;
  EXPECT_EQ(runHpds(verify_a + " --frame 1 --input " + shellQuote(tmp / "s" / "frame_000001.pcd"), &log), 0) << log;
  EXPECT_EQ(runHpds(verify_a + " --frame 1 --input " + shellQuote(tmp / "s" / "frame_000000.pcd"), &log), 1)
      << "frame 1's samples do not cover frame 0's points\n" << log;
  EXPECT_EQ(runHpds(verify_a + " --input " + shellQuote(tmp / "s" / "frame_000001.pcd"), &log), 1) << log;
  EXPECT_NE(log.find("give every input in order (frame K is input K), or check one with --frame K"), std::string::npos) << log;
  EXPECT_EQ(runHpds(verify_a + " --frame 2", &log), 1) << log;
  EXPECT_NE(log.find("holds no sample of frame 2"), std::string::npos) << log;
  ASSERT_EQ(runHpds("sample " + inputs + " --mode map --poses " + shellQuote(tmp / "s" / "poses.txt") + " -o " + shellQuote(tmp / "m.ply") +
                     " --order sphericity --normals --threads 2",
                 &log),
            0)
      << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "m.ply") + " --spacing 0.1", &log), 0) << log;
}

// A recorded drive with an empty frame (a driver's first message, often with x y z only): scan mode writes the
// fields of the frames with samples, as map mode does, on one thread and on several.
TEST(Cli, ScanModeTakesAnEmptyFrameWithFewerFields) {
  const auto tmp = test::scratchDir("cli_empty_frame");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 2 --beams 8 --azimuth-steps 600", &log), 0) << log;
  {
    std::ofstream e(tmp / "empty.pcd");
    e << "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\nHEIGHT 1\n"
         "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 0\nDATA ascii\n";
  }
  const std::string f0 = shellQuote(tmp / "s" / "frame_000000.pcd"), f1 = shellQuote(tmp / "s" / "frame_000001.pcd"),
                    empty = shellQuote(tmp / "empty.pcd");
  // The empty frame keeps its place in the stream (its index), so each case has its own frame numbers.
  const std::vector<std::pair<std::string, std::set<double>>> cases = {
      {empty + " " + f0 + " " + f1, {1.0, 2.0}}, {f0 + " " + empty + " " + f1, {0.0, 2.0}}, {f0 + " " + f1 + " " + empty, {0.0, 1.0}}};
  for (const auto &[inputs, frames] : cases) {
    std::string bytes[2];
    for (int t = 0; t < 2; ++t) {
      const std::string args = inputs + " --no-normals --threads " + std::to_string(t + 1);
      ASSERT_EQ(runHpds("sample " + args + " -o " + shellQuote(tmp / "out.ply"), &log), 0) << args << "\n" << log;
      bytes[t] = readText(tmp / "out.ply");
      const PointBuffer out = readPointCloud((tmp / "out.ply").string());
      for (const char *name : {"intensity", "ring", "time"}) EXPECT_NE(out.layout().find(name), nullptr) << args;
      const PointField *frame = out.layout().find("frame");
      ASSERT_NE(frame, nullptr) << args;
      std::set<double> seen;
      for (std::size_t i = 0; i < out.size(); ++i) seen.insert(readAsDouble(out.record(i), *frame));
      EXPECT_EQ(seen, frames) << args;
    }
    EXPECT_EQ(bytes[0], bytes[1]) << inputs;
  }
  // Frames with samples and other fields are still refused, naming the frame.
  PointLayout l;
  for (const char *axis : {"x", "y", "z"}) l.append(axis, FieldType::Float32);
  PointBuffer xyz(l, 1);
  for (int a = 0; a < 3; ++a) writeFromDouble(xyz.record(0), l.fields[a], 1.0 + a);
  writePcd((tmp / "xyz.pcd").string(), xyz);
  EXPECT_EQ(runHpds("sample " + f0 + " " + shellQuote(tmp / "xyz.pcd") + " -o " + shellQuote(tmp / "bad.ply"), &log), 1);
  // Both sets of fields are named (the output's: the input's with hpds's own).
  EXPECT_NE(log.find("xyz.pcd' has other point fields (x y z normal_x"), std::string::npos) << log;
  EXPECT_NE(log.find("than the frames with samples before it (x y z normal_x normal_y normal_z curvature frame "
                     "intensity time ring level"),
            std::string::npos)
      << log;
}

TEST(Cli, CovariancesAreWrittenAsSixPlyPropertiesAfterTheNormals) {
  const auto tmp = test::scratchDir("cli_cov");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 1 --beams 16 --azimuth-steps 600", &log), 0) << log;
  const std::string input = shellQuote(tmp / "s" / "frame_000000.pcd");
  ASSERT_EQ(runHpds("sample " + input + " --spacing 0.2 --covariances -o " + shellQuote(tmp / "c.ply"), &log), 0) << log;
  const std::string text = readText(tmp / "c.ply");
  const std::string header = text.substr(0, text.find("end_header"));
  EXPECT_NE(header.find("property float curvature\nproperty float cov_xx\nproperty float cov_xy\nproperty float cov_xz\n"
                        "property float cov_yy\nproperty float cov_yz\nproperty float cov_zz\n"),
            std::string::npos)
      << header;
  const PointBuffer c = readPointCloud((tmp / "c.ply").string());
  const PointField *xx = c.layout().find("cov_xx"), *yy = c.layout().find("cov_yy"), *zz = c.layout().find("cov_zz");
  ASSERT_TRUE(xx && yy && zz);
  std::size_t valid = 0;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const double trace = readAsDouble(c.record(i), *xx) + readAsDouble(c.record(i), *yy) + readAsDouble(c.record(i), *zz);
    if (std::isnan(trace)) continue;
    // Eigenvalues (0.001, 1, 1) at the default epsilon, or the identity for a neighbourhood on one scan line.
    const bool plane = std::abs(trace - 2.001) < 1e-5, line = std::abs(trace - 3.0) < 1e-5;
    EXPECT_TRUE(plane || line) << trace;
    valid += plane ? 1 : 0;
  }
  EXPECT_GT(valid, c.size() / 2);
  ASSERT_EQ(runHpds("verify " + shellQuote(tmp / "c.ply") + " --spacing 0.2", &log), 0) << log;
  // Without the flag the same run writes no covariances.
  ASSERT_EQ(runHpds("sample " + input + " --spacing 0.2 --normals -o " + shellQuote(tmp / "n.ply"), &log), 0) << log;
  EXPECT_EQ(readText(tmp / "n.ply").find("cov_xx"), std::string::npos);
  // A config whose combination only the flags make valid is judged with them: it was refused before they applied.
  { std::ofstream y(tmp / "off.yaml"); y << "normals:\n  enabled: false\n  covariances: true\n"; }
  const std::string with_file = "sample " + input + " --spacing 0.2 --config " + shellQuote(tmp / "off.yaml");
  EXPECT_EQ(runHpds(with_file + " -o " + shellQuote(tmp / "refused.ply"), &log), 1) << log;
  EXPECT_NE(log.find("normals.covariances: needs normals.enabled"), std::string::npos) << log;
  EXPECT_NE(log.find("off.yaml, with the flags over it)"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(tmp / "refused.ply"));
  ASSERT_EQ(runHpds(with_file + " --normals -o " + shellQuote(tmp / "mended.ply"), &log), 0) << log;
  EXPECT_EQ(readText(tmp / "mended.ply"), text);
}

TEST(Cli, ScanModeWithASpacingBuildsAndReportsOnlyTheLevelsItWrites) {
  // With 4 m cells, --spacing 0.2 writes levels 0..5; scan mode then builds no deeper (with --normals too: they
  // average the frame's own points instead of levels 6..7), and the summary and --stats say so instead of listing
  // empty deeper levels. The written samples are the same as when every level is built (--level 8 writes them all;
  // its levels 0..5 are the same points).
  const auto tmp = test::scratchDir("cli_depth");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 1 --beams 8 --azimuth-steps 600", &log), 0) << log;
  const std::string input = shellQuote(tmp / "s" / "frame_000000.pcd");
  const std::string fixed = " --cell-size 4 --no-normals";
  ASSERT_EQ(runHpds("sample " + input + fixed + " --spacing 0.2 -o " + shellQuote(tmp / "a.ply") + " --stats " + shellQuote(tmp / "a.json"), &log), 0)
      << log;
  EXPECT_NE(log.find("dropped past level 5,"), std::string::npos) << log;
  const std::string stats = readText(tmp / "a.json");
  EXPECT_NE(stats.find("\"built_depth\": 5,"), std::string::npos) << stats;
  EXPECT_NE(stats.find("\"max_depth\": 8,"), std::string::npos) << stats;
  std::size_t listed = 0;
  for (std::size_t at = stats.find("{\"level\": "); at != std::string::npos; at = stats.find("{\"level\": ", at + 1)) ++listed;
  EXPECT_EQ(listed, 6u) << stats;
  ASSERT_EQ(runHpds("sample " + input + " --cell-size 4 --spacing 0.2 --normals -o " + shellQuote(tmp / "n.ply") + " --stats " + shellQuote(tmp / "n.json"), &log), 0)
      << log;
  EXPECT_NE(readText(tmp / "n.json").find("\"built_depth\": 5,"), std::string::npos);

  ASSERT_EQ(runHpds("sample " + input + fixed + " --level 8 -o " + shellQuote(tmp / "all.ply"), &log), 0) << log;
  const PointBuffer a = readPointCloud((tmp / "a.ply").string()), all = readPointCloud((tmp / "all.ply").string());
  const PointField *level = all.layout().find("level");
  ASSERT_NE(level, nullptr);
  std::vector<std::string> from_all;
  for (std::size_t i = 0; i < all.size(); ++i)
    if (readAsDouble(all.record(i), *level) <= 5.0)
      from_all.emplace_back(reinterpret_cast<const char *>(all.record(i)), all.layout().point_step);
  ASSERT_EQ(a.layout().point_step, all.layout().point_step);
  std::vector<std::string> from_a;
  for (std::size_t i = 0; i < a.size(); ++i) from_a.emplace_back(reinterpret_cast<const char *>(a.record(i)), a.layout().point_step);
  EXPECT_GT(from_a.size(), 100u);
  EXPECT_LT(from_a.size(), all.size());
  EXPECT_EQ(from_a, from_all);
}

TEST(Cli, VerifyCatchesABrokenSampling) {
  const auto tmp = test::scratchDir("cli_verify");
  PointLayout l;
  l.append("x", FieldType::Float32);
  l.append("y", FieldType::Float32);
  l.append("z", FieldType::Float32);
  l.append("level", FieldType::UInt8);
  PointBuffer b(l, 3);
  const double pts[3][4] = {{0.5, 0.5, 0.5, 0}, {0.6, 0.5, 0.5, 1}, {9, 9, 9, 0}};  // 0.1 m apart at r_1 = 1.73 m
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 4; ++k) writeFromDouble(b.record(i), l.fields[k], pts[i][k]);
  writePly((tmp / "bad.ply").string(), b);
  std::string log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "bad.ply") + " --cell-size 4", &log), 1) << log;
  EXPECT_NE(log.find("FAILED"), std::string::npos) << log;
  // The help advertised [0, 1e6] for both lengths, and 0 failed later with exit 1: a bad command line, said as such.
  for (const std::string flag : {" --cell-size 0", " --spacing 0", " --spacing -1"}) {
    EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "bad.ply") + flag, &log), 2) << flag << log;
    EXPECT_NE(log.find("must be a finite number in (0, "), std::string::npos) << log;
  }
  EXPECT_EQ(runHpds("verify --help", &log), 0);
  EXPECT_EQ(log.find("[0, 1e"), std::string::npos) << log;
}

// Found in a user trial: no way to tell which hpds a script runs. One version, from package.xml via CMake.
TEST(Cli, VersionIsTheProjectsAndExitsZero) {
  std::string log;
  EXPECT_EQ(runHpds("--version", &log), 0);
  EXPECT_NE(log.find("hpds " HPDS_TEST_VERSION), std::string::npos) << log;
}

// A folder stands for its frames in name order; found preprocessing a recorded drive, where `hpds sample frames/`
// said "not a regular file" and a drive of many frames needed a glob the shell may refuse.
TEST(Cli, AFolderInputIsItsFramesInNameOrder) {
  const auto tmp = test::scratchDir("cli_folder");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 3 --beams 8 --azimuth-steps 600", &log), 0) << log;
  std::string listed;
  for (int i = 0; i < 3; ++i) listed += shellQuote(tmp / "s" / ("frame_00000" + std::to_string(i) + ".pcd")) + " ";
  const std::string map = " --mode map --spacing 0.2 --poses " + shellQuote(tmp / "s" / "poses.txt") + " -o ";
  ASSERT_EQ(runHpds("sample " + listed + map + shellQuote(tmp / "listed.ply"), &log), 0) << log;
  // poses.txt beside the frames is not a frame.
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "s") + map + shellQuote(tmp / "folder.ply"), &log), 0) << log;
  EXPECT_EQ(readText(tmp / "folder.ply"), readText(tmp / "listed.ply"));
  std::filesystem::create_directories(tmp / "empty");
  std::ofstream(tmp / "empty" / "notes.txt") << "no frames here\n";
  EXPECT_EQ(runHpds("sample " + shellQuote(tmp / "empty") + " -o " + shellQuote(tmp / "e.ply"), &log), 1) << log;
  EXPECT_NE(log.find("holds no .pcd, .ply or .bin frame"), std::string::npos) << log;
  // An output saved into the folder came back as a frame on the next run (a trial's second run read 229 069 points
  // for 172 800): hpds's own PLY files are left out, and said to be; so are hidden files.
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "s") + " --spacing 0.2 -o " + shellQuote(tmp / "s" / "out.ply"), &log),
            0)
      << log;
  EXPECT_NE(log.find("hpds: folder '"), std::string::npos) << log;
  EXPECT_NE(log.find("3 inputs in name order, 'frame_000000.pcd' to 'frame_000002.pcd'"), std::string::npos) << log;
  std::filesystem::copy_file(tmp / "s" / "frame_000001.pcd", tmp / "s" / ".hidden.pcd");
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "s") + " --spacing 0.2 -o " + shellQuote(tmp / "s" / "again.ply"), &log),
            0)
      << log;
  EXPECT_NE(log.find("out.ply' left out of folder"), std::string::npos) << log;
  EXPECT_NE(log.find("samples written by hpds (an output, not a frame; name it to take it)"), std::string::npos) << log;
  EXPECT_NE(log.find(".hidden.pcd' left out of folder"), std::string::npos) << log;
  EXPECT_EQ(readText(tmp / "s" / "again.ply"), readText(tmp / "s" / "out.ply"));
  // Natural name order: unpadded numbers meet their pose lines (frame_2 before frame_10).
  std::filesystem::create_directories(tmp / "n");
  for (const auto &[from, to] : {std::pair{"frame_000000.pcd", "f_1.pcd"}, std::pair{"frame_000001.pcd", "f_2.pcd"},
                                 std::pair{"frame_000002.pcd", "f_10.pcd"}})
    std::filesystem::copy_file(tmp / "s" / from, tmp / "n" / to);
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "n") + map + shellQuote(tmp / "natural.ply"), &log), 0) << log;
  EXPECT_EQ(readText(tmp / "natural.ply"), readText(tmp / "listed.ply"));
  EXPECT_EQ(log.find("warning: --poses"), std::string::npos) << log;
  // The same files in the order a shell glob gives (text order: f_10 before f_2) are taken as given, and a trial's
  // map was posed wrong without a word: now a warning names the pair and says to give the folder.
  const std::string glob_order = shellQuote(tmp / "n" / "f_1.pcd") + " " + shellQuote(tmp / "n" / "f_10.pcd") + " " +
                                 shellQuote(tmp / "n" / "f_2.pcd");
  ASSERT_EQ(runHpds("sample " + glob_order + map + shellQuote(tmp / "glob.ply"), &log), 0) << log;
  EXPECT_NE(log.find("hpds: warning: --poses: '" + (tmp / "n" / "f_10.pcd").string() + "' is given before '" +
                     (tmp / "n" / "f_2.pcd").string() + "'"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("give the folder '" + (tmp / "n").string() + "' itself"), std::string::npos) << log;
  EXPECT_NE(readText(tmp / "glob.ply"), readText(tmp / "natural.ply"));
  // Frames hpds writes as PLY (`synth --format ply`) are frames: a trial's folder of them was refused as "holds no
  // frame" because every PLY hpds wrote carried the outputs' mark.
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "p") + " --frames 3 --beams 8 --azimuth-steps 600 --format ply",
                    &log),
            0)
      << log;
  const std::string ply_map = " --mode map --spacing 0.2 --poses " + shellQuote(tmp / "p" / "poses.txt") + " -o ";
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "p") + ply_map + shellQuote(tmp / "plyframes.ply"), &log), 0) << log;
  EXPECT_NE(log.find("3 inputs in name order"), std::string::npos) << log;
  EXPECT_EQ(log.find("left out"), std::string::npos) << log;
}

// Found in a trial: `hpds sample --config` accepted a `ros:` section the node refuses (queue_size 0), although the
// config says every reader checks it as the node does; it is checked against the file's own keys, as the node
// reads the file, so that flags for the sampling (--mode scan) cannot make a node file fail.
TEST(Cli, AConfigsRosSectionIsCheckedAsTheNodeChecksIt) {
  const auto tmp = test::scratchDir("cli_ros_section");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 1 --beams 8 --azimuth-steps 600", &log), 0) << log;
  const std::string frame = shellQuote(tmp / "s" / "frame_000000.pcd");
  std::ofstream(tmp / "bad.yaml") << "ros:\n  queue_size: 0\n";
  EXPECT_EQ(runHpds("sample " + frame + " --config " + shellQuote(tmp / "bad.yaml") + " -o " + shellQuote(tmp / "a.ply"),
                    &log),
            1)
      << log;
  EXPECT_NE(log.find("ros.queue_size: must be in 1..1000, got 0 (in " + (tmp / "bad.yaml").string() + ")"),
            std::string::npos)
      << log;
  EXPECT_FALSE(std::filesystem::exists(tmp / "a.ply"));
  std::ofstream(tmp / "node.yaml") << "mode: map\nros:\n  fixed_frame: odom\n  map_file: m.hpdsmap\n"
                                      "  load_map_on_start: true\n";
  EXPECT_EQ(runHpds("sample " + frame + " --config " + shellQuote(tmp / "node.yaml") + " --mode scan -o " +
                        shellQuote(tmp / "b.ply"),
                    &log),
            0)
      << log;
}

// Found in a trial: NaN-only frames gave "wrote 0 samples" and exit 0, and nothing said why the map was empty.
TEST(Cli, AnEmptyOutputSaysWhy) {
  const auto tmp = test::scratchDir("cli_empty_output");
  PointLayout l;
  for (const char *axis : {"x", "y", "z"}) l.append(axis, FieldType::Float32);
  PointBuffer nan_cloud(l, 50);
  for (std::size_t i = 0; i < nan_cloud.size(); ++i) {
    writeFromDouble(nan_cloud.record(i), l.fields[0], std::nan(""));
    writeFromDouble(nan_cloud.record(i), l.fields[1], double(i));
    writeFromDouble(nan_cloud.record(i), l.fields[2], 1.0);
  }
  writePly((tmp / "nan.ply").string(), nan_cloud);
  std::string log;
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "nan.ply") + " --spacing 0.2 -o " + shellQuote(tmp / "out.ply"), &log),
            0)
      << log;
  EXPECT_NE(log.find("wrote 0 samples"), std::string::npos) << log;
  EXPECT_NE(log.find("hpds: warning: the output holds no sample: of 50 input points: 50 NaN/Inf"), std::string::npos)
      << log;
}

// Found offline: verify could not check a posed map's coverage: its one --input was in the sensor frame, the map in
// the pose frame, and every point read as uncovered. --input takes the map's frames and --poses poses them.
TEST(Cli, VerifyChecksAPosedMapAgainstItsPosedFrames) {
  const auto tmp = test::scratchDir("cli_verify_poses");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 3 --beams 8 --azimuth-steps 600", &log), 0) << log;
  std::string frames;
  for (int i = 0; i < 3; ++i) frames += shellQuote(tmp / "s" / ("frame_00000" + std::to_string(i) + ".pcd")) + " ";
  const std::string poses = " --poses " + shellQuote(tmp / "s" / "poses.txt");
  ASSERT_EQ(runHpds("sample " + frames + "--mode map --spacing 0.2" + poses + " -o " + shellQuote(tmp / "map.ply"), &log),
            0)
      << log;
  const std::string verify = "verify " + shellQuote(tmp / "map.ply") + " --spacing 0.2";
  EXPECT_EQ(runHpds(verify + " --input " + frames + poses, &log), 0) << log;
  EXPECT_NE(log.find("OK: no violations"), std::string::npos) << log;
  // Unposed, the frames lie where the sensor saw them, and the drive moved: coverage fails, as it should.
  EXPECT_EQ(runHpds(verify + " --input " + frames, &log), 1) << log;
  EXPECT_EQ(runHpds(verify + " --input " + shellQuote(tmp / "s") + poses, &log), 0) << log;  // a folder, as sample
  EXPECT_EQ(runHpds(verify + poses, &log), 1) << log;
  EXPECT_NE(log.find("--poses: give the --input frames it poses"), std::string::npos) << log;
  const std::string first = shellQuote(tmp / "s" / "frame_000000.pcd");
  EXPECT_EQ(runHpds(verify + " --input " + first + poses, &log), 1) << log;
  EXPECT_NE(log.find("3 poses for 1 inputs: one pose per input, by order"), std::string::npos) << log;
  // A scan-mode output of posed frames: frame K against its input posed by line K.
  ASSERT_EQ(runHpds("sample " + frames + "--spacing 0.2" + poses + " -o " + shellQuote(tmp / "scan.ply"), &log), 0)
      << log;
  const std::string second = shellQuote(tmp / "s" / "frame_000001.pcd");
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "scan.ply") + " --spacing 0.2 --frame 1 --input " + second + poses,
                    &log),
            0)
      << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "scan.ply") + " --spacing 0.2 --frame 1 --input " + first + poses,
                    &log),
            1)
      << log;
  // All frames in one run: frame K against input K, posed by line K; inputs in another order fail.
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "scan.ply") + " --spacing 0.2 --input " + frames + poses, &log), 0)
      << log;
  EXPECT_NE(log.find("3 frames checked on their own, 0 with violations"), std::string::npos) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "scan.ply") + " --spacing 0.2 --input " + second + " " + first + " " +
                        shellQuote(tmp / "s" / "frame_000002.pcd") + poses,
                    &log),
            1)
      << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "scan.ply") + " --spacing 0.2 --input " + first + " " + second, &log),
            1)
      << log;
  EXPECT_NE(log.find("holds frame 2, but 2 inputs were given"), std::string::npos) << log;
}

// A trajectory from a SLAM tool in TUM form (time x y z qx qy qz qw, a '#' header) poses the frames as the KITTI file
// of the same poses: the map it builds passes verify against the KITTI-posed frames.
TEST(Cli, TumTrajectoryPosesTheFramesAsKittiPosesDo) {
  const auto tmp = test::scratchDir("cli_tum_poses");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 3 --beams 8 --azimuth-steps 600", &log), 0) << log;
  {
    std::ofstream tum(tmp / "trajectory.tum");
    tum << "# timestamp tx ty tz qx qy qz qw\n";
    tum.precision(17);
    double t = 1.7e9;
    for (const Eigen::Isometry3d &p : readKittiPoses((tmp / "s" / "poses.txt").string())) {
      const Eigen::Quaterniond q(p.linear());
      tum << (t += 0.1) << " " << p.translation().x() << " " << p.translation().y() << " " << p.translation().z()
          << " " << q.x() << " " << q.y() << " " << q.z() << " " << q.w() << "\n";
    }
  }
  std::string frames;
  for (int i = 0; i < 3; ++i) frames += shellQuote(tmp / "s" / ("frame_00000" + std::to_string(i) + ".pcd")) + " ";
  for (const auto &[poses, out] : {std::pair{"trajectory.tum", "tum.ply"}, std::pair{"s/poses.txt", "kitti.ply"}})
    ASSERT_EQ(runHpds("sample " + frames + "--mode map --spacing 0.2 --poses " + shellQuote(tmp / poses) + " -o " +
                          shellQuote(tmp / out),
                      &log),
              0)
        << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "tum.ply") + " --spacing 0.2 --input " + frames + " --poses " +
                        shellQuote(tmp / "s" / "poses.txt"),
                    &log),
            0)
      << log;
  const double tum_samples = double(readPointCloud((tmp / "tum.ply").string()).size());
  EXPECT_NEAR(tum_samples, double(readPointCloud((tmp / "kitti.ply").string()).size()), 0.005 * tum_samples);
  // Unposed, the same check fails: the poses moved the frames.
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "tum.ply") + " --spacing 0.2 --input " + frames, &log), 1) << log;
}

// Found with a frame moved to UTM coordinates as a PLY (no VIEWPOINT): normals faced the origin, 5e6 m away, half of
// them away from the sensor, without a word, and the CLI had no way to say where the sensor was.
TEST(Cli, AViewpointFarFromEveryPointIsSaidAndViewpointSetsIt) {
  const auto tmp = test::scratchDir("cli_viewpoint");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 1 --beams 16 --azimuth-steps 900", &log), 0)
      << log;
  PointBuffer shifted = readPointCloud((tmp / "s" / "frame_000000.pcd").string());
  const PointField *x = shifted.layout().find("x");
  ASSERT_TRUE(x && x->type == FieldType::Float32);
  const double kOffset = 3000.0;
  for (std::size_t i = 0; i < shifted.size(); ++i) {
    float v;
    std::memcpy(&v, shifted.record(i) + x->offset, 4);
    v = static_cast<float>(v + kOffset);
    std::memcpy(shifted.record(i) + x->offset, &v, 4);
  }
  writePly((tmp / "shifted.ply").string(), shifted);
  const std::string run = "sample " + shellQuote(tmp / "shifted.ply") + " --spacing 0.2 -o ";
  // The share of normals facing the sensor (at x = kOffset).
  auto facing = [&](const std::string &ply) {
    const PointBuffer c = readPointCloud((tmp / ply).string());
    const PointLayout &l = c.layout();
    std::size_t toward = 0, valid = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
      double d = 0.0;
      for (const auto &[p, n] : {std::pair{"x", "normal_x"}, std::pair{"y", "normal_y"}, std::pair{"z", "normal_z"}}) {
        const double sensor = std::string(p) == "x" ? kOffset : 0.0;
        d += (sensor - readAsDouble(c.record(i), *l.find(p))) * readAsDouble(c.record(i), *l.find(n));
      }
      if (std::isnan(d)) continue;
      ++valid;
      toward += d > 0.0 ? 1 : 0;
    }
    return valid ? static_cast<double>(toward) / static_cast<double>(valid) : 0.0;
  };
  ASSERT_EQ(runHpds(run + shellQuote(tmp / "origin.ply"), &log), 0) << log;
  EXPECT_NE(log.find("hpds: warning: the nearest point of"), std::string::npos) << log;
  EXPECT_NE(log.find("give the sensor's position with --viewpoint X Y Z"), std::string::npos) << log;
  ASSERT_EQ(runHpds(run + shellQuote(tmp / "sensor.ply") + " --viewpoint 3000 0 0", &log), 0) << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  const double at_origin = facing("origin.ply"), at_sensor = facing("sensor.ply");
  EXPECT_GT(at_sensor, 0.9);
  EXPECT_LT(at_origin, at_sensor - 0.1);
  EXPECT_EQ(runHpds(run + shellQuote(tmp / "bad.ply") + " --viewpoint 1 2", &log), 2) << log;
  EXPECT_NE(log.find("--viewpoint"), std::string::npos) << log;
}

// `hpds smaple x.pcd` was answered "A subcommand is required", as if none had been given.
TEST(Cli, AnUnknownCommandIsNamedWithTheKnownOnes) {
  std::string log;
  EXPECT_EQ(runHpds("smaple x.pcd -o y.ply", &log), 2);
  EXPECT_NE(log.find("hpds: error: unknown command 'smaple': one of sample, verify, synth"), std::string::npos) << log;
  EXPECT_EQ(runHpds("", &log), 2);
  EXPECT_NE(log.find("hpds: error: A subcommand is required"), std::string::npos) << log;
}

// A --spacing with another --max-depth than the sampling's derives another cell, under which every radius shrinks
// and any sampling passes: `verify --spacing 0.1 --max-depth 0` passed a sampling of levels 0..5 whatever it held.
TEST(Cli, VerifyRefusesLevelsDeeperThanItsSpacingMakes) {
  const auto tmp = test::scratchDir("cli_verify_depth");
  writePlanePcd(tmp / "plane.pcd", 150, 0.02);
  std::string log;
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "plane.pcd") + " --no-normals -o " + shellQuote(tmp / "s.ply"), &log),
            0)
      << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "s.ply") + " --spacing 0.1", &log), 0) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "s.ply") + " --spacing 0.1 --max-depth 0", &log), 1) << log;
  EXPECT_NE(log.find("holds level 5"), std::string::npos) << log;
  EXPECT_NE(log.find("levels 0..0"), std::string::npos) << log;

  // Found: a sampling without its finest levels, and an empty one, passed `verify --spacing 0.1 --input`: only the
  // levels present were checked. The level --spacing gives counts, present or not.
  const PointBuffer full = readPointCloud((tmp / "s.ply").string());
  const PointField &level = *full.layout().find("level");
  PointBuffer coarse(full.layout(), 0), none(full.layout(), 0);
  for (std::size_t i = 0; i < full.size(); ++i)
    if (readAsDouble(full.record(i), level) <= 3.0) coarse.pushBack(full.record(i));
  ASSERT_GT(coarse.size(), 0u);
  ASSERT_LT(coarse.size(), full.size());
  writePly((tmp / "coarse.ply").string(), coarse);
  writePly((tmp / "none.ply").string(), none);
  const std::string input = " --input " + shellQuote(tmp / "plane.pcd");
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "s.ply") + " --spacing 0.1" + input, &log), 0) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "coarse.ply") + " --spacing 0.1" + input, &log), 1) << log;
  EXPECT_NE(log.find("FAILED"), std::string::npos) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "coarse.ply") + " --spacing 0.1", &log), 0) << log;
  EXPECT_NE(log.find("note: level 5 (the level --spacing gives) holds no sample"), std::string::npos) << log;
  for (const std::string cell : {" --spacing 0.1", " --cell-size 4"}) {
    EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "none.ply") + cell + input, &log), 1) << cell << log;
    EXPECT_NE(log.find("FAILED: "), std::string::npos) << log;
    EXPECT_NE(log.find("the sampling holds no sample"), std::string::npos) << log;
  }
}

// Found offline: verify and analyze had to be told the cell (--spacing, --max-depth) the file was sampled with,
// which its header did not keep, and a wrong one could pass unnoticed. hpds sample records it; verify reads it.
TEST(Cli, VerifyAndAnalyzeReadTheCellTheSamplingRecords) {
  const auto tmp = test::scratchDir("cli_verify_record");
  writePlanePcd(tmp / "plane.pcd", 120, 0.025);
  std::string log;
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "plane.pcd") + " --spacing 0.15 --max-depth 6 --no-normals -o " +
                        shellQuote(tmp / "s.ply"),
                    &log),
            0)
      << log;
  const std::optional<SamplingRecord> record = readSamplingRecord((tmp / "s.ply").string());
  ASSERT_TRUE(record.has_value());
  EXPECT_EQ(record->max_depth, 6);
  EXPECT_NEAR(poissonRadius(record->cell_size, record->output_level), 0.15, 1e-12);
  const std::string input = " --input " + shellQuote(tmp / "plane.pcd");
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "s.ply") + input, &log), 0) << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  EXPECT_NE(log.find("as its header records: level-0 cell "), std::string::npos) << log;
  EXPECT_NE(log.find("max_depth 6, output level " + std::to_string(record->output_level)), std::string::npos) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "s.ply") + " --spacing 0.15 --max-depth 6", &log), 0) << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  // Flags that disagree with the record are used, and said to disagree.
  runHpds("verify " + shellQuote(tmp / "s.ply") + " --spacing 0.1", &log);
  EXPECT_NE(log.find("was sampled with cell size"), std::string::npos) << log;
  EXPECT_EQ(runHpds("analyze " + shellQuote(tmp / "s.ply") + " -o " + shellQuote(tmp / "analysis"), &log), 0) << log;
  EXPECT_NE(readText(tmp / "analysis" / "analysis.json").find("\"cell_size\": "), std::string::npos);

  // The record's output level must be reached: a file holding only levels 0..2 of it fails coverage.
  const PointBuffer full = readPointCloud((tmp / "s.ply").string());
  const PointField &level = *full.layout().find("level");
  PointBuffer coarse(full.layout(), 0);
  for (std::size_t i = 0; i < full.size(); ++i)
    if (readAsDouble(full.record(i), level) <= 2.0) coarse.pushBack(full.record(i));
  ASSERT_LT(coarse.size(), full.size());
  writePly((tmp / "coarse.ply").string(), coarse, *record);
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "coarse.ply") + input, &log), 1) << log;
  EXPECT_NE(log.find("FAILED"), std::string::npos) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "coarse.ply"), &log), 0) << log;
  EXPECT_NE(log.find("(the output level its header records) holds no sample"), std::string::npos) << log;
  // A file holding deeper levels than its record says is not what the record says.
  SamplingRecord shallow = *record;
  shallow.output_level = 2;
  writePly((tmp / "deeper.ply").string(), full, shallow);
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "deeper.ply"), &log), 1) << log;
  EXPECT_NE(log.find("but its header records levels 0..2"), std::string::npos) << log;
  // Without a record, the flags are still required, and the message says why.
  writePly((tmp / "bare.ply").string(), full, PlyContent::kSamples);
  for (const std::string &cmd : {"verify " + shellQuote(tmp / "bare.ply"),
                                "analyze " + shellQuote(tmp / "bare.ply") + " -o " + shellQuote(tmp / "a2")}) {
    EXPECT_EQ(runHpds(cmd, &log), 1) << cmd << log;
    EXPECT_NE(log.find("--cell-size or --spacing is required"), std::string::npos) << log;
    EXPECT_NE(log.find("does not record the cell"), std::string::npos) << log;
  }
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "bare.ply") + " --spacing 0.15 --max-depth 6" + input, &log), 0)
      << log;
}

TEST(Cli, BadInputGivesAClearErrorAndNonZeroExit) {
  const auto tmp = test::scratchDir("cli_bad");
  const std::string out = " -o " + shellQuote(tmp / "out.ply");
  std::mt19937_64 rng(1);
  {
    std::ofstream g(tmp / "garbage.pcd", std::ios::binary);
    for (int i = 0; i < 5000; ++i) g.put(static_cast<char>(rng()));
  }
  { std::ofstream e(tmp / "empty.pcd"); }
  {
    std::ofstream t(tmp / "truncated.pcd", std::ios::binary);
    t << "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\nHEIGHT 1\n"
         "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1000\nDATA binary\n";
    for (int i = 0; i < 100; ++i) t.put('\0');
  }
  { std::ofstream b(tmp / "odd.bin", std::ios::binary); b << "12345678901234567"; }
  { std::ofstream y(tmp / "bad.yaml"); y << "hierarchy:\n  cell_sise: 2\n"; }
  { std::ofstream y(tmp / "neg.yaml"); y << "hierarchy:\n  cell_size: -1\n"; }
  { std::ofstream y(tmp / "cov.yaml"); y << "normals:\n  enabled: false\n  covariances: true\n"; }
  { std::ofstream y(tmp / "ros.yaml"); y << "ros:\n  queue_sise: 3\n"; }
  struct Case {
    std::string args;
    int code;
    std::string message;
  };
  const std::vector<Case> cases = {
      {shellQuote(tmp / "missing.pcd") + out, 1, "missing.pcd"},
      {shellQuote(tmp / "garbage.pcd") + out, 1, "garbage.pcd"},
      {shellQuote(tmp / "empty.pcd") + out, 1, "empty.pcd"},
      {shellQuote(tmp / "truncated.pcd") + out, 1, "truncated"},
      {shellQuote(tmp / "odd.bin") + out, 1, "odd.bin"},
      {shellQuote(tmp / "cloud.xyz") + out, 1, "cloud.xyz"},
      {shellQuote(tmp / "odd.bin") + out + " --config " + shellQuote(tmp / "bad.yaml"), 1, "hierarchy.cell_sise"},
      {shellQuote(tmp / "odd.bin") + out + " --config " + shellQuote(tmp / "neg.yaml"), 1, "hierarchy.cell_size"},
      // A bad flag value is a bad command line (2), named by its flag: it was exit 1 naming the config key.
      {shellQuote(tmp / "odd.bin") + out + " --max-depth 22", 2, "--max-depth"},
      {shellQuote(tmp / "odd.bin") + out + " --cell-size nan", 2, "--cell-size"},
      {shellQuote(tmp / "odd.bin") + out + " --order zigzag", 2, "--order: zigzag not in {random,input,sphericity,surface_variation}"},
      {shellQuote(tmp / "odd.bin") + out + " --level 30", 2, "--level"},
      {shellQuote(tmp / "odd.bin") + out + " --spacing 0", 2, "--spacing: must be a finite number in (0, "},
      {shellQuote(tmp / "odd.bin") + out + " --threads 5000", 2, "--threads"},
      {shellQuote(tmp / "odd.bin") + out + " --seed -1", 2, "--seed"},
      {shellQuote(tmp / "odd.bin") + out + " --config " + shellQuote(tmp / "cov.yaml"), 1, "normals.covariances"},
      // the node's own keys are checked as the node checks them: a file the CLI accepts, the node accepts
      {shellQuote(tmp / "odd.bin") + out + " --config " + shellQuote(tmp / "ros.yaml"), 1, "ros.queue_sise: unknown key"},
      {shellQuote(tmp / "odd.bin"), 2, "output"},
  };
  for (const Case &c : cases) {
    std::string log;
    EXPECT_EQ(runHpds("sample " + c.args, &log), c.code) << c.args << "\n" << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
    if (c.code == 1) {
      EXPECT_NE(log.find("hpds: error:"), std::string::npos) << log;
    }
  }
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "garbage.pcd") + " --cell-size 4"), 1);
}

TEST(Cli, NanOnlyAndHugeCoordinateFramesAreCountedNotFatal) {
  const auto tmp = test::scratchDir("cli_nan");
  PointLayout l;
  for (const char *n : {"x", "y", "z", "intensity"}) l.append(n, FieldType::Float32);
  PointBuffer nan(l, 50), huge(l, 3);
  for (std::size_t i = 0; i < 50; ++i)
    for (int k = 0; k < 3; ++k) writeFromDouble(nan.record(i), l.fields[k], i % 2 ? NAN : INFINITY);
  const double far[3][3] = {{1e7, 0, 0}, {0, -1e7, 5}, {1, 2, 3}};
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) writeFromDouble(huge.record(i), l.fields[k], far[i][k]);
  writeKittiBin((tmp / "nan.bin").string(), nan);
  writeKittiBin((tmp / "huge.bin").string(), huge);
  std::string log;
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "nan.bin") + " -o " + shellQuote(tmp / "nan.ply") + " --stats " + shellQuote(tmp / "nan.json"), &log), 0)
      << log;
  EXPECT_NE(readText(tmp / "nan.json").find("\"skipped_invalid\": 50"), std::string::npos);
  EXPECT_EQ(readPointCloud((tmp / "nan.ply").string()).size(), 0u);
  // 1e7 m with 2^-21 * 1 m cells is beyond exact keys: counted and warned about, the near point still sampled.
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "huge.bin") + " -o " + shellQuote(tmp / "huge.ply") + " --cell-size 1 --max-depth 21", &log), 0)
      << log;
  EXPECT_NE(log.find("beyond the exact key range"), std::string::npos) << log;
  EXPECT_EQ(readPointCloud((tmp / "huge.ply").string()).size(), 1u);
  // At 4 m cells and depth 8 the same coordinates are exact and all three are kept.
  ASSERT_EQ(runHpds("sample " + shellQuote(tmp / "huge.bin") + " -o " + shellQuote(tmp / "huge8.ply"), &log), 0) << log;
  EXPECT_EQ(readPointCloud((tmp / "huge8.ply").string()).size(), 3u);
}

// Points beyond the exact key range of the finest level are never inserted (counted as out_of_range), so no sample
// covers them: `verify --input` counted them as uncovered and failed a sampling that did all it could.
TEST(Cli, VerifyLeavesInputPointsBeyondTheKeyRangeOutOfCoverage) {
  const auto tmp = test::scratchDir("cli_verify_key_range");
  PointLayout l;
  for (const char *n : {"x", "y", "z"}) l.append(n, FieldType::Float32);
  // 1.6e7 m: beyond 2^30 cells of the finest level at the default spacing and depth (1.55e7 m), within them at 4 m
  // cells (1.68e7 m).
  const double pts[5][3] = {{1.6e7, 0, 0}, {0, -1.6e7, 5}, {1, 2, 3}, {1.05, 2, 3}, {3, 2, 1}};
  PointBuffer frame(l, 5);
  for (int i = 0; i < 5; ++i)
    for (int k = 0; k < 3; ++k) writeFromDouble(frame.record(i), l.fields[k], pts[i][k]);
  writeKittiBin((tmp / "far.bin").string(), frame);
  const std::string in = shellQuote(tmp / "far.bin");
  std::string log;
  ASSERT_EQ(runHpds("sample " + in + " --no-normals -o " + shellQuote(tmp / "s.ply"), &log), 0) << log;
  ASSERT_NE(log.find("2 points lie beyond the exact key range"), std::string::npos) << log;
  // The advice names what helps at a derived cell (the spacing, or depth below the output), not hierarchy.cell_size,
  // and following it brings the points in.
  EXPECT_NE(log.find("reach 1.54981e+07 m from the origin"), std::string::npos) << log;
  EXPECT_NE(log.find("or lower hierarchy.max_depth toward the output level 5\n"), std::string::npos) << log;
  EXPECT_EQ(log.find("raise hierarchy.cell_size"), std::string::npos) << log;
  ASSERT_EQ(runHpds("sample " + in + " --no-normals --max-depth 5 -o " + shellQuote(tmp / "s5.ply"), &log), 0) << log;
  EXPECT_NE(log.find("0 beyond exact key range"), std::string::npos) << log;
  EXPECT_EQ(log.find("lie beyond the exact key range"), std::string::npos) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "s.ply") + " --spacing 0.1 --input " + in, &log), 0) << log;
  EXPECT_NE(log.find("2 of the 5 input points lie beyond the exact key range of level 8"), std::string::npos) << log;
  EXPECT_NE(log.find("OK: no violations"), std::string::npos) << log;

  // With a fixed cell the key range is that of the --max-depth the sampling was made with (hpds sample's 8 when not
  // given): at 4 m cells and depth 8 the same points are all inserted, and all must be covered.
  ASSERT_EQ(runHpds("sample " + in + " --no-normals --float64-xyz --cell-size 4 -o " + shellQuote(tmp / "c.ply"), &log),
            0)
      << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "c.ply") + " --cell-size 4 --input " + in, &log), 0) << log;
  EXPECT_EQ(log.find("key range"), std::string::npos) << log;
  const std::string deep = " --no-normals --cell-size 4 --max-depth 21 -o ";
  ASSERT_EQ(runHpds("sample " + in + deep + shellQuote(tmp / "d.ply"), &log), 0) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "d.ply") + " --cell-size 4 --input " + in, &log), 1) << log;
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "d.ply") + " --cell-size 4 --max-depth 21 --input " + in, &log), 0)
      << log;
  EXPECT_NE(log.find("2 of the 5 input points lie beyond the exact key range of level 21"), std::string::npos) << log;
  // Its samples are at levels 0 and 1: a depth of 0 is not the sampler's.
  EXPECT_EQ(runHpds("verify " + shellQuote(tmp / "d.ply") + " --cell-size 4 --max-depth 0 --input " + in, &log), 1)
      << log;
  EXPECT_NE(log.find("holds level 1, deeper than --max-depth 0"), std::string::npos) << log;
}

// `--normals --no-normals` (or the other way round, as a flag appended to a command that had one) added up to
// nothing and ran without normals, exit 0, whichever came last. Contradictory flags are a bad command line.
TEST(Cli, NormalsAndNoNormalsTogetherAreRefused) {
  const auto tmp = test::scratchDir("cli_normals_flags");
  std::ofstream(tmp / "one.pcd") << "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
                                    "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n";
  const std::string run = "sample " + shellQuote(tmp / "one.pcd") + " -o " + shellQuote(tmp / "out.ply");
  for (const char *flags :
       {" --normals --no-normals", " --no-normals --normals", " --normals --no-normals --normals"}) {
    std::string log;
    EXPECT_EQ(runHpds(run + flags, &log), 2) << flags << "\n" << log;
    EXPECT_NE(log.find("--normals and --no-normals contradict each other"), std::string::npos) << flags << "\n" << log;
  }
  // So are the other contradictions, each said as "hpds: error: ..." like any error (CLI11's own messages were
  // printed without it, and --covariances --no-normals exited 1).
  for (const auto &[flags, message] : std::vector<std::pair<std::string, std::string>>{
           {" --covariances --no-normals", "hpds: error: --covariances needs normals"},
           {" --level 3 --spacing 0.1", "hpds: error: --level excludes --spacing"},
           {" --float64-xyz --float32-xyz", "hpds: error: --float64-xyz and --float32-xyz contradict each other"},
           {" --normals --no-normals", "hpds: error: --normals and --no-normals contradict each other"}}) {
    std::string log;
    EXPECT_EQ(runHpds(run + flags, &log), 2) << flags << "\n" << log;
    EXPECT_NE(log.find(message), std::string::npos) << flags << "\n" << log;
  }
  EXPECT_FALSE(std::filesystem::exists(tmp / "out.ply"));
  std::string log;
  EXPECT_EQ(runHpds(run + " --normals --normals", &log), 0) << log;
}

TEST(Cli, MapModeStatsCountEachFramesNormalsNotOnlyTheFinalCloud) {
  // Map mode estimates the normals the map keeps inside every frame; the final cloud only looks them up. The
  // stats' "normals" seconds must hold the frames' estimates: it held only the final lookup (overwritten), so a
  // run that spent most of its time on normals reported microseconds. A last frame far away evicts the whole map,
  // leaving a final cloud of nothing to look up: what remains is the frames' share.
  const auto tmp = test::scratchDir("cli_map_normals_seconds");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 3 --beams 16 --azimuth-steps 900", &log), 0)
      << log;
  {
    std::ofstream f(tmp / "nothing.pcd");  // the synthetic frames' fields (with their 2 padding bytes), no return
    f << "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity ring _ time\nSIZE 4 4 4 4 2 1 4\nTYPE F F F F U U F\n"
         "COUNT 1 1 1 1 1 2 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n"
         "0 0 0 1 1 0 0 0\nnan nan nan 1 1 0 0 0\n";
  }
  std::string poses = readText(tmp / "s" / "poses.txt");
  {
    std::ofstream f(tmp / "poses.txt");
    f << poses << "1 0 0 1000 0 1 0 0 0 0 1 0\n";
  }
  std::string inputs;
  for (int i = 0; i < 3; ++i) inputs += shellQuote(tmp / "s" / ("frame_00000" + std::to_string(i) + ".pcd")) + " ";
  ASSERT_EQ(runHpds("sample " + inputs + shellQuote(tmp / "nothing.pcd") + " --mode map --poses " +
                        shellQuote(tmp / "poses.txt") + " -o " + shellQuote(tmp / "m.ply") + " --stats " +
                        shellQuote(tmp / "stats.json"),
                    &log),
            0)
      << log;
  const std::string stats = readText(tmp / "stats.json");
  ASSERT_NE(stats.find("\"output_points\": 0"), std::string::npos) << stats;
  const std::size_t at = stats.find("\"normals\": ");
  ASSERT_NE(at, std::string::npos) << stats;
  const double normals = std::stod(stats.substr(at + 11));
  // Three frames' normals of ~5000 samples each: tens of milliseconds; the final empty lookup: microseconds.
  EXPECT_GT(normals, 2e-3) << stats;
  // The warning names the flags that keep every sample, and they do (a user's offline map lost half its samples
  // and only a --config could say so).
  EXPECT_NE(log.find("samples were evicted from the map"), std::string::npos) << log;
  EXPECT_NE(log.find("give --evict-distance 0 --max-samples 0 to keep every sample"), std::string::npos) << log;
  const std::string kept = "sample " + inputs + shellQuote(tmp / "nothing.pcd") + " --mode map --poses " +
                           shellQuote(tmp / "poses.txt") + " --evict-distance 0 --max-samples 0 -o ";
  ASSERT_EQ(runHpds(kept + shellQuote(tmp / "all.ply"), &log), 0) << log;
  EXPECT_EQ(log.find("evicted"), std::string::npos) << log;
  EXPECT_GT(readPointCloud((tmp / "all.ply").string()).size(), 5000u);
  // A cap alone evicts down to it.
  const std::string capped = "sample " + inputs + " --mode map --poses " + shellQuote(tmp / "s" / "poses.txt") +
                             " --evict-distance 0 --max-samples 1000 -o " + shellQuote(tmp / "capped.ply");
  ASSERT_EQ(runHpds(capped, &log), 0) << log;
  EXPECT_LE(readPointCloud((tmp / "capped.ply").string()).size(), 1000u);
  EXPECT_NE(log.find("samples were evicted from the map"), std::string::npos) << log;
  EXPECT_EQ(runHpds(capped + " --evict-distance -1", &log), 2) << log;
  EXPECT_NE(log.find("--evict-distance"), std::string::npos) << log;
}

}  // namespace
}  // namespace hpds
