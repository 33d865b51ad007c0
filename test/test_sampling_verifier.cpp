// The sampling verifier against hand-built samplings and an O(n^2) oracle that applies the three rules literally.
// Samplings are stored as float32 like the real output, so the tolerance is exercised everywhere.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <array>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hpds/points/PointBuffer.hpp"
#include "hpds/eval/SamplingVerifier.hpp"
#include "hpds/sampling/CellKey.hpp"

namespace hpds {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

struct Sample {
  double x, y, z;
  int level;
};
using P3 = std::array<double, 3>;

double radius(double cell, int level) { return std::sqrt(3.0) / 2.0 * std::ldexp(cell, -level); }

PointBuffer makeSampling(const std::vector<Sample> &samples, FieldType coord = FieldType::Float32) {
  PointLayout layout;
  layout.append("x", coord);
  layout.append("y", coord);
  layout.append("z", coord);
  layout.append("level", FieldType::UInt8);
  PointBuffer buf(layout, samples.size());
  const auto &f = buf.layout().fields;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    writeFromDouble(buf.record(i), f[0], samples[i].x);
    writeFromDouble(buf.record(i), f[1], samples[i].y);
    writeFromDouble(buf.record(i), f[2], samples[i].z);
    writeFromDouble(buf.record(i), f[3], samples[i].level);
  }
  return buf;
}

PointBuffer makeCloud(const std::vector<P3> &pts, FieldType coord = FieldType::Float32) {
  PointLayout layout;
  layout.append("x", coord);
  layout.append("y", coord);
  layout.append("z", coord);
  PointBuffer buf(layout, pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (int a = 0; a < 3; ++a) writeFromDouble(buf.record(i), buf.layout().fields[a], pts[i][a]);
  return buf;
}

double f32(double v) { return static_cast<double>(static_cast<float>(v)); }

double dist(const P3 &a, const P3 &b) {
  double s = 0.0;
  for (int k = 0; k < 3; ++k) s += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(s);
}

// ---------------------------------------------------------------- oracle

std::vector<P3> readXyz(const PointBuffer &buf) {
  std::vector<P3> out(buf.size());
  const PointField *f[3] = {buf.layout().find("x"), buf.layout().find("y"), buf.layout().find("z")};
  for (std::size_t i = 0; i < buf.size(); ++i)
    for (int a = 0; a < 3; ++a) out[i][a] = readAsDouble(buf.record(i), *f[a]);
  return out;
}

bool finite3(const P3 &p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); }

VerifyReport bruteForce(const PointBuffer &sampling, double cell_size, const PointBuffer *input) {
  const std::vector<P3> pts = readXyz(sampling);
  std::vector<int> lv(pts.size());
  int max_level = -1;
  double max_abs = 0.0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    lv[i] = static_cast<int>(readAsDouble(sampling.record(i), *sampling.layout().find("level")));
    max_level = std::max(max_level, lv[i]);
    if (finite3(pts[i]))
      for (double v : pts[i]) max_abs = std::max(max_abs, std::fabs(v));
  }
  std::vector<P3> probes;
  if (input)
    for (const P3 &p : readXyz(*input))
      if (finite3(p) && !(p[0] == 0 && p[1] == 0 && p[2] == 0)) probes.push_back(p);

  VerifyReport rep;
  rep.cell_size = cell_size;
  rep.tolerance = 4.0 * std::pow(2.0, -24) * max_abs;
  const double tol = rep.tolerance;
  for (int d = 0; d <= max_level; ++d) {
    const double c = cell_size / std::pow(2.0, d), r = radius(cell_size, d);
    LevelReport l;
    l.level = d;
    std::vector<P3> u;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (lv[i] == d) ++l.count;
      if (lv[i] > d) continue;
      ++l.union_count;
      if (finite3(pts[i]))
        u.push_back(pts[i]);
      else
        ++l.spacing_violations;
    }
    double mn = kInf;
    for (std::size_t i = 0; i < u.size(); ++i) {
      double nn = kInf;
      for (std::size_t j = 0; j < u.size(); ++j)
        if (j != i) nn = std::min(nn, dist(u[i], u[j]));
      mn = std::min(mn, nn);
      if (nn < r - tol) ++l.spacing_violations;
    }
    l.min_nn_over_r = mn / r;
    std::map<std::array<long long, 3>, int> cells;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (lv[i] != d || !finite3(pts[i])) continue;
      std::array<long long, 3> key{};
      bool interior = true;
      for (int a = 0; a < 3; ++a) {
        const double k = std::floor(pts[i][a] / c);
        key[a] = static_cast<long long>(k);
        interior = interior && pts[i][a] - k * c > tol && (k + 1) * c - pts[i][a] > tol;
      }
      if (interior) ++cells[key];
    }
    for (const auto &kv : cells) l.cell_violations += static_cast<std::size_t>(std::max(0, kv.second - 1));
    l.max_coverage_over_r = kNaN;
    if (!probes.empty()) {
      double mx = 0.0;
      for (const P3 &p : probes) {
        double best = kInf;
        for (const P3 &q : u) best = std::min(best, dist(p, q));
        mx = std::max(mx, best);
        if (best > 2 * r + tol) ++l.coverage_violations;
      }
      l.max_coverage_over_r = mx / r;
    }
    rep.levels.push_back(l);
  }
  return rep;
}

void expectSameRatio(double a, double b, const std::string &what) {
  if (std::isnan(b)) {
    EXPECT_TRUE(std::isnan(a)) << what;
  } else if (std::isinf(b)) {
    EXPECT_EQ(a, b) << what;
  } else {
    EXPECT_NEAR(a, b, 1e-12 * std::max(1.0, std::fabs(b))) << what;
  }
}

void expectSameReport(const VerifyReport &got, const VerifyReport &want) {
  EXPECT_EQ(got.tolerance, want.tolerance);
  ASSERT_EQ(got.levels.size(), want.levels.size());
  for (std::size_t d = 0; d < want.levels.size(); ++d) {
    const LevelReport &g = got.levels[d], &w = want.levels[d];
    const std::string at = "level " + std::to_string(d);
    EXPECT_EQ(g.level, w.level) << at;
    EXPECT_EQ(g.count, w.count) << at;
    EXPECT_EQ(g.union_count, w.union_count) << at;
    EXPECT_EQ(g.spacing_violations, w.spacing_violations) << at;
    EXPECT_EQ(g.cell_violations, w.cell_violations) << at;
    EXPECT_EQ(g.coverage_violations, w.coverage_violations) << at;
    expectSameRatio(g.min_nn_over_r, w.min_nn_over_r, at + " min_nn");
    expectSameRatio(g.max_coverage_over_r, w.max_coverage_over_r, at + " cover");
  }
}

// ---------------------------------------------------------------- a tiny valid sampler

// Greedy dart throwing over a fixed candidate list, level by level: a candidate becomes a level-D sample when its
// level-D cell has no level-D sample and it is >= r_D from U_D. Every candidate is then within 2 r_D of U_D (it
// was rejected for a neighbour closer than r_D, or for a sample in its own cell, whose diagonal is 2 r_D).
// Candidates are rounded to float32 first so the guarantees hold for the stored values.
std::vector<Sample> dartThrow(const std::vector<P3> &candidates, double cell_size, int levels) {
  std::vector<Sample> out;
  std::vector<bool> taken(candidates.size(), false);
  for (int d = 0; d < levels; ++d) {
    const double c = cell_size / std::pow(2.0, d), r = radius(cell_size, d);
    std::map<std::array<long long, 3>, bool> occupied;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      if (taken[i]) continue;
      const P3 &p = candidates[i];
      const std::array<long long, 3> key{static_cast<long long>(std::floor(p[0] / c)),
                                         static_cast<long long>(std::floor(p[1] / c)),
                                         static_cast<long long>(std::floor(p[2] / c))};
      if (occupied.count(key)) continue;
      bool ok = true;
      for (const Sample &s : out)
        if (dist(p, {s.x, s.y, s.z}) < r) {
          ok = false;
          break;
        }
      if (!ok) continue;
      occupied[key] = true;
      taken[i] = true;
      out.push_back({p[0], p[1], p[2], d});
    }
  }
  return out;
}

// Points on a tilted plane and a sphere, away from the origin so (0,0,0) is never near the scene.
std::vector<P3> sceneCandidates(std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.5, 1.5), ang(0.0, 2 * M_PI), cz(-1.0, 1.0);
  std::vector<P3> pts;
  for (std::size_t i = 0; i < n; ++i) {
    if (i % 3 == 2) {
      const double t = ang(rng), z = cz(rng), s = std::sqrt(1 - z * z);
      pts.push_back({f32(2.0 + 0.6 * s * std::cos(t)), f32(-1.0 + 0.6 * s * std::sin(t)), f32(5.0 + 0.6 * z)});
    } else {
      const double x = u(rng), y = u(rng);
      pts.push_back({f32(x), f32(y), f32(4.0 + 0.1 * x - 0.05 * y)});
    }
  }
  return pts;
}

struct Scene {
  std::vector<P3> candidates;
  std::vector<Sample> samples;
};

const Scene &validScene() {
  static const Scene scene = [] {
    Scene s;
    s.candidates = sceneCandidates(3000, 11);
    s.samples = dartThrow(s.candidates, 1.0, 6);
    return s;
  }();
  return scene;
}

// ---------------------------------------------------------------- tests

TEST(SamplingVerifier, DartThrownSamplingHasNoViolations) {
  const Scene &scene = validScene();
  const PointBuffer sampling = makeSampling(scene.samples);
  const PointBuffer input = makeCloud(scene.candidates);
  const VerifyReport rep = verifySampling(sampling, 1.0, &input);
  ASSERT_EQ(rep.levels.size(), 6u);
  EXPECT_EQ(rep.total_violations(), 0u) << formatReport(rep);
  for (const LevelReport &l : rep.levels) {
    EXPECT_GT(l.count, 0u) << "level " << l.level;
    EXPECT_GE(l.min_nn_over_r, 1.0) << "level " << l.level;
    EXPECT_LE(l.max_coverage_over_r, 2.0 + rep.tolerance / radius(1.0, l.level)) << "level " << l.level;
  }
  EXPECT_EQ(rep.levels.back().union_count, scene.samples.size());
  expectSameReport(rep, bruteForce(sampling, 1.0, &input));
}

TEST(SamplingVerifier, CloseMixedLevelPairViolatesOnlyWhereBothArePresent) {
  std::vector<Sample> samples = validScene().samples;
  const double r4 = radius(1.0, 4);
  // Far from the scene: the pair only meets itself. p sits inside its level-2 cell [100, 100.25), q inside its
  // level-4 cell [100.125, 100.1875).
  samples.push_back({100.1, 0.1, 0.1, 2});
  samples.push_back({100.1 + 0.9 * r4, 0.1, 0.1, 4});
  const PointBuffer sampling = makeSampling(samples);
  const VerifyReport rep = verifySampling(sampling, 1.0, nullptr);
  ASSERT_EQ(rep.levels.size(), 6u);
  for (const LevelReport &l : rep.levels) {
    // U_2 and U_3 hold p alone; at level 5 the gap 0.9 r_4 = 1.8 r_5 is legal again.
    EXPECT_EQ(l.spacing_violations, l.level == 4 ? 2u : 0u) << "level " << l.level;
    EXPECT_EQ(l.cell_violations, 0u) << "level " << l.level;
    EXPECT_TRUE(std::isnan(l.max_coverage_over_r));
  }
  EXPECT_NEAR(rep.levels[4].min_nn_over_r, 0.9, 1e-4);
  EXPECT_GE(rep.levels[3].min_nn_over_r, 1.0);
  EXPECT_GE(rep.levels[5].min_nn_over_r, 1.0);
  expectSameReport(rep, bruteForce(sampling, 1.0, nullptr));
}

// The coarser end of a close pair is counted as well as the finer one, wherever it sits among the coarser samples:
// here it is the very last of them (the boundary of the older points the new level's close pairs are applied to).
TEST(SamplingVerifier, CloseToTheLastCoarserSampleCountsBothEnds) {
  const double r1 = radius(1.0, 1);
  for (int coarser : {1, 3}) {
    std::vector<Sample> samples;
    for (int i = 0; i < coarser; ++i) samples.push_back({10.0 * i + 0.1, 0.1, 0.1, 0});
    const Sample last = samples.back();
    samples.push_back({last.x + 0.9 * r1, last.y, last.z, 1});
    const PointBuffer sampling = makeSampling(samples);
    const VerifyReport rep = verifySampling(sampling, 1.0, nullptr);
    ASSERT_EQ(rep.levels.size(), 2u);
    EXPECT_EQ(rep.levels[0].spacing_violations, 0u) << coarser << " level-0 samples";
    EXPECT_EQ(rep.levels[1].spacing_violations, 2u) << coarser << " level-0 samples";
    expectSameReport(rep, bruteForce(sampling, 1.0, nullptr));
  }
}

TEST(SamplingVerifier, CellDuplicateCountedAtItsLevelOnly) {
  std::vector<Sample> samples = validScene().samples;
  // Opposite corners of the level-3 cell [50, 50.125) x [0, 0.125)^2: 0.18 apart, more than r_3 = 0.108, so only
  // the cell rule catches them.
  samples.push_back({50.01, 0.01, 0.01, 3});
  samples.push_back({50.115, 0.115, 0.115, 3});
  const PointBuffer sampling = makeSampling(samples);
  const VerifyReport rep = verifySampling(sampling, 1.0, nullptr);
  for (const LevelReport &l : rep.levels) {
    EXPECT_EQ(l.cell_violations, l.level == 3 ? 1u : 0u) << "level " << l.level;
    EXPECT_EQ(l.spacing_violations, 0u) << "level " << l.level;
  }
  EXPECT_EQ(rep.total_violations(), 1u);
  expectSameReport(rep, bruteForce(sampling, 1.0, nullptr));
}

TEST(SamplingVerifier, CellDuplicateWithinToleranceOfAFaceIsNotCounted) {
  std::vector<Sample> samples = validScene().samples;
  samples.push_back({50.01, 0.01, 0.01, 3});
  // One float32 ulp below the face x = 50.125: it may have been rounded there from the next cell.
  samples.push_back({static_cast<double>(std::nextafter(50.125f, 0.0f)), 0.115, 0.115, 3});
  const PointBuffer sampling = makeSampling(samples);
  const VerifyReport rep = verifySampling(sampling, 1.0, nullptr);
  EXPECT_GT(rep.tolerance, 50.125 - std::nextafter(50.125f, 0.0f));
  EXPECT_EQ(rep.total_violations(), 0u) << formatReport(rep);
}

TEST(SamplingVerifier, FarInputPointIsUncoveredAndItsDistanceMatches) {
  const Scene &scene = validScene();
  const PointBuffer sampling = makeSampling(scene.samples);
  std::vector<P3> input_pts = scene.candidates;
  const P3 far{10.0, 10.0, 10.0};
  input_pts.push_back(far);
  input_pts.push_back({0.0, 0.0, 0.0});  // a no-return: 4 m from the scene, would be uncovered if it counted
  input_pts.push_back({kNaN, 1.0, 1.0});
  input_pts.push_back({kInf, 1.0, 1.0});
  const PointBuffer input = makeCloud(input_pts);
  const VerifyReport rep = verifySampling(sampling, 1.0, &input);
  std::vector<P3> u;
  for (const LevelReport &l : rep.levels) {
    for (const Sample &s : scene.samples)
      if (s.level == l.level) u.push_back({f32(s.x), f32(s.y), f32(s.z)});
    double best = kInf;
    for (const P3 &q : u) best = std::min(best, dist(far, q));
    EXPECT_EQ(l.coverage_violations, 1u) << "level " << l.level;
    EXPECT_NEAR(l.max_coverage_over_r, best / radius(1.0, l.level), 1e-12 * best) << "level " << l.level;
    EXPECT_EQ(l.spacing_violations + l.cell_violations, 0u);
  }
  expectSameReport(rep, bruteForce(sampling, 1.0, &input));
}

// Found: `hpds verify --spacing` passed a sampling without its finest levels, and an empty one, against their input:
// only the levels present were checked. through_level makes the levels a sampling was asked to reach count.
TEST(SamplingVerifier, LevelsTheSamplingWasAskedToReachAreCheckedEvenWhenEmpty) {
  const Scene &scene = validScene();
  std::vector<Sample> coarse;
  for (const Sample &s : scene.samples)
    if (s.level <= 2) coarse.push_back(s);
  const PointBuffer sampling = makeSampling(coarse);
  const PointBuffer input = makeCloud(scene.candidates);
  EXPECT_EQ(verifySampling(sampling, 1.0, &input).total_violations(), 0u) << "levels 0..2 alone are a valid sampling";
  const VerifyReport rep = verifySampling(sampling, 1.0, &input, 1, -1, 5);
  ASSERT_EQ(rep.levels.size(), 6u);
  for (int d = 3; d <= 5; ++d) {
    const LevelReport &l = rep.levels[d];
    EXPECT_EQ(l.count, 0u);
    EXPECT_EQ(l.union_count, coarse.size());
    // The oracle: candidates farther than 2 r_D from every kept sample (none lies within the tolerance of it).
    std::size_t uncovered = 0;
    for (const P3 &p : scene.candidates) {
      double best = kInf;
      for (const Sample &q : coarse) best = std::min(best, dist({f32(p[0]), f32(p[1]), f32(p[2])}, {f32(q.x), f32(q.y), f32(q.z)}));
      uncovered += best > 2.0 * radius(1.0, d) ? 1 : 0;
    }
    EXPECT_GT(uncovered, 0u) << "level " << d;
    EXPECT_EQ(l.coverage_violations, uncovered) << "level " << d;
  }

  // An empty sampling covers nothing: every input point counts at each level asked for.
  const VerifyReport empty = verifySampling(makeSampling({}), 1.0, &input, 1, -1, 0);
  ASSERT_EQ(empty.levels.size(), 1u);
  EXPECT_EQ(empty.levels[0].coverage_violations, scene.candidates.size());
  EXPECT_TRUE(verifySampling(makeSampling({}), 1.0, &input).levels.empty()) << "without through_level: nothing to check";
  EXPECT_THROW((void)verifySampling(sampling, 1.0, &input, 1, -1, 22), std::invalid_argument);
  EXPECT_THROW((void)verifySampling(sampling, 1.0, &input, 1, -1, -2), std::invalid_argument);
}

// The sampler inserts no point 2^30 - 8 cells of its finest level or more from the origin (CellKey.hpp): no sample
// can cover one, and counting it as uncovered failed samplings that did all they could.
TEST(SamplingVerifier, InputBeyondTheKeyRangeIsCountedNotCovered) {
  const PointBuffer sampling = makeSampling({{0.5, 0.5, 0.5, 0}});
  // At depth 21 of 1 m cells: the last coordinate the sampler inserts and the first it refuses.
  const double inside = std::ldexp(1073741824.0 - 9.0, -21), outside = std::ldexp(1073741824.0 - 8.0, -21);
  ASSERT_TRUE(inCellRange(inside, std::ldexp(1.0, 21)));
  ASSERT_FALSE(inCellRange(outside, std::ldexp(1.0, 21)));
  const PointBuffer input =
      makeCloud({{0.5, 0.5, 0.5}, {outside, 0.5, 0.5}, {0.5, 0.5, -outside}, {inside, 0.5, 0.5}}, FieldType::Float64);

  const VerifyReport rep = verifySampling(sampling, 1.0, &input, 1, 21);
  EXPECT_EQ(rep.key_range_depth, 21);
  EXPECT_EQ(rep.input_points, 4u);
  EXPECT_EQ(rep.input_beyond_key_range, 2u);
  ASSERT_EQ(rep.levels.size(), 1u);
  EXPECT_EQ(rep.levels[0].coverage_violations, 1u) << "the point the sampler inserts must still be covered";
  const std::string text = formatReport(rep);
  EXPECT_NE(text.find("2 of the 4 input points lie beyond the exact key range of level 21"), std::string::npos)
      << text;

  // Without the sampler's depth, only the deepest level present bounds it (here 0: 1e9 m), so all three count.
  const VerifyReport unknown = verifySampling(sampling, 1.0, &input);
  EXPECT_EQ(unknown.key_range_depth, 0);
  EXPECT_EQ(unknown.input_beyond_key_range, 0u);
  EXPECT_EQ(unknown.levels[0].coverage_violations, 3u);
  EXPECT_EQ(formatReport(unknown).find("key range"), std::string::npos);

  // A depth shallower than a level present, or beyond 21, is no sampler's.
  const PointBuffer two_levels = makeSampling({{0.5, 0.5, 0.5, 0}, {0.1, 0.1, 0.1, 1}});
  EXPECT_THROW((void)verifySampling(two_levels, 1.0, &input, 1, 0), std::invalid_argument);
  EXPECT_NO_THROW((void)verifySampling(two_levels, 1.0, &input, 1, 1));
  EXPECT_THROW((void)verifySampling(sampling, 1.0, &input, 1, 22), std::invalid_argument);
  EXPECT_THROW((void)verifySampling(sampling, 1.0, &input, 1, -2), std::invalid_argument);
}

TEST(SamplingVerifier, MatchesBruteForceOnRandomSets) {
  // The last seed has > 3 * 1024 level-4 points and 3000 probes, enough to split the loops into thread chunks.
  for (unsigned seed : {1u, 2u, 3u}) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-3.0, 3.0);
    std::uniform_int_distribution<int> lv(0, 4);
    std::vector<Sample> samples;
    const int n = seed == 3 ? 7000 : 1500;
    for (int i = 0; i < n; ++i) samples.push_back({u(rng), u(rng), 0.2 * u(rng), i % 2 ? 4 : lv(rng)});
    samples.push_back(samples[7]);  // an exact duplicate: nearest neighbour 0
    samples.push_back({kNaN, 0.0, 0.0, 2});
    std::vector<P3> probes;
    for (int i = 0; i < (seed == 3 ? 3000 : 800); ++i) probes.push_back({u(rng), u(rng), u(rng)});
    const PointBuffer sampling = makeSampling(samples);
    const PointBuffer input = makeCloud(probes);
    const double cell = 2.0;
    const VerifyReport want = bruteForce(sampling, cell, &input);
    // Random points at these densities break every rule at the finer levels, so the counts are exercised.
    EXPECT_GT(want.levels[4].spacing_violations, 100u);
    EXPECT_GT(want.levels[2].cell_violations, 0u);
    EXPECT_GT(want.levels[4].coverage_violations, 0u);
    for (int threads : {1, 3}) {
      SCOPED_TRACE("seed " + std::to_string(seed) + " threads " + std::to_string(threads));
      expectSameReport(verifySampling(sampling, cell, &input, threads), want);
    }
    EXPECT_EQ(want.levels[4].min_nn_over_r, 0.0);
  }
}

TEST(SamplingVerifier, NonFiniteSampleIsAViolationWhereverItIsInTheUnion) {
  std::vector<Sample> samples = validScene().samples;
  samples.push_back({kNaN, 4.0, 4.0, 1});
  const VerifyReport rep = verifySampling(makeSampling(samples), 1.0, nullptr);
  for (const LevelReport &l : rep.levels) EXPECT_EQ(l.spacing_violations, l.level >= 1 ? 1u : 0u) << l.level;
}

TEST(SamplingVerifier, ToleranceAbsorbsFloatRoundingButNotRealViolations) {
  const double r0 = radius(1.0, 0);
  // Different level-0 cells ([100,101) and [101,102) in x), so only spacing is in play.
  const auto pairAt = [&](double gap) {
    return std::vector<Sample>{{100.7, 100.5, 100.5, 0}, {100.7 + gap, 100.5, 100.5, 0}};
  };
  {
    const VerifyReport rep = verifySampling(makeSampling(pairAt(r0 * (1 - 1e-9))), 1.0, nullptr);
    EXPECT_NEAR(rep.tolerance, 4.0 * std::pow(2.0, -24) * f32(100.7 + r0), 1e-10);
    EXPECT_EQ(rep.total_violations(), 0u) << formatReport(rep);
  }
  {
    const VerifyReport rep = verifySampling(makeSampling(pairAt(0.99 * r0)), 1.0, nullptr);
    EXPECT_EQ(rep.levels[0].spacing_violations, 2u);
  }
  // In float64 storage the tolerance is float64's, and the threshold r - tol itself is visible: a pair a float32
  // rounding too close is a violation there.
  const double tol32 = 4.0 * std::pow(2.0, -24) * (100.7 + r0), tol64 = 4.0 * std::pow(2.0, -53) * (100.7 + r0);
  EXPECT_NEAR(verifySampling(makeSampling(pairAt(r0), FieldType::Float64), 1.0, nullptr).tolerance, tol64, 1e-20);
  EXPECT_EQ(verifySampling(makeSampling(pairAt(r0 - 0.25 * tol64), FieldType::Float64), 1.0, nullptr)
                .total_violations(),
            0u);
  EXPECT_EQ(verifySampling(makeSampling(pairAt(r0 - 3.0 * tol64), FieldType::Float64), 1.0, nullptr)
                .total_violations(),
            2u);
  EXPECT_EQ(verifySampling(makeSampling(pairAt(r0 - 0.5 * tol32), FieldType::Float64), 1.0, nullptr)
                .total_violations(),
            2u);
}

TEST(SamplingVerifier, LevelsFloat32CannotResolveAreViolationsNotPasses) {
  // At 5e6 m a float32 is exact to 0.25 m: tol = 4 * 2^-24 * M = 1.19 m, more than a tenth of every radius from
  // level 0 (0.87 m at cell 1 m) down. Those levels are reported unresolved, one violation each, not passed.
  const std::vector<Sample> far = {{5e6 + 0.5, 0.5, 0.5, 0}, {5e6 + 2.5, 0.5, 0.5, 1}};
  const VerifyReport f32rep = verifySampling(makeSampling(far), 1.0, nullptr);
  ASSERT_EQ(f32rep.levels.size(), 2u);
  EXPECT_TRUE(f32rep.levels[0].unresolved && f32rep.levels[1].unresolved);
  EXPECT_EQ(f32rep.total_violations(), 2u);
  EXPECT_NE(formatReport(f32rep).find("levels 0 and finer cannot be checked"), std::string::npos);
  const VerifyReport f64rep = verifySampling(makeSampling(far, FieldType::Float64), 1.0, nullptr);
  EXPECT_FALSE(f64rep.levels[0].unresolved || f64rep.levels[1].unresolved);
  EXPECT_EQ(f64rep.total_violations(), 0u) << formatReport(f64rep);
  // Near the origin float32 resolves every level a sampling reaches.
  const VerifyReport near = verifySampling(makeSampling({{0.5, 0.5, 0.5, 0}, {2.5, 0.5, 0.5, 1}}), 1.0, nullptr);
  EXPECT_FALSE(near.levels[1].unresolved);
}

TEST(SamplingVerifier, AWrongCellSizeCostsTimeNotMemory) {
  // Found with --cell-size far too large: every pair of samples was then a close pair, all held at once (memory
  // quadratic in the samples: 1.1 GB for 47 k, then bad_alloc). 4 000 samples on each of two levels within 1 m,
  // checked with 1 km cells: 16 M close pairs, 256 MB as held before. ctest runs this test in its own process, so
  // the peak resident size is this test's.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Sample> samples;
  for (int i = 0; i < 8000; ++i) samples.push_back({u(rng), u(rng), u(rng), i % 2});
  const VerifyReport rep = verifySampling(makeSampling(samples), 1000.0, nullptr, 2);
  EXPECT_EQ(rep.levels[1].spacing_violations, 8000u);
  rusage usage{};
  ASSERT_EQ(getrusage(RUSAGE_SELF, &usage), 0);
  EXPECT_LT(usage.ru_maxrss, 150 * 1024) << "peak resident size " << usage.ru_maxrss / 1024 << " MB";
}

TEST(SamplingVerifier, InvalidInputsThrow) {
  const PointBuffer good = makeSampling({{0.5, 0.5, 0.5, 0}});
  EXPECT_NO_THROW((void)verifySampling(good, 1.0, nullptr));
  for (double c : {0.0, -1.0, kNaN, kInf}) EXPECT_THROW((void)verifySampling(good, c, nullptr), std::invalid_argument);
  for (int bad_level : {22, 200}) {
    EXPECT_THROW((void)verifySampling(makeSampling({{0.5, 0.5, 0.5, bad_level}}), 1.0, nullptr),
                 std::invalid_argument);
  }
  {
    PointLayout layout;  // float level field to express -1 and 1.5
    layout.append("x", FieldType::Float32);
    layout.append("y", FieldType::Float32);
    layout.append("z", FieldType::Float32);
    layout.append("level", FieldType::Float32);
    for (double bad : {-1.0, 1.5, kNaN}) {
      PointBuffer buf(layout, 1);
      writeFromDouble(buf.record(0), layout.fields[3], bad);
      EXPECT_THROW((void)verifySampling(buf, 1.0, nullptr), std::invalid_argument) << bad;
    }
  }
  {
    PointLayout no_level;
    no_level.append("x", FieldType::Float32);
    no_level.append("y", FieldType::Float32);
    no_level.append("z", FieldType::Float32);
    EXPECT_THROW((void)verifySampling(PointBuffer(no_level, 1), 1.0, nullptr), std::invalid_argument);
    PointLayout no_z;
    no_z.append("x", FieldType::Float32);
    no_z.append("y", FieldType::Float32);
    no_z.append("level", FieldType::UInt8);
    EXPECT_THROW((void)verifySampling(PointBuffer(no_z, 1), 1.0, nullptr), std::invalid_argument);
    const PointBuffer input_without_z(no_z, 1);
    EXPECT_THROW((void)verifySampling(good, 1.0, &input_without_z), std::invalid_argument);
  }
}

TEST(SamplingVerifier, EmptySamplingHasNoLevels) {
  const VerifyReport rep = verifySampling(makeSampling({}), 1.0, nullptr);
  EXPECT_TRUE(rep.levels.empty());
  EXPECT_EQ(rep.total_violations(), 0u);
}

TEST(SamplingVerifier, FormatReportHasOneRowPerLevel) {
  const Scene &scene = validScene();
  const PointBuffer sampling = makeSampling(scene.samples);
  const PointBuffer input = makeCloud(scene.candidates);
  for (bool with_input : {false, true}) {
    const VerifyReport rep = verifySampling(sampling, 1.0, with_input ? &input : nullptr);
    const std::string text = formatReport(rep);
    std::istringstream lines(text);
    std::string line;
    std::vector<std::string> rows;
    while (std::getline(lines, line)) {
      int level = -1;
      if (std::sscanf(line.c_str(), "%d", &level) == 1) rows.push_back(line);
    }
    ASSERT_EQ(rows.size(), rep.levels.size()) << text;
    for (std::size_t d = 0; d < rows.size(); ++d) {
      std::istringstream cols(rows[d]);
      std::vector<std::string> c;
      for (std::string w; cols >> w;) c.push_back(w);
      ASSERT_EQ(c.size(), 9u) << rows[d];
      EXPECT_EQ(c[0], std::to_string(d));
      EXPECT_EQ(c[2], std::to_string(rep.levels[d].count));
      EXPECT_EQ(with_input, c[7] != "-") << rows[d];
    }
    EXPECT_NE(text.find("min_nn/r"), std::string::npos);
  }
}

// Cell centres of every level form a valid sampling with all gaps >= r_D (per axis the centres of different
// levels differ by an odd multiple of half the finer cell), so random subsets of them give large valid inputs
// without a sampler: ~300k samples over 9 levels on a 64 m x 64 m slab.
TEST(SamplingVerifier, LargeSamplingTiming) {
  const double cell = 8.0;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Sample> samples;
  for (int d = 0; d <= 8; ++d) {
    const double c = std::ldexp(cell, -d);
    const long long n = static_cast<long long>(64.0 / c);
    const double keep = std::min(1.0, 150000.0 * std::pow(0.5, 8 - d) / double(n * n));
    for (long long i = 0; i < n; ++i)
      for (long long j = 0; j < n; ++j)
        if (u01(rng) < keep) samples.push_back({(i + 0.5) * c, (j + 0.5) * c, 0.5 * c, d});
  }
  std::vector<P3> input;
  std::uniform_real_distribution<double> uxy(0.0, 64.0), uz(0.0, 4.0);
  for (int i = 0; i < 300000; ++i) input.push_back({uxy(rng), uxy(rng), uz(rng)});
  const PointBuffer sampling = makeSampling(samples);
  const PointBuffer cloud = makeCloud(input);
  VerifyReport single[2];
  for (int threads : {1, 2}) {
    for (bool with_input : {false, true}) {
      const auto t0 = std::chrono::steady_clock::now();
      const VerifyReport rep = verifySampling(sampling, cell, with_input ? &cloud : nullptr, threads);
      const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::cout << "[ timing   ] " << samples.size() << " samples, 9 levels, threads " << threads
                << (with_input ? ", coverage of 300000 input points: " : ", no input: ") << secs << " s\n";
      ASSERT_EQ(rep.levels.size(), 9u);
      for (const LevelReport &l : rep.levels) {
        EXPECT_EQ(l.spacing_violations, 0u) << l.level;
        EXPECT_EQ(l.cell_violations, 0u) << l.level;
        EXPECT_GE(l.min_nn_over_r, 1.0 - 1e-12) << l.level;
      }
      EXPECT_LT(secs, 30.0);  // a guard against accidental O(n^2), not a benchmark
      if (threads == 1 && !with_input) std::cout << formatReport(rep);
      if (threads == 1)
        single[with_input] = rep;
      else
        expectSameReport(rep, single[with_input]);
    }
  }
}

}  // namespace
}  // namespace hpds
