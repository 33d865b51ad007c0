// The refined normal estimator (NormalParams::neighborhood_level_offset, max_growth) on geometry with a known normal:
// a noisy plane (finer levels average the noise) and parallel scan lines on a plane (growth spans two lines).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <array>
#include <cstring>
#include <map>

#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "HierarchyTestSupport.hpp"
#include "hpds/sampling/Hierarchy.hpp"
#include "normals/CellCentroids.hpp"
#include "normals/RefinedNormals.hpp"

namespace hpds {
namespace {

constexpr double kCell = 1.0;

Hierarchy build(const std::vector<double> &xyz, int max_depth, unsigned seed) {
  return test::buildShuffled(xyz, kCell, max_depth, seed, {0.3, 0.2, 5.0});  // above the plane z = 0
}

/// Angles in degrees between the estimated normals and +z (NaN for invalid ones).
std::vector<double> errorsToZ(const std::vector<SampleNormal> &n) {
  std::vector<double> e;
  for (const auto &s : n)
    e.push_back(s.valid ? std::acos(std::min(1.0, std::abs(double(s.normal[2])))) * 57.29577951308232 : NAN);
  return e;
}

double median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return std::isnan(x); }), v.end());
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

NormalParams params(int level, int k, double radius) {
  NormalParams p;
  p.level = level;
  p.k = k;
  p.radius = radius;
  p.min_neighbors = 3;
  return p;
}

/// The refined estimator on `h` at `level` as the defaults run it (footprint 2.5 r_L, averaging points two levels
/// finer, 5 neighbours at least), growing up to `max_growth`.
NormalParams refinedParams(const Hierarchy &h, int level, double max_growth) {
  NormalParams p = params(level, 0, 2.5 * h.radius(level));
  p.min_neighbors = 5;
  p.neighborhood_level_offset = 2;
  p.max_growth = max_growth;
  return p;
}

TEST(RefinedNormals, FinerLevelsAverageRangeNoise) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(0.0, 4.0);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<double> xyz;
  for (int i = 0; i < 60000; ++i) xyz.insert(xyz.end(), {u(rng), u(rng), noise(rng)});
  const Hierarchy h = build(xyz, 7, 3);
  const int level = 4;  // r_4 = 0.054 m, noise 1 cm
  const std::vector<SampleId> ids = h.samplesUpTo(level);
  NormalParams plain = params(level, 10, 0.0);
  NormalParams fine = plain;
  fine.neighborhood_level_offset = 2;
  const double e_plain = median(errorsToZ(estimateNormals(h, ids, plain)));
  const double e_fine = median(errorsToZ(estimateNormals(h, ids, fine)));
  EXPECT_LT(e_fine, 0.6 * e_plain) << "plain " << e_plain << " deg, finer levels " << e_fine << " deg";
  // Radius neighbourhoods gain too.
  NormalParams rp = params(level, 0, 2.5 * h.radius(level));
  NormalParams rf = rp;
  rf.neighborhood_level_offset = 2;
  EXPECT_LT(median(errorsToZ(estimateNormals(h, ids, rf))), median(errorsToZ(estimateNormals(h, ids, rp))));
}

TEST(RefinedNormals, GrowthSpansParallelScanLines) {
  // Dense lines along x on the plane z = 0, 0.8 m apart, with 1 cm range noise along a ray that meets the plane at
  // 20 degrees, as a lidar ring on the ground: one line's scatter spans a plane tilted by those 20 degrees.
  std::mt19937_64 rng(2);
  std::normal_distribution<double> noise(0.0, 0.01);
  const double c = std::cos(20.0 / 57.29577951308232), s = std::sin(20.0 / 57.29577951308232);
  std::vector<double> xyz;
  for (int line = 0; line < 6; ++line)
    for (int i = 0; i < 2000; ++i) {
      const double n = noise(rng);
      xyz.insert(xyz.end(), {i * 0.003, line * 0.8 + c * n, s * n});
    }
  const Hierarchy h = build(xyz, 6, 5);
  // r_3 = 0.108 m: samples of one line are far closer than the lines, and a 10-sample footprint (~1 m) is long
  // against the 1 cm scatter, as for a lidar ring at the benchmark's output level.
  const int level = 3;
  std::vector<SampleId> ids;
  for (SampleId id : h.samplesUpTo(level)) {
    const double *p = h.position(id);
    if (p[0] > 1.0 && p[0] < 5.0 && p[1] > 0.4 && p[1] < 3.6) ids.push_back(id);  // inner lines, away from ends
  }
  ASSERT_GT(ids.size(), 100u);
  NormalParams plain = params(level, 10, 0.0);
  NormalParams grown = plain;
  grown.max_growth = 64.0;
  const auto e_plain = errorsToZ(estimateNormals(h, ids, plain));
  const auto e_grown = errorsToZ(estimateNormals(h, ids, grown));
  EXPECT_GT(median(e_plain), 10.0);
  std::vector<double> sorted = e_grown;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_LT(sorted[sorted.size() * 99 / 100], 3.0) << "median " << median(e_grown) << ", max " << sorted.back();

}

TEST(RefinedNormals, AScanLineWhoseGrownBallReachesTheGroundKeepsThePlaneThroughIt) {
  // A wall (the plane y = 0) seen as scan lines along x, 0.6 m apart in height, with 1 cm range noise along a ray
  // that meets it at about 30 degrees, standing on dense ground (z = 0, y < 0). The line at 0.9 m: its first
  // non-line ball (1.08 m, the lines above and below) reaches the ground, so it is not flat; the plane through the
  // line that both neighbouring lines support is the wall's. The lowest line (0.3 m) has the ground on one side and
  // no line below it: no plane through it is supported on both sides, and it stays a line rather than take a plane
  // the ground's points happen to favour.
  std::mt19937_64 rng(12);
  std::normal_distribution<double> noise(0.0, 0.01);
  const Eigen::Vector3d ray = Eigen::Vector3d(0.55, -0.8, 0.25).normalized();
  std::vector<double> xyz;
  for (const double z : {0.3, 0.9, 1.5, 2.1})
    for (int i = 0; i < 2000; ++i) {
      const Eigen::Vector3d p = Eigen::Vector3d(i * 0.003, 0.0, z) + noise(rng) * ray;
      xyz.insert(xyz.end(), {p.x(), p.y(), p.z()});
    }
  for (int i = 0; i < 120; ++i)
    for (int j = 1; j <= 40; ++j) xyz.insert(xyz.end(), {0.0013 + 0.05 * i, -0.05 * j, 0.002 * noise(rng)});
  const Hierarchy h = test::buildShuffled(xyz, kCell, 6, 13, {3.0, -6.0, 1.5});
  const int level = 3;  // r_3 = 0.108 m: one line's samples, the lines 0.6 m apart
  std::vector<SampleId> wall, lowest;
  for (SampleId id : h.samplesUpTo(level)) {
    const double *p = h.position(id);
    if (p[0] < 1.5 || p[0] > 4.5) continue;  // away from the lines' ends
    if (std::abs(p[1]) < 0.05 && std::abs(p[2] - 0.9) < 0.05) wall.push_back(id);
    if (std::abs(p[1]) < 0.05 && std::abs(p[2] - 0.3) < 0.05) lowest.push_back(id);
  }
  ASSERT_GT(wall.size(), 20u);
  ASSERT_GT(lowest.size(), 20u);
  const NormalParams p = refinedParams(h, level, 8.0);
  std::vector<LocalPca> nb;
  const std::vector<SampleNormal> wn = estimateNormals(h, wall, p, &nb);
  for (std::size_t i = 0; i < wall.size(); ++i) {
    ASSERT_TRUE(wn[i].valid);
    EXPECT_GT(std::abs(wn[i].normal[1]), std::cos(5.0 / 57.29577951308232)) << "wall sample " << i;
    EXPECT_GE(nb[i].l1, p.line_ratio * nb[i].l2) << "wall sample " << i << ": a plane, not the line";
  }
  (void)estimateNormals(h, lowest, p, &nb);
  for (std::size_t i = 0; i < lowest.size(); ++i)
    EXPECT_LT(nb[i].l1, p.line_ratio * nb[i].l2) << "lowest line's sample " << i << " was given a plane";
}

TEST(RefinedNormals, OfTwoPlanesThroughAScanLineTiedOnVotesTheFlatterIsTaken) {
  // A scan line along x with two planes through it, as two rows each 0.6 m to either side: the plane z = 0 exact,
  // the plane y = 0 with 5 mm of scatter. Every point is 5 cm from the next, so every one is a sample of levels
  // 0..5 and both planes get exactly the same votes. The line's ball at 0.54 m holds the line only; at 1.08 m it
  // holds both planes (not flat), so the plane through the line is chosen between the two: the flatter, z = 0.
  // Four windows tie (each plane's bin with either neighbour). The first of them, the rule before, depended on where
  // the bins fell about the line's axis, whose sign is arbitrary; one of these turns then got neither plane (its
  // first window was 5 degrees off the flat plane, whose rows fell outside the refit's band).
  std::mt19937_64 rng(21);
  std::normal_distribution<double> line_noise(0.0, 0.002), row_noise(0.0, 0.005);
  std::uniform_real_distribution<double> angle(-3.14159, 3.14159);
  std::vector<Eigen::Vector3d> scene;
  for (int i = -60; i <= 60; ++i) {
    const double x = 0.05 * i + 0.0013;
    scene.emplace_back(x, line_noise(rng), line_noise(rng));
    for (const double side : {-0.6, 0.6}) {
      scene.emplace_back(x, side, 0.0);            // the plane z = 0
      scene.emplace_back(x, row_noise(rng), side);  // the plane y = 0, scattered
    }
  }
  int flatter = 0;
  constexpr int kTurns = 12;
  for (int turn = 0; turn < kTurns; ++turn) {
    const Eigen::Matrix3d rot = (Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitX()))
                                    .toRotationMatrix();
    const Eigen::Vector3d shift(20.0, -7.0, 3.0);
    std::vector<double> xyz;
    for (const Eigen::Vector3d &p : scene) {
      const Eigen::Vector3d q = rot * p + shift;
      xyz.insert(xyz.end(), {q.x(), q.y(), q.z()});
    }
    const Eigen::Vector3d view = rot * Eigen::Vector3d(0.0, 3.0, 4.0) + shift;
    const Hierarchy h = test::buildShuffled(xyz, kCell, 6, 31 + turn, {view.x(), view.y(), view.z()});
    const int level = 3;  // r_3 = 0.108 m: footprints 0.27, 0.54 and 1.08 m
    std::vector<SampleId> query;
    for (SampleId id : h.samplesUpTo(5))
      if ((Eigen::Vector3d(h.position(id)) - (rot * Eigen::Vector3d(0.0013, 0.0, 0.0) + shift)).norm() < 0.01)
        query.push_back(id);
    ASSERT_EQ(query.size(), 1u) << "turn " << turn;
    const NormalParams p = refinedParams(h, level, 4.0);
    std::vector<LocalPca> nb;
    const std::vector<SampleNormal> n = estimateNormals(h, query, p, &nb);
    ASSERT_TRUE(n[0].valid) << "turn " << turn;
    const Eigen::Vector3d got(n[0].normal[0], n[0].normal[1], n[0].normal[2]);
    const double to_flat = std::abs(got.dot(rot * Eigen::Vector3d::UnitZ()));
    const double to_scattered = std::abs(got.dot(rot * Eigen::Vector3d::UnitY()));
    EXPECT_TRUE(to_flat > 0.999 || to_scattered > 0.999) << "turn " << turn << ": neither plane";
    flatter += to_flat > 0.999 ? 1 : 0;
  }
  EXPECT_EQ(flatter, kTurns);
}

TEST(RefinedNormals, TooFewNeighboursGrowTheFootprintUntilThereAreEnough) {
  // A plane sampled on a 0.2 m grid, far sparser than the output level: the base footprint (2.5 r_5 = 0.068 m) holds
  // the sample alone, 2x still, 4x (0.27 m) the sample and its four nearest grid neighbours.
  std::vector<double> xyz;
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) xyz.insert(xyz.end(), {0.013 + 0.2 * i, 0.029 + 0.2 * j, 0.0});
  const Hierarchy h = build(xyz, 6, 11);
  const int level = 5;
  std::vector<SampleId> ids;
  for (SampleId id : h.samplesUpTo(level)) {
    const double *p = h.position(id);
    if (p[0] > 0.3 && p[0] < 3.6 && p[1] > 0.3 && p[1] < 3.6) ids.push_back(id);  // four neighbours each
  }
  ASSERT_EQ(ids.size(), 16u * 16u);
  NormalParams p = params(level, 0, 2.5 * h.radius(level));
  p.min_neighbors = 5;
  p.neighborhood_level_offset = 0;
  for (const double growth : {1.0, 2.0}) {
    p.max_growth = growth;
    for (const SampleNormal &n : estimateNormals(h, ids, p)) EXPECT_FALSE(n.valid) << "growth " << growth;
  }
  p.max_growth = 8.0;
  for (const SampleNormal &n : estimateNormals(h, ids, p)) {
    ASSERT_TRUE(n.valid);
    EXPECT_NEAR(n.normal[2], 1.0f, 1e-6f);  // the viewpoint is above
  }
}

TEST(RefinedNormals, ThreadCountDoesNotChangeResultsAndNormalsFaceTheViewpoint) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0.0, 3.0);
  std::vector<double> xyz;
  for (int i = 0; i < 20000; ++i) xyz.insert(xyz.end(), {u(rng), u(rng), 0.01 * std::sin(u(rng))});
  const Hierarchy h = build(xyz, 6, 7);
  const std::vector<SampleId> ids = h.samplesUpTo(4);
  NormalParams p = params(4, 10, 0.0);
  p.neighborhood_level_offset = 2;
  p.max_growth = 8.0;
  p.threads = 1;
  const auto a = estimateNormals(h, ids, p);
  p.threads = 3;
  const auto b = estimateNormals(h, ids, p);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].valid, b[i].valid);
    if (!a[i].valid) continue;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(a[i].normal[c], b[i].normal[c]);
    EXPECT_GT(a[i].normal[2], 0.0f);  // the viewpoint is above
  }
}

TEST(RefinedNormals, IsolatedSamplesStayInvalidAndOffsetsBeyondMaxDepthAreClamped) {
  std::vector<double> xyz = {0.1, 0.1, 0.0, 3.7, 3.7, 0.0};
  const Hierarchy h = build(xyz, 3, 1);
  NormalParams p = params(3, 10, 0.0);
  p.neighborhood_level_offset = 10;
  p.max_growth = 4.0;
  for (const auto &n : estimateNormals(h, h.samplesUpTo(3), p)) {
    EXPECT_FALSE(n.valid);
    EXPECT_TRUE(std::isnan(n.normal[0]));
  }
  EXPECT_TRUE(estimateNormals(h, {}, p).empty());
}

// ---------------------------------------------------------------- scan mode: the frame's own cell centroids

using CellIndex = std::array<double, 3>;  // floor(p / edge) per axis, exact integers

/// Brute force: per cell floor(p * (1 / edge)), the sum of its points and their count, by increasing cell.
std::map<CellIndex, std::array<double, 4>> bruteCentroids(const std::vector<double> &xyz,
                                                         const std::vector<std::uint32_t> &indices, double edge) {
  std::map<CellIndex, std::array<double, 4>> cells;
  const double inv = 1.0 / edge;
  for (std::uint32_t i : indices) {
    const double *p = &xyz[3 * std::size_t(i)];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
    auto &c = cells[{std::floor(p[0] * inv), std::floor(p[1] * inv), std::floor(p[2] * inv)}];
    for (int a = 0; a < 3; ++a) c[a] += p[a];
    c[3] += 1.0;
  }
  return cells;
}

void expectCentroidsMatch(const std::vector<double> &xyz, const std::vector<std::uint32_t> &indices, double edge) {
  const std::vector<double> got = cellCentroids(xyz.data(), indices.data(), indices.size(), edge);
  const auto want = bruteCentroids(xyz, indices, edge);
  ASSERT_EQ(got.size(), 3 * want.size()) << "edge " << edge;
  std::size_t k = 0;
  for (const auto &[cell, sum] : want) {  // in cell order, x-major
    for (int a = 0; a < 3; ++a)
      ASSERT_NEAR(got[3 * k + a], sum[a] / sum[3], 1e-12 * (1.0 + std::fabs(sum[a] / sum[3]))) << "cell " << k;
    ++k;
  }
}

TEST(CellCentroids, MatchBruteForceInCellOrder) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-5.0, 5.0);
  std::uniform_int_distribution<int> grid(-160, 160);
  std::vector<double> xyz;
  for (int i = 0; i < 20000; ++i) xyz.insert(xyz.end(), {u(rng), u(rng), 0.3 * u(rng)});
  // On cell faces of every edge below (multiples of 1/32 m are exact), repeated points, a non-finite coordinate.
  for (int i = 0; i < 2000; ++i) xyz.insert(xyz.end(), {grid(rng) / 32.0, grid(rng) / 32.0, grid(rng) / 32.0});
  xyz.insert(xyz.end(), {1.0, 2.0, 3.0, 1.0, 2.0, 3.0, NAN, 0.0, 0.0, 0.5, INFINITY, 0.5});
  std::vector<std::uint32_t> all(xyz.size() / 3), every_third;
  std::iota(all.begin(), all.end(), 0u);
  for (std::uint32_t i = 0; i < all.size(); i += 3) every_third.push_back(i);
  for (const double edge : {1.0 / 32.0, 0.1, 1.0, 20.0}) {
    expectCentroidsMatch(xyz, all, edge);
    expectCentroidsMatch(xyz, every_third, edge);
  }
  // A far outlier (2^21 cells and more from the rest on an axis): the wide path, the same answer.
  xyz.insert(xyz.end(), {-1e6, 3.0, 1.0});
  all.push_back(static_cast<std::uint32_t>(all.size()));
  expectCentroidsMatch(xyz, all, 1.0 / 32.0);
  EXPECT_TRUE(cellCentroids(xyz.data(), all.data(), 0, 0.1).empty());
  EXPECT_TRUE(cellCentroids(xyz.data(), all.data(), all.size(), 0.0).empty());
}

TEST(CellCentroids, BoxHoldsEveryKeptPoint) {
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<double> u(-40.0, 40.0);
  std::vector<double> xyz;
  for (int i = 0; i < 5000; ++i) xyz.insert(xyz.end(), {u(rng), u(rng), 0.1 * u(rng)});
  xyz.insert(xyz.end(), {NAN, 0.0, 0.0});
  std::vector<std::uint32_t> all(xyz.size() / 3);
  std::iota(all.begin(), all.end(), 0u);
  double box[6];
  const double edge = 0.05;
  (void)cellCentroids(xyz.data(), all.data(), all.size(), edge, box);
  for (std::size_t i = 0; i + 1 < all.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      ASSERT_LT(box[a], xyz[3 * i + a]);
      ASSERT_GT(box[3 + a], xyz[3 * i + a]);
    }
  for (int a = 0; a < 3; ++a) EXPECT_LE(box[3 + a] - box[a], 80.0 * (a == 2 ? 0.1 : 1.0) + 3.0 * edge + 1e-9);
  // The wide path (a point 2^30 cells away) has no box.
  xyz.insert(xyz.end(), {1e9, 0.0, 0.0});
  all.push_back(static_cast<std::uint32_t>(all.size()));
  (void)cellCentroids(xyz.data(), all.data(), all.size(), edge, box);
  for (double v : box) EXPECT_TRUE(std::isnan(v));
}

/// 20 000 points: a floor with sparse scan lines far out (footprints grow over several radii) and a wall.
std::vector<double> floorLinesAndWall(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 4.0);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<double> xyz;
  for (int i = 0; i < 20000; ++i) {
    const double x = u(rng), y = u(rng);
    if (i % 5 == 0) xyz.insert(xyz.end(), {4.0 + 0.5 * x, std::floor(y * 2.0) * 0.7, noise(rng)});
    else if (i % 5 == 1) xyz.insert(xyz.end(), {x, 4.0 + noise(rng), y});
    else xyz.insert(xyz.end(), {x, y, noise(rng)});
  }
  return xyz;
}

/// The refined search grids of (h, p) over `centroids` in `box`, the first `built` radii sorted ahead.
AveragingGrids averagingGrids(const Hierarchy &h, const NormalParams &p, const std::vector<double> &centroids,
                              const double box[6], std::size_t built) {
  AveragingGrids g;
  g.radii = refinedSearchRadii(h, p);
  std::copy(box, box + 3, g.lo);
  std::copy(box + 3, box + 6, g.hi);
  g.by_radius.resize(g.radii.size());
  const PointSet points{centroids.data(), nullptr, centroids.size() / 3};
  for (std::size_t r = 0; r < std::min(built, g.radii.size()); ++r)
    g.by_radius[r] = g.make(r, points);  // as the pipeline sorts them ahead
  return g;
}

TEST(RefinedNormals, AveragingGridsSortedAheadDoNotChangeTheNormals) {
  // The pipeline sorts the averaging points for the first search radii while a frame is inserted, as many as are
  // ready when the insertion ends; the rest are sorted over the same box when needed. However many were ready, and
  // whatever the thread count, the normals and their neighbourhoods are the same bits.
  const std::vector<double> xyz = floorLinesAndWall(8);
  const Hierarchy h = build(xyz, 4, 3);
  const std::vector<SampleId> ids = h.samplesUpTo(3);
  NormalParams p = params(3, 10, 0.0);
  p.neighborhood_level_offset = 2;
  p.max_growth = 8.0;
  std::vector<std::uint32_t> all(xyz.size() / 3);
  std::iota(all.begin(), all.end(), 0u);
  double box[6];
  const std::vector<double> centroids = cellCentroids(xyz.data(), all.data(), all.size(), h.edge(3) / 4.0, box);
  auto gridsWith = [&](std::size_t built) { return averagingGrids(h, p, centroids, box, built); };
  std::vector<LocalPca> ref_pca(ids.size());
  const AveragingGrids none = gridsWith(0);
  ASSERT_GE(none.radii.size(), 3u);
  const std::vector<SampleNormal> ref = estimateNormalsRefined(h, ids, p, &centroids, &ref_pca, &none);
  std::size_t valid = 0;
  for (const SampleNormal &n : ref) valid += n.valid ? 1 : 0;
  EXPECT_GT(valid, ids.size() * 9 / 10);
  for (std::size_t built : {std::size_t(1), std::size_t(2), none.radii.size()})
    for (int threads : {1, 2}) {
      p.threads = threads;
      const AveragingGrids g = gridsWith(built);
      std::vector<LocalPca> pca(ids.size());
      const std::vector<SampleNormal> got = estimateNormalsRefined(h, ids, p, &centroids, &pca, &g);
      ASSERT_EQ(got.size(), ref.size());
      for (std::size_t i = 0; i < ref.size(); ++i) {
        ASSERT_EQ(got[i].valid, ref[i].valid) << "sample " << i << ", " << built << " built ahead";
        if (!ref[i].valid) continue;
        ASSERT_EQ(std::memcmp(got[i].normal, ref[i].normal, sizeof ref[i].normal), 0) << "sample " << i;
        ASSERT_EQ(got[i].curvature, ref[i].curvature);
        ASSERT_EQ(pca[i].l0, ref_pca[i].l0);
        ASSERT_EQ(pca[i].normal[2], ref_pca[i].normal[2]);
      }
    }
}

TEST(RefinedNormals, NeighbourhoodsEstimatedInPiecesWithoutTheHierarchyAreTheSameBits) {
  // The pipeline's second thread estimates the neighbourhoods of samples as the insertion accepts them, in pieces,
  // from the frame's points (no hierarchy yet), sorting the grids it needs into the shared AveragingGrids; the
  // normals then take those as known and estimate the rest. Whatever the split, the same bits as estimating all.
  std::vector<double> xyz = floorLinesAndWall(11);
  for (int i = 0; i < 4; ++i) xyz.insert(xyz.end(), {20.0 + 10.0 * i, 20.0, 1.0});  // alone: no normal
  const Hierarchy h = build(xyz, 4, 3);
  const std::vector<SampleId> ids = h.samplesUpTo(3);
  NormalParams p = params(3, 0, 2.5 * h.radius(3));
  p.neighborhood_level_offset = 2;
  p.max_growth = 8.0;
  std::vector<std::uint32_t> all(xyz.size() / 3);
  std::iota(all.begin(), all.end(), 0u);
  double box[6];
  const std::vector<double> centroids = cellCentroids(xyz.data(), all.data(), all.size(), h.edge(3) / 4.0, box);
  const AveragingGrids none = averagingGrids(h, p, centroids, box, 0);
  std::vector<LocalPca> ref_pca(ids.size());
  const std::vector<SampleNormal> ref = estimateNormalsRefined(h, ids, p, &centroids, &ref_pca, &none);
  std::size_t valid = 0;
  for (const SampleNormal &n : ref) valid += n.valid ? 1 : 0;
  ASSERT_GT(valid, ids.size() * 9 / 10);
  ASSERT_LT(valid, ids.size()) << "the scene should also hold samples without a normal";

  // The samples' positions as the pipeline has them: the frame's points, addressed by point index.
  std::vector<double> frame_xyz;
  std::vector<std::uint32_t> point_of(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    point_of[i] = static_cast<std::uint32_t>(frame_xyz.size() / 3);
    frame_xyz.insert(frame_xyz.end(), h.position(ids[i]), h.position(ids[i]) + 3);
  }
  // Pieces of 1, 7, 300 and the rest of the first two thirds, in a shuffled order; the last third left unknown.
  std::vector<std::uint32_t> order(ids.size());
  std::iota(order.begin(), order.end(), 0u);
  std::mt19937_64 rng(12);
  std::shuffle(order.begin(), order.end(), rng);
  const std::size_t known_count = ids.size() * 2 / 3;
  std::vector<std::uint32_t> piece_points(known_count);
  for (std::size_t t = 0; t < known_count; ++t) piece_points[t] = point_of[order[t]];
  AveragingGrids grids = averagingGrids(h, p, centroids, box, 1);
  std::vector<LocalPca> piece_pca(known_count);
  std::vector<std::uint8_t> piece_have(known_count, 7);
  std::size_t done = 0;
  for (std::size_t size : {std::size_t(1), std::size_t(7), std::size_t(300), known_count}) {
    const std::size_t count = std::min(size, known_count - done);
    refinedNeighbourhoodsOverCentroids(frame_xyz.data(), piece_points.data() + done, count, p, h.cellSize(),
                                       centroids, grids, piece_pca.data() + done, piece_have.data() + done);
    done += count;
  }
  ASSERT_EQ(done, known_count);
  std::size_t kept = 0;
  for (const auto &g : grids.by_radius) kept += g ? 1 : 0;
  EXPECT_GE(kept, 3u) << "footprints grew over several radii: their grids are kept for the next pieces";

  std::vector<std::uint8_t> state(ids.size(), KnownNeighbourhoods::kUnknown);
  std::vector<LocalPca> chosen(ids.size());
  std::size_t known_none = 0;
  for (std::size_t t = 0; t < known_count; ++t) {
    ASSERT_LE(piece_have[t], 1u);
    state[order[t]] = piece_have[t] ? KnownNeighbourhoods::kChosen : KnownNeighbourhoods::kNone;
    chosen[order[t]] = piece_pca[t];
    known_none += piece_have[t] ? 0 : 1;
  }
  EXPECT_GT(known_none, 0u);
  const KnownNeighbourhoods known{state.data(), chosen.data()};
  for (int threads : {1, 2}) {
    p.threads = threads;
    std::vector<LocalPca> pca(ids.size());
    const std::vector<SampleNormal> got = estimateNormalsRefined(h, ids, p, &centroids, &pca, &grids, &known);
    ASSERT_EQ(got.size(), ref.size());
    for (std::size_t i = 0; i < ref.size(); ++i) {
      ASSERT_EQ(got[i].valid, ref[i].valid) << "sample " << i << ", " << threads << " threads";
      if (!ref[i].valid) continue;
      ASSERT_EQ(std::memcmp(got[i].normal, ref[i].normal, sizeof ref[i].normal), 0) << "sample " << i;
      ASSERT_EQ(got[i].curvature, ref[i].curvature);
      ASSERT_EQ(std::memcmp(&pca[i], &ref_pca[i], sizeof(LocalPca::normal) + 3 * sizeof(double)), 0);
    }
  }
  // Known neighbourhoods need the centroids and a fixed footprint.
  EXPECT_THROW((void)estimateNormalsRefined(h, ids, p, nullptr, nullptr, nullptr, &known), std::invalid_argument);
  NormalParams knn = p;
  knn.k = 10;
  EXPECT_THROW((void)estimateNormalsRefined(h, ids, knn, &centroids, nullptr, &grids, &known), std::invalid_argument);
  EXPECT_THROW(refinedNeighbourhoodsOverCentroids(frame_xyz.data(), piece_points.data(), 1, knn, h.cellSize(),
                                                  centroids, grids, piece_pca.data(), piece_have.data()),
               std::invalid_argument);
}

TEST(RefinedNormals, ScanModeNormalsArePcaOfTheFramesCellCentroids) {
  // A noisy tilted plane and a wall, seen from the origin, in one scan-mode frame: with growth off, each output
  // sample's normal is the PCA of the frame's cell centroids (cells of level output + offset) within the radius.
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.0, 6.0);
  std::normal_distribution<double> noise(0.0, 0.01);
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  Frame frame;
  frame.points = PointBuffer(layout, 0);
  std::vector<double> xyz;  // as the pipeline reads them (float32)
  for (int i = 0; i < 30000; ++i) {
    const double x = u(rng) - 3.0, y = u(rng) - 3.0;
    const double p[3] = {i % 4 ? x : 3.5, i % 4 ? y : x, i % 4 ? -1.5 + 0.1 * x + noise(rng) : y + 1.0 + noise(rng)};
    float f[3];
    for (int a = 0; a < 3; ++a) f[a] = static_cast<float>(p[a]), xyz.push_back(f[a]);
    std::uint8_t rec[12];
    std::memcpy(rec, f, sizeof rec);
    frame.points.pushBack(rec);
  }
  HpdsConfig c;
  c.output.level = 4;
  c.normals.enabled = true;
  c.normals.neighborhood_level_offset = 2;
  c.normals.max_growth = 1.0;
  Pipeline pipeline(c);
  pipeline.addFrame(frame);
  const Hierarchy &h = pipeline.hierarchy();
  for (int l = 5; l <= h.maxDepth(); ++l) EXPECT_EQ(h.countAtLevel(l), 0u) << "no level is built for the normals";
  const std::vector<SampleId> ids = pipeline.outputSamples();
  const PointBuffer out = pipeline.makeCloud(ids, false);
  ASSERT_EQ(out.size(), ids.size());

  std::vector<std::uint32_t> all(xyz.size() / 3);
  std::iota(all.begin(), all.end(), 0u);
  std::vector<Eigen::Vector3d> centroids;
  for (const auto &[cell, sum] : bruteCentroids(xyz, all, cellEdge(pipeline.config().hierarchy.cell_size, 6)))
    centroids.emplace_back(sum[0] / sum[3], sum[1] / sum[3], sum[2] / sum[3]);
  const double radius = 2.5 * h.radius(4);
  const PointField *nf[3] = {out.layout().find("normal_x"), out.layout().find("normal_y"), out.layout().find("normal_z")};
  const PointField *cf = out.layout().find("curvature");
  std::size_t valid = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const Eigen::Vector3d q(h.position(ids[i])[0], h.position(ids[i])[1], h.position(ids[i])[2]);
    std::vector<Eigen::Vector3d> nb;
    for (const Eigen::Vector3d &p : centroids)
      if ((p - q).squaredNorm() < radius * radius) nb.push_back(p);
    const Eigen::Vector3d n(readAsDouble(out.record(i), *nf[0]), readAsDouble(out.record(i), *nf[1]),
                            readAsDouble(out.record(i), *nf[2]));
    if (static_cast<int>(nb.size()) < c.normals.min_neighbors) {
      EXPECT_TRUE(std::isnan(n.x())) << "too few centroids: the normal must be invalid";
      continue;
    }
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto &p : nb) mean += p;
    mean /= static_cast<double>(nb.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto &p : nb) cov += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov / static_cast<double>(nb.size()));
    ASSERT_TRUE(n.allFinite()) << "sample " << i << " has " << nb.size() << " centroids in reach";
    ++valid;
    const Eigen::Vector3d truth = es.eigenvectors().col(0);
    EXPECT_LT(std::acos(std::min(1.0, std::abs(n.normalized().dot(truth)))), 1e-4) << "sample " << i;
    EXPECT_NEAR(readAsDouble(out.record(i), *cf), es.eigenvalues()(0) / es.eigenvalues().sum(), 1e-5);
    EXPECT_GE(n.dot(-q), -1e-6 * q.norm()) << "oriented toward the sensor at the origin";
  }
  EXPECT_GT(valid, ids.size() * 9 / 10);
}

TEST(RefinedNormals, ScanModeCentroidsAverageRangeNoiseAsTheFinerLevelsDid) {
  // The noisy plane of FinerLevelsAverageRangeNoise as one scan-mode frame: the frame's centroids must beat the
  // plain estimator as the finer levels do.
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(0.0, 4.0);
  std::normal_distribution<double> noise(0.0, 0.01);
  PointLayout layout;
  layout.append("x", FieldType::Float64);
  layout.append("y", FieldType::Float64);
  layout.append("z", FieldType::Float64);
  Frame frame;
  frame.points = PointBuffer(layout, 0);
  for (int i = 0; i < 60000; ++i) {
    const double p[3] = {u(rng), u(rng), 5.0 + noise(rng)};  // the sensor below, at the origin: normals face -z
    frame.points.pushBack(reinterpret_cast<const std::uint8_t *>(p));
  }
  auto medianError = [&](int offset) {
    HpdsConfig c;
    c.hierarchy.cell_size = kCell;
    c.hierarchy.max_depth = 7;
    c.output.level = 4;
    c.normals.enabled = true;
    c.normals.k = 10;
    c.normals.min_neighbors = 3;
    c.normals.neighborhood_level_offset = offset;
    c.normals.max_growth = 1.0;
    Pipeline pipeline(c);
    pipeline.addFrame(frame);
    const PointBuffer out = pipeline.makeCloud(pipeline.outputSamples(), false);
    const PointField *nz = out.layout().find("normal_z");
    std::vector<double> e;
    for (std::size_t i = 0; i < out.size(); ++i) {
      const double z = readAsDouble(out.record(i), *nz);
      e.push_back(std::isnan(z) ? NAN : std::acos(std::min(1.0, -z)) * 57.29577951308232);
    }
    return median(e);
  };
  const double plain = medianError(0), centroids = medianError(2);
  EXPECT_LT(centroids, 0.6 * plain) << "plain " << plain << " deg, centroids " << centroids << " deg";
}

}  // namespace
}  // namespace hpds
