// The spacing asked for: how output.spacing, output.level and hierarchy.cell_size choose the output level and the
// level-0 cell (resolveOutput), checked against the rules and, by brute force on small frames, against the samples
// a pipeline and `hpds sample` actually write.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "TestData.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/sampling/CellKey.hpp"

namespace hpds {
namespace {

HpdsConfig bySpacing(double spacing, double cell_size = 0.0, int max_depth = 8) {
  HpdsConfig c;
  c.hierarchy.cell_size = cell_size;
  c.hierarchy.max_depth = max_depth;
  c.output.level = -1;
  c.output.spacing = spacing;
  return c;
}

bool contains(const std::string &text, const std::string &part) { return text.find(part) != std::string::npos; }

TEST(OutputResolution, ShippedDefaultsGiveTheSpacingExactly) {
  const HpdsConfig defaults;
  EXPECT_EQ(defaults.hierarchy.cell_size, 0.0) << "derived";
  EXPECT_EQ(defaults.output.spacing, 0.1);
  EXPECT_TRUE(defaults.normals.enabled);
  const OutputResolution r = resolveOutput(defaults);
  EXPECT_EQ(r.level, 5);
  EXPECT_NEAR(r.cell_size, 0.2 / std::sqrt(3.0) * 32.0, 1e-12);
  EXPECT_GE(r.radius, 0.1);
  EXPECT_LE(r.radius - 0.1, 1e-15);
  EXPECT_EQ(r.spacing_asked, 0.1);
  EXPECT_TRUE(contains(r.reason, "output level 5")) << r.reason;
  EXPECT_TRUE(contains(r.reason, "the spacing asked (output.spacing 0.1 m)")) << r.reason;
  EXPECT_TRUE(contains(r.reason, "derived")) << r.reason;
}

TEST(OutputResolution, DerivedCellGivesEveryAskedSpacingAsTheOutputRadius) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> log_spacing(std::log(1e-3), std::log(50.0));
  for (int trial = 0; trial < 2000; ++trial) {
    const double s = std::exp(log_spacing(rng));
    const int max_depth = static_cast<int>(rng() % 22);
    const HpdsConfig c = bySpacing(s, 0.0, max_depth);
    ASSERT_NO_THROW(validateConfig(c)) << s;
    const OutputResolution r = resolveOutput(c);
    SCOPED_TRACE("spacing " + std::to_string(s) + ", max_depth " + std::to_string(max_depth));
    ASSERT_GE(r.level, 0);
    ASSERT_LE(r.level, max_depth);
    // r_L is the spacing: never below it, above it only by rounding.
    EXPECT_GE(poissonRadius(r.cell_size, r.level), s);
    EXPECT_LE(poissonRadius(r.cell_size, r.level), s * (1.0 + 1e-15));
    EXPECT_EQ(r.radius, poissonRadius(r.cell_size, r.level));
    // The level: the largest whose cell stays within 4 m (or max_depth, or 0 for spacings above the 4 m cell).
    const double edge = 2.0 * s / std::sqrt(3.0);
    if (r.level < max_depth) {
      EXPECT_GT(std::ldexp(edge, r.level + 1), kDefaultCellSize);
    }
    if (r.level > 0) {
      EXPECT_LE(r.cell_size, kDefaultCellSize * (1.0 + 1e-15));
    }
    if (r.level > 0 && r.level < max_depth) {
      EXPECT_GT(r.cell_size, 0.5 * kDefaultCellSize);
    }
    // A pipeline runs with exactly these values, and resolving its config again changes nothing.
    const HpdsConfig resolved = resolvedConfig(c);
    EXPECT_EQ(resolved.hierarchy.cell_size, r.cell_size);
    EXPECT_EQ(resolved.output.level, r.level);
    const OutputResolution again = resolveOutput(resolved);
    EXPECT_EQ(again.cell_size, r.cell_size);
    EXPECT_EQ(again.level, r.level);
  }
}

TEST(OutputResolution, FixedCellKeepsTheCoarsestLevelWithinTheSpacingAndSaysSo) {
  // The example: 0.2 m with 4 m cells gives level 5, r = 0.108 m.
  const OutputResolution r = resolveOutput(bySpacing(0.2, 4.0));
  EXPECT_EQ(r.level, 5);
  EXPECT_EQ(r.cell_size, 4.0);
  EXPECT_NEAR(r.radius, 0.10825, 1e-5);
  EXPECT_EQ(r.spacing_asked, 0.2);
  EXPECT_TRUE(contains(r.reason, "coarsest level with r_D <= output.spacing 0.2 m")) << r.reason;
  EXPECT_TRUE(contains(r.reason, "fixed hierarchy.cell_size 4 m")) << r.reason;
  EXPECT_TRUE(contains(r.reason, "hierarchy.cell_size 0 gives the spacing exactly")) << r.reason;

  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 1000; ++trial) {
    const double cell = 0.5 + 10.0 * u(rng), s = 0.02 + 3.0 * u(rng);
    const OutputResolution f = resolveOutput(bySpacing(s, cell, 12));
    if (f.level == 0) {
      EXPECT_LE(f.radius, s);
    } else if (f.level < 12 || f.radius <= s) {
      EXPECT_LE(f.radius, s) << "cell " << cell << ", spacing " << s;
      EXPECT_GT(poissonRadius(cell, f.level - 1), s) << "not the coarsest";
    }
  }
}

TEST(OutputResolution, SpacingBeyondTheFinestFixedLevelOutputsMaxDepthAndSaysWhy) {
  const OutputResolution r = resolveOutput(bySpacing(0.1, 2.0, 3));
  EXPECT_EQ(r.level, 3);
  EXPECT_GT(r.radius, 0.1);
  EXPECT_TRUE(contains(r.reason, "hierarchy.max_depth 3, since even its radius is coarser than output.spacing 0.1 m"))
      << r.reason;
}

TEST(OutputResolution, AnExplicitLevelUsesTheCellOrFourMetres) {
  HpdsConfig c;
  c.output.level = 4;
  OutputResolution r = resolveOutput(c);  // cell_size 0, but no spacing chooses the level
  EXPECT_EQ(r.level, 4);
  EXPECT_EQ(r.cell_size, kDefaultCellSize);
  EXPECT_EQ(r.spacing_asked, 0.0);
  EXPECT_TRUE(contains(r.reason, "output.level 4")) << r.reason;
  // A spacing beside the level is named as not used, not as missing.
  c.output.spacing = 0.2;
  EXPECT_TRUE(contains(resolveOutput(c).reason, "output.spacing 0.2 m is not used, as output.level is set"))
      << resolveOutput(c).reason;
  c.output.spacing = 0.0;
  EXPECT_TRUE(contains(resolveOutput(c).reason, "no output.spacing to derive it from")) << resolveOutput(c).reason;
  c.hierarchy.cell_size = 2.0;
  r = resolveOutput(c);
  EXPECT_EQ(r.cell_size, 2.0);
  EXPECT_EQ(r.radius, poissonRadius(2.0, 4));
  c.output.level = -1;
  c.output.spacing = 0.0;
  r = resolveOutput(c);
  EXPECT_EQ(r.level, c.hierarchy.max_depth);
  EXPECT_TRUE(contains(r.reason, "output.spacing 0, so hierarchy.max_depth 8")) << r.reason;
}

TEST(OutputResolution, ValidationOfTheDerivedCell) {
  EXPECT_NO_THROW(validateConfig(bySpacing(1000.0)));
  try {
    validateConfig(bySpacing(2e6));
    ADD_FAILURE() << "a spacing whose derived cell exceeds 1e6 m must be refused";
  } catch (const std::invalid_argument &e) {
    EXPECT_TRUE(contains(e.what(), "output.spacing")) << e.what();
  }
  HpdsConfig negative;
  negative.hierarchy.cell_size = -1.0;
  EXPECT_THROW(validateConfig(negative), std::invalid_argument);
}

// The warning for points beyond the exact keys names only settings that widen the reach, and every one it names does.
TEST(OutputResolution, KeyRangeAdviceNamesExactlyTheSettingsThatWidenTheReach) {
  const auto reach = [](const HpdsConfig &c) {
    return (kMaxCellCoord - 8.0) * cellEdge(resolveOutput(c).cell_size, c.hierarchy.max_depth);
  };
  for (const HpdsConfig &c : {bySpacing(0.1), bySpacing(0.0001), bySpacing(0.1, 4.0), bySpacing(0.1, 4.0, 3),
                              bySpacing(0.02, 0.0, 4), bySpacing(5.0)}) {
    const std::string advice = keyRangeAdvice(c);
    SCOPED_TRACE(advice);
    EXPECT_TRUE(contains(advice, "local frame"));
    char reach_text[32];
    std::snprintf(reach_text, sizeof reach_text, "reach %.6g m", reach(c));
    EXPECT_TRUE(contains(advice, reach_text)) << reach_text;

    HpdsConfig shallower = c;
    shallower.hierarchy.max_depth = resolveOutput(c).level;
    EXPECT_EQ(contains(advice, "lower hierarchy.max_depth"), reach(shallower) > reach(c));
    HpdsConfig coarser = c;
    if (c.hierarchy.cell_size == 0.0) {
      coarser.output.spacing *= 2.0;
      EXPECT_FALSE(contains(advice, "hierarchy.cell_size"));
    } else {
      coarser.hierarchy.cell_size *= 2.0;
      EXPECT_TRUE(contains(advice, "raise hierarchy.cell_size"));
    }
    // Named exactly when it widens the reach (a derived cell keeps its level-0 edge within (2, 4] m: a coarser
    // spacing moves the output level, not the keys, unless the output is at max_depth).
    EXPECT_EQ(contains(advice, "raise output.spacing") || contains(advice, "raise hierarchy.cell_size"),
              reach(coarser) > reach(c));
    // Some setting always helps besides a local frame.
    EXPECT_TRUE(reach(coarser) > reach(c) || reach(shallower) > reach(c));
  }
}

// Smallest distance between two points, by brute force.
double bruteForceMinDistance(const std::vector<Eigen::Vector3d> &p) {
  double best = INFINITY;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (std::size_t j = i + 1; j < p.size(); ++j) best = std::min(best, (p[i] - p[j]).norm());
  return best;
}

SyntheticLidarConfig smallLidar() {
  SyntheticLidarConfig c;
  c.beams = 8;
  c.azimuth_steps = 500;
  c.frames = 2;
  return c;
}

TEST(OutputResolution, WrittenSamplesAreSeparatedByTheAskedSpacingBruteForce) {
  // Scan and map mode, derived cells: every two output samples are at least the asked spacing apart (positions are
  // doubles in the pipeline), and the spacing is not wasted: some pair lies within twice it.
  const SyntheticLidar lidar(smallLidar());
  for (const Mode mode : {Mode::Scan, Mode::Map})
    for (const double s : {0.1, 0.17, 0.3, 0.55}) {
      SCOPED_TRACE(std::string(toString(mode)) + ", spacing " + std::to_string(s));
      HpdsConfig c = bySpacing(s);
      c.mode = mode;
      c.normals.enabled = false;
      Pipeline p(c);
      for (int i = 0; i < 2; ++i) p.addFrame(lidar.frame(i).frame);
      std::vector<Eigen::Vector3d> xyz;
      for (SampleId id : p.outputSamples())
        xyz.emplace_back(p.hierarchy().position(id)[0], p.hierarchy().position(id)[1], p.hierarchy().position(id)[2]);
      ASSERT_GT(xyz.size(), 50u);
      const double min_d = bruteForceMinDistance(xyz);
      EXPECT_GE(min_d, s);
      EXPECT_LT(min_d, 2.0 * s);
    }
}

TEST(OutputResolution, CliWritesTheAskedSpacingAndReportsTheChoice) {
  const auto tmp = test::scratchDir("spacing_cli");
  const SyntheticLidar lidar(smallLidar());
  writePcd((tmp / "f.pcd").string(), lidar.frame(0).frame.points);
  const std::string in = test::shellQuote((tmp / "f.pcd").string());
  for (const double s : {0.13, 0.4}) {
    SCOPED_TRACE("spacing " + std::to_string(s));
    const std::string spacing = std::to_string(s);
    std::string log;
    ASSERT_EQ(test::runHpds("sample " + in + " --spacing " + spacing + " -o " + test::shellQuote(tmp / "s.ply") + " --stats " +
                          test::shellQuote(tmp / "s.json"),
                      &log),
              0)
        << log;
    EXPECT_TRUE(contains(log, "the spacing asked (output.spacing " + std::string(s == 0.13 ? "0.13" : "0.4") + " m)"))
        << log;
    const std::string stats = test::readText(tmp / "s.json");
    EXPECT_TRUE(contains(stats, "\"spacing_asked\": " + std::string(s == 0.13 ? "0.13" : "0.4"))) << stats;
    EXPECT_TRUE(contains(stats, "\"reason\": \"output level")) << stats;
    const PointBuffer out = readPointCloud((tmp / "s.ply").string());
    std::vector<Eigen::Vector3d> xyz;
    const PointField *fx = out.layout().find("x"), *fy = out.layout().find("y"), *fz = out.layout().find("z");
    double extent = 0.0;
    for (std::size_t i = 0; i < out.size(); ++i) {
      xyz.emplace_back(readAsDouble(out.record(i), *fx), readAsDouble(out.record(i), *fy), readAsDouble(out.record(i), *fz));
      extent = std::max(extent, xyz.back().cwiseAbs().maxCoeff());
    }
    ASSERT_GT(xyz.size(), 50u);
    // The PLY holds float32 coordinates: each may move by half an ulp of the largest coordinate.
    EXPECT_GE(bruteForceMinDistance(xyz), s - 4.0 * std::ldexp(1.0, -24) * extent);
    ASSERT_EQ(test::runHpds("verify " + test::shellQuote(tmp / "s.ply") + " --spacing " + spacing + " --input " + in, &log), 0) << log;
    EXPECT_TRUE(contains(log, "OK: no violations")) << log;
  }
  // A fixed cell: the coarsest level within the spacing, and the report says so.
  std::string log;
  ASSERT_EQ(test::runHpds("sample " + in + " --spacing 0.2 --cell-size 4 -o " + test::shellQuote(tmp / "f.ply") + " --stats " +
                        test::shellQuote(tmp / "f.json"),
                    &log),
            0)
      << log;
  EXPECT_TRUE(contains(log, "output level 5, r_5 = 0.108253 m")) << log;
  EXPECT_TRUE(contains(test::readText(tmp / "f.json"), "fixed hierarchy.cell_size 4 m"));
  ASSERT_EQ(test::runHpds("verify " + test::shellQuote(tmp / "f.ply") + " --cell-size 4", &log), 0) << log;
  // verify takes one of the two, not both.
  EXPECT_NE(test::runHpds("verify " + test::shellQuote(tmp / "f.ply") + " --cell-size 4 --spacing 0.2", &log), 0) << log;
  // Without either, the cell and levels the file's header records.
  EXPECT_EQ(test::runHpds("verify " + test::shellQuote(tmp / "f.ply"), &log), 0) << log;
  EXPECT_TRUE(contains(log, "as its header records: level-0 cell 4 m, max_depth 8, output level 5")) << log;
}

}  // namespace
}  // namespace hpds
