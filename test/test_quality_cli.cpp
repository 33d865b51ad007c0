// `hpds analyze` and `hpds render` end to end on a small synthetic drive: the files they promise, the blue-noise
// properties the analysis must find in an hpds sampling (and not in the grid baselines), and clear errors.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include "TestData.hpp"

namespace hpds {
namespace {

using test::cliPath;
using test::readText;
using test::runCommand;
using test::runHpds;
using test::shellQuote;

bool isPng(const std::filesystem::path &p) {
  std::ifstream f(p, std::ios::binary);
  char sig[8] = {};
  f.read(sig, 8);
  return f && std::memcmp(sig, "\x89PNG\r\n\x1a\n", 8) == 0;
}

/// The value of `key` in the comparison set of `method` in analysis.json (written one set per line).
double comparisonValue(const std::string &json, const std::string &method, const std::string &key) {
  const std::regex line("\\{\"method\": \"" + method + "\", \"level\": [0-9]+,[^\\n]*\"" + key + "\": ([-0-9.e]+)");
  std::smatch m;
  // The per-level entries also hold an hpds set; the comparison block comes last.
  std::string::const_iterator from = json.begin() + static_cast<long>(json.find("\"comparison\""));
  if (!std::regex_search(from, json.end(), m, line)) return NAN;
  return std::stod(m[1]);
}

class QualityCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::filesystem::path(test::scratchDir("quality_cli"));
    std::string log;
    ASSERT_EQ(runHpds("synth -o " + shellQuote(*dir_ / "stream") + " --frames 4 --scene planar_urban --seed 3", &log), 0) << log;
    ASSERT_EQ(runHpds("sample " + shellQuote(*dir_ / "stream") + "/frame_*.pcd --poses " + shellQuote(*dir_ / "stream/poses.txt") +
                       " --mode map --normals --cell-size 4 --max-depth 7 --spacing 0.15 -o " + shellQuote(*dir_ / "map.ply"),
                   &log),
              0)
        << log;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::filesystem::path *dir_;
};
std::filesystem::path *QualityCli::dir_ = nullptr;

TEST_F(QualityCli, AnalyzeWritesDataAndFindsBlueNoiseOnlyInHpds) {
  const auto out = *dir_ / "analysis";
  std::string log;
  ASSERT_EQ(runHpds("analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 -o " + shellQuote(out) + " --input " + shellQuote(*dir_ / "stream") +
                     "/frame_*.pcd --poses " + shellQuote(*dir_ / "stream/poses.txt") + " --plane-band 0.04 --no-plots",
                 &log),
            0)
      << log;
  for (const char *f : {"analysis.json", "levels.csv", "rdf.csv", "spectrum.csv"})
    EXPECT_TRUE(std::filesystem::exists(out / f)) << f;
  for (const char *m : {"hpds", "grid_random", "grid_closest", "voxel_centroid", "random"}) {
    EXPECT_TRUE(isPng(out / ("periodogram_" + std::string(m) + "_L5.png"))) << m;
    EXPECT_TRUE(isPng(out / ("points_" + std::string(m) + "_L5.png"))) << m;
  }
  const std::string json = readText(out / "analysis.json");
  // Equal count by construction (bisection may miss by a few points for the grids).
  const double n = comparisonValue(json, "hpds", "count");
  ASSERT_GT(n, 300.0) << json;
  EXPECT_EQ(comparisonValue(json, "random", "count"), n);
  for (const char *m : {"grid_random", "grid_closest", "voxel_centroid"})
    EXPECT_NEAR(comparisonValue(json, m, "count"), n, 0.02 * n) << m;
  // hpds: no pair closer than r_D in 3D. Projected onto the plane, two samples within the +-4 cm band can come
  // closer: at worst sqrt(r^2 - (8 cm)^2) = 0.67 r at level 5. The baselines have pairs far closer.
  EXPECT_GT(comparisonValue(json, "hpds", "min_nn_over_r"), 0.67);
  EXPECT_LT(comparisonValue(json, "grid_random", "min_nn_over_r"), 0.5);
  EXPECT_LT(comparisonValue(json, "random", "min_nn_over_r"), 0.5);
  // Structural aliasing: the closest-to-centre grid concentrates energy in spikes that blue noise does not have.
  EXPECT_GT(comparisonValue(json, "grid_closest", "power_max"), 5.0 * comparisonValue(json, "hpds", "power_max"));
  // Per level, the whole union keeps its spacing in 3D: min NN / r_D >= 1 up to float rounding.
  const std::string levels = readText(out / "levels.csv");
  std::istringstream rows(levels);
  std::string row;
  std::getline(rows, row);
  EXPECT_EQ(row, "level,r,count,union_count,min_nn_over_r,mean_nn_over_r,patch_points");
  int nrows = 0;
  while (std::getline(rows, row)) {
    ++nrows;
    std::vector<std::string> cols;
    std::stringstream ss(row);
    for (std::string c; std::getline(ss, c, ',');) cols.push_back(c);
    ASSERT_EQ(cols.size(), 7u) << row;
    if (cols[4] != "null") {
      EXPECT_GT(std::stod(cols[4]), 0.999) << row;
    }
  }
  EXPECT_EQ(nrows, 6);  // levels 0..5
}

TEST_F(QualityCli, RenderWritesEveryColourAndView) {
  const auto out = *dir_ / "render";
  std::string log;
  ASSERT_EQ(runHpds("render " + shellQuote(*dir_ / "map.ply") + " -o " + shellQuote(out) + " --width 400 --height 300", &log), 0) << log;
  for (const char *c : {"level", "normal", "feature"})
    for (const char *v : {"top", "front", "side"})
      EXPECT_TRUE(isPng(out / ("render_" + std::string(c) + "_" + v + ".png"))) << c << " " << v;
  // A crop with nothing inside is an error, not an empty picture.
  EXPECT_EQ(runHpds("render " + shellQuote(*dir_ / "map.ply") + " -o " + shellQuote(out) + " --crop 900,900,900,901,901,901", &log), 1);
  EXPECT_NE(log.find("no points to render"), std::string::npos) << log;
  // One point: no spacing to derive a feature radius from (it was refused naming order.feature_radius, a key render
  // does not have); drawn without a feature.
  std::ofstream(*dir_ / "one.pcd") << "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
                                      "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n";
  ASSERT_EQ(runHpds("render " + shellQuote(*dir_ / "one.pcd") + " -o " + shellQuote(*dir_ / "one_render"), &log), 0)
      << log;
  EXPECT_TRUE(isPng(*dir_ / "one_render" / "render_feature_top.png"));
}

TEST_F(QualityCli, InputsOutsideThePatchAndFrameOnAMapAreSaidNotCrashed) {
  // Found analysing a map with its frames but without --poses: the baselines had no point in the patch and drawing
  // their (empty) periodograms crashed. And --frame on a map output (no 'frame' field) was silently ignored.
  std::ofstream(*dir_ / "far.pcd") << "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n"
                                      "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n900 900 0\n901 900 0\n";
  std::string log;
  EXPECT_EQ(runHpds("analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 -o " + shellQuote(*dir_ / "far_an") +
                        " --no-plots --input " + shellQuote(*dir_ / "far.pcd"),
                    &log),
            0)
      << log;
  EXPECT_NE(log.find("are the --input clouds in the sampling's frame (map mode needs --poses)?"), std::string::npos)
      << log;
  for (const std::string &cmd : {"render " + shellQuote(*dir_ / "map.ply") + " -o " + shellQuote(*dir_ / "fr"),
                                "analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 -o " +
                                    shellQuote(*dir_ / "fa")}) {
    EXPECT_EQ(runHpds(cmd + " --frame 2", &log), 1) << cmd << "\n" << log;
    EXPECT_NE(log.find("has no 'frame' field"), std::string::npos) << log;
  }
}

TEST_F(QualityCli, BadInputGivesClearErrors) {
  std::string log;
  // A plain cloud has no level field.
  EXPECT_EQ(runHpds("analyze " + shellQuote(*dir_ / "stream/frame_000000.pcd") + " --cell-size 4 -o " + shellQuote(*dir_ / "bad"), &log), 1);
  EXPECT_NE(log.find("no `level` field"), std::string::npos) << log;
  EXPECT_NE(runHpds("analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 -o " + shellQuote(*dir_ / "bad") + " --patch 1,2", &log), 0);
  EXPECT_EQ(runHpds("analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 0 -o " + shellQuote(*dir_ / "bad"), &log), 2);  // a bad command line
  EXPECT_NE(log.find("--cell-size"), std::string::npos) << log;
  // A patch in empty space.
  EXPECT_EQ(runHpds("analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 -o " + shellQuote(*dir_ / "bad") + " --patch 500,500,4 "
                 "--no-plots", &log), 1);
  EXPECT_NE(log.find("--patch"), std::string::npos) << log;
}

// Size-like flags are bounded (errors name the flag and the bound), an inverted crop is refused instead of ignored,
// and analysis.json stays valid JSON whatever the path holds.
TEST_F(QualityCli, SizeLikeFlagsAreBoundedAndPathsEscaped) {
  struct Case {
    std::string args;
    int code;
    std::string message;
  };
  const std::string map = shellQuote(*dir_ / "map.ply"), out = " -o " + shellQuote(*dir_ / "bounded");
  const std::vector<Case> cases = {
      {"render " + map + out + " --width 20000", 2, "--width: must be an integer in 18..8192, got '20000'"},
      {"render " + map + out + " --height 0", 2, "--height: must be an integer in 18..8192"},
      {"render " + map + out + " --splat inf", 2, "--splat: must be a finite number in [0, 1e+06], got 'inf'"},
      {"render " + map + out + " --splat 1000", 1, "px a splat may have"},
      {"render " + map + out + " --frame 4294967297", 2, "--frame: must be an integer in 0..4294967295"},
      {"render " + map + out + " --crop 5,0,0,1,1,1", 1, "--crop: x0 = 5.000000 > x1 = 1.000000"},
      {"render " + map + out + " --threads 5000", 2, "--threads: must be an integer in 0..1024"},
      {"analyze " + map + " --cell-size 4" + out + " --rdf-bins 2000000000", 2, "--rdf-bins: must be an integer in 1..10000"},
      {"analyze " + map + " --cell-size 4" + out + " --freq-max 1e9", 2, "--freq-max: must be a finite number"},
      {"analyze " + map + " --cell-size 4" + out + " --seed -1", 2, "--seed: must be an integer in 0..18446744073709551615"},
      {"analyze " + map + " --cell-size nan" + out, 2, "--cell-size: must be a finite number"},
      {"verify " + map + " --cell-size 0", 2, "--cell-size: must be a finite number in (0, 1e+06]"},
      // -5 was taken as -1 (check each frame), 2^64 - 1 passed as a frame number.
      {"verify " + map + " --cell-size 4 --frame -5", 2, "--frame: must be an integer in -1..4294967295, got '-5'"},
      {"verify " + map + " --cell-size 4 --frame 18446744073709551615", 2, "--frame: must be an integer in -1.."},
      {"synth -o " + shellQuote(*dir_ / "synth_bounded") + " --beams 2000", 2, "--beams: must be an integer in 1..1024"},
      {"synth -o " + shellQuote(*dir_ / "synth_bounded") + " --beams 1024 --azimuth-steps 100000", 1,
       "rays per frame, more than the 4194304"},
  };
  for (const Case &c : cases) {
    std::string log;
    EXPECT_EQ(runHpds(c.args, &log), c.code) << c.args << "\n" << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
  }
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "bounded" / "render_level_top.png")) << "drew before refusing";

  // A path with a quote and a backslash: analysis.json still parses, and gives the path back.
  const auto odd = *dir_ / "a \"quoted\" \\ dir";
  std::filesystem::create_directories(odd);
  std::filesystem::copy_file(*dir_ / "map.ply", odd / "map.ply");
  std::string log;
  ASSERT_EQ(runHpds("analyze " + shellQuote(odd / "map.ply") + " --cell-size 4 -o " + shellQuote(odd / "out") +
                        " --plane-band 0.04 --no-plots",
                    &log),
            0)
      << log;
  const YAML::Node json = YAML::LoadFile((odd / "out" / "analysis.json").string());
  EXPECT_EQ(json["sampling"].as<std::string>(), (odd / "map.ply").string());
}

// The smallest --width/--height the flags accepted (16, 17) always failed once drawing began, with an error naming
// an internal function ("renderPoints: image too small for its margin") and exit 1: the bound is now the smallest
// picture that can be drawn, and every accepted size draws.
TEST_F(QualityCli, EverySizeRenderAcceptsDraws) {
  const std::string map = shellQuote(*dir_ / "map.ply");
  std::string log;
  for (const char *flag : {"--width", "--height"}) {
    EXPECT_EQ(runHpds("render " + map + " -o " + shellQuote(*dir_ / "tiny") + " " + flag + " 17", &log), 2) << log;
    EXPECT_NE(log.find(std::string(flag) + ": must be an integer in 18..8192, got '17'"), std::string::npos) << log;
  }
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "tiny")) << "drew before refusing";
  ASSERT_EQ(runHpds("render " + map + " -o " + shellQuote(*dir_ / "tiny") + " --width 18 --height 18 --view top", &log),
            0)
      << log;
  EXPECT_TRUE(isPng(*dir_ / "tiny" / "render_level_top.png"));
}

// An unknown --feature was noticed only when the feature pictures were drawn, after the level and normal ones: the
// run failed (exit 1) leaving six new pictures in the folder, beside whatever an earlier render had put there.
TEST_F(QualityCli, AnUnknownFeatureIsRefusedBeforeAnythingIsDrawn) {
  std::string log;
  EXPECT_EQ(runHpds("render " + shellQuote(*dir_ / "map.ply") + " -o " + shellQuote(*dir_ / "bad_feature") +
                        " --feature normals",
                    &log),
            1)
      << log;
  EXPECT_NE(log.find("--feature: expected curvature, surface_variation or sphericity, got 'normals'"),
            std::string::npos)
      << log;
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "bad_feature")) << "drew before refusing:\n" << log;
}

// --grid-offset was the one number analyze took unchecked: nan or 1e300 placed the baseline grids nowhere, the
// comparison ran on 0 or 1 baseline points in the patch and analysis.json was written with exit 0.
TEST_F(QualityCli, GridOffsetIsAFractionOfACell) {
  const std::string args = "analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 --no-plots --input " +
                           shellQuote(*dir_ / "stream/frame_000000.pcd") + " -o " + shellQuote(*dir_ / "offset");
  std::string log;
  for (const char *bad : {"nan", "inf", "1e300", "-0.5", "1.5"}) {
    EXPECT_EQ(runHpds(args + " --grid-offset " + bad, &log), 2) << bad << "\n" << log;
    EXPECT_NE(log.find("--grid-offset: must be a finite number in [0, 1], got '" + std::string(bad) + "'"),
              std::string::npos)
        << log;
  }
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "offset")) << "analysed before refusing";
}

// --compare-level deeper than the sampling's levels was silently replaced by the deepest one (exit 0), and a level
// with too few samples in the patch was refused only after every level's pictures had been written.
TEST_F(QualityCli, ACompareLevelThatCannotBeComparedIsRefusedBeforeAnythingIsWritten) {
  const std::string args = "analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 --no-plots --input " +
                           shellQuote(*dir_ / "stream/frame_000000.pcd") + " -o ";
  std::string log;
  EXPECT_EQ(runHpds(args + shellQuote(*dir_ / "cmp_deep") + " --compare-level 7", &log), 1) << log;
  EXPECT_NE(log.find("--compare-level 7: the sampling's deepest level is 5"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "cmp_deep")) << log;
  EXPECT_EQ(runHpds(args + shellQuote(*dir_ / "cmp_coarse") + " --compare-level 0", &log), 1) << log;
  EXPECT_NE(log.find("--compare-level 0: too few hpds samples in the patch to compare"), std::string::npos) << log;
  // Not even the folder: a failed run leaves no half output.
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "cmp_coarse")) << "left a folder behind:\n" << log;
}

// A sampling with no planar near-horizontal patch (a wall) failed with exit 1 but left its new, empty -o folder
// behind, which looked like an analysis that had produced nothing.
TEST_F(QualityCli, AnAnalysisThatFindsNoPatchLeavesNoFolder) {
  std::ofstream wall(*dir_ / "wall.pcd");
  wall << "VERSION .7\nFIELDS x y z level\nSIZE 4 4 4 1\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 400\nHEIGHT 1\n"
          "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 400\nDATA ascii\n";
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) wall << "3 " << 0.2 * i << " " << 0.2 * j << " " << (i + j) % 4 << "\n";
  wall.close();
  const auto top = *dir_ / "no_patch";
  std::string log;
  EXPECT_EQ(runHpds("analyze " + shellQuote(*dir_ / "wall.pcd") + " --cell-size 4 --no-plots -o " +
                        shellQuote(top / "nested" / "out"),
                    &log),
            1)
      << log;
  EXPECT_NE(log.find("no planar near-horizontal patch"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(top)) << "left a folder behind:\n" << log;
  // A folder that was there before stays, with nothing added.
  std::filesystem::create_directories(top);
  EXPECT_EQ(runHpds("analyze " + shellQuote(*dir_ / "wall.pcd") + " --cell-size 4 --no-plots -o " + shellQuote(top),
                    &log),
            1)
      << log;
  EXPECT_TRUE(std::filesystem::is_directory(top));
  EXPECT_TRUE(std::filesystem::is_empty(top)) << log;
}

// --compare-level and --poses act on the --input clouds only; without --input they were dropped without a word
// (exit 0, no comparison), so a user never learnt that the comparison asked for did not happen.
TEST_F(QualityCli, ComparisonFlagsWithoutInputAreABadCommandLine) {
  const std::string args = "analyze " + shellQuote(*dir_ / "map.ply") + " --cell-size 4 --no-plots -o " +
                           shellQuote(*dir_ / "no_input");
  std::string log;
  EXPECT_EQ(runHpds(args + " --compare-level 4", &log), 2) << log;
  EXPECT_NE(log.find("--compare-level requires --input"), std::string::npos) << log;
  EXPECT_EQ(runHpds(args + " --poses " + shellQuote(*dir_ / "stream/poses.txt"), &log), 2) << log;
  EXPECT_NE(log.find("--poses requires --input"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "no_input")) << log;
}

// An empty -o (an unset shell variable: `-o "$OUT"`) reached the file system: synth failed with the library's
// "filesystem error: cannot create directories: No such file or directory []"; every command now refuses it as a
// bad command line.
TEST_F(QualityCli, AnEmptyOutputPathIsABadCommandLine) {
  const std::string map = shellQuote(*dir_ / "map.ply");
  for (const std::string &cmd : {std::string("synth --frames 1"), "render " + map, "analyze " + map + " --cell-size 4",
                                 "sample " + shellQuote(*dir_ / "stream/frame_000000.pcd")}) {
    std::string log;
    EXPECT_EQ(runHpds(cmd + " -o ''", &log), 2) << cmd << "\n" << log;
    EXPECT_NE(log.find("--output: must be a path, got an empty string"), std::string::npos) << cmd << "\n" << log;
  }
}

// `render --prefix ../x -o DIR` wrote its nine pictures beside DIR, outside the folder it was given.
TEST_F(QualityCli, APrefixIsAFileNameNotAPath) {
  const auto out = *dir_ / "prefixed";
  for (const std::string prefix : {"../escaped", "sub/p", "..", "/tmp/abs"}) {
    std::string log;
    EXPECT_EQ(runHpds("render " + shellQuote(*dir_ / "map.ply") + " --view top --color level -o " + shellQuote(out) +
                          " --prefix " + shellQuote(prefix),
                      &log),
              2)
        << prefix << "\n" << log;
    EXPECT_NE(log.find("--prefix: must be a file-name prefix"), std::string::npos) << log;
  }
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "escaped_level_top.png"));
  EXPECT_FALSE(std::filesystem::exists(out));
  std::string log;
  ASSERT_EQ(runHpds("render " + shellQuote(*dir_ / "map.ply") + " --view top --color level -o " + shellQuote(out) +
                        " --prefix run.1",
                    &log),
            0)
      << log;
  EXPECT_TRUE(isPng(out / "run.1_level_top.png"));
}

// A cloud whose every point has a NaN coordinate (a sensor frame with no return) was "rendered" into nine blank
// pictures with exit 0, where a crop with nothing inside is an error.
TEST_F(QualityCli, ACloudWithNoFinitePointIsNotRenderedBlank) {
  std::ofstream(*dir_ / "nan.pcd") << "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n"
                                      "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\nnan nan nan\n1 nan 2\n";
  std::string log;
  EXPECT_EQ(runHpds("render " + shellQuote(*dir_ / "nan.pcd") + " -o " + shellQuote(*dir_ / "nan_render"), &log), 1)
      << log;
  EXPECT_NE(log.find("no points to render"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(*dir_ / "nan_render")) << log;
}

}  // namespace
}  // namespace hpds
