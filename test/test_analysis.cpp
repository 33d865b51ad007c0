// Sampling-quality analysis on cases with known answers: spectra of regular grids, RDFs against an O(n^2) oracle,
// Poisson-disk sets, plane patches, the grid baselines, and the PNG encoder (decoded by an independent inflater).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>
#include <stdexcept>
#include <vector>

#include "hpds/eval/BlueNoiseAnalysis.hpp"
#include "hpds/eval/GridSubsampling.hpp"
#include "hpds/eval/PointRender.hpp"
#include "hpds/eval/PngWriter.hpp"
#include "hpds/util/Crc32.hpp"

namespace hpds {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::vector<Eigen::Vector2d> regularGrid(int n, double size, double offset_x = 0.5, double offset_y = 0.5) {
  std::vector<Eigen::Vector2d> pts;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) pts.emplace_back((i + offset_x) * size / n, (j + offset_y) * size / n);
  return pts;
}

std::vector<Eigen::Vector2d> uniformRandom(std::size_t n, double size, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, size);
  std::vector<Eigen::Vector2d> pts(n);
  for (auto &p : pts) p = {u(rng), u(rng)};
  return pts;
}

/// Dart throwing on the unit torus: a Poisson-disk set of radius r.
std::vector<Eigen::Vector2d> dartThrowing(double r, int attempts, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector2d> pts;
  for (int a = 0; a < attempts; ++a) {
    const Eigen::Vector2d c(u(rng), u(rng));
    bool ok = true;
    for (const auto &p : pts) {
      double dx = p.x() - c.x(), dy = p.y() - c.y();
      dx -= std::round(dx), dy -= std::round(dy);
      if (dx * dx + dy * dy < r * r) {
        ok = false;
        break;
      }
    }
    if (ok) pts.push_back(c);
  }
  return pts;
}

/// The definition applied literally: every ordered pair, no buckets.
std::vector<double> bruteForceRdf(const std::vector<Eigen::Vector2d> &pts, double size, double r_max, int bins,
                                  bool periodic) {
  std::vector<double> hist(static_cast<std::size_t>(bins), 0.0);
  std::size_t refs = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const auto &p = pts[i];
    if (!periodic && (p.x() < r_max || p.y() < r_max || p.x() > size - r_max || p.y() > size - r_max)) continue;
    ++refs;
    for (std::size_t j = 0; j < pts.size(); ++j) {
      if (i == j) continue;
      double dx = pts[j].x() - p.x(), dy = pts[j].y() - p.y();
      if (periodic) dx -= size * std::round(dx / size), dy -= size * std::round(dy / size);
      const double d = std::sqrt(dx * dx + dy * dy);
      if (d * d >= r_max * r_max) continue;
      hist[static_cast<std::size_t>(std::min(bins - 1, static_cast<int>(d / (r_max / bins))))] += 1.0;
    }
  }
  const double rho = (static_cast<double>(pts.size()) - 1.0) / (size * size);
  std::vector<double> g(static_cast<std::size_t>(bins), 0.0);
  for (int b = 0; b < bins && refs > 0; ++b) {
    const double r0 = b * r_max / bins, r1 = (b + 1) * r_max / bins;
    g[static_cast<std::size_t>(b)] = hist[static_cast<std::size_t>(b)] / (refs * rho * kPi * (r1 * r1 - r0 * r0));
  }
  return g;
}

// ---------------------------------------------------------------------------------------------------- spectrum

TEST(PowerSpectrum, RegularGridHasPeaksOnlyAtMultiplesOfTheInverseSpacing) {
  const int n = 16;  // spacing 1/16 in the unit window -> peaks at integer frequencies that are multiples of 16
  for (double off : {0.5, 0.137}) {
    const auto pts = regularGrid(n, 1.0, off, off);
    const PowerSpectrum s = powerSpectrum(pts, SquareWindow{0.0, 0.0, 1.0}, 40, 2);
    ASSERT_EQ(s.points, static_cast<std::size_t>(n * n));
    const double N = n * n;
    for (int ky = -40; ky <= 40; ++ky)
      for (int kx = -40; kx <= 40; ++kx) {
        const bool peak = kx % n == 0 && ky % n == 0;
        if (peak)
          EXPECT_NEAR(s.at(kx, ky), N, 1e-6 * N) << kx << "," << ky;
        else
          EXPECT_LT(s.at(kx, ky), 1e-9 * N) << kx << "," << ky;
      }
    // Radial average: non-zero exactly in the annuli holding a peak (|k| = 16, 16 sqrt 2 ~ 22.6, 32, 35.8).
    const std::set<int> peak_bins = {16, 23, 32, 36};
    for (int b = 1; b <= 40; ++b) {
      if (peak_bins.count(b))
        EXPECT_GT(s.radial_power[static_cast<std::size_t>(b - 1)], 1.0) << b;
      else
        EXPECT_LT(s.radial_power[static_cast<std::size_t>(b - 1)], 1e-9 * N) << b;
      EXPECT_DOUBLE_EQ(s.radial_frequency[static_cast<std::size_t>(b - 1)], b);
    }
  }
}

TEST(PowerSpectrum, WindowOffsetAndScaleOnlyChangeUnits) {
  // The same grid scaled by 2.5 and shifted: same periodogram at k, frequency step 1/2.5.
  auto pts = regularGrid(8, 2.5);
  for (auto &p : pts) p += Eigen::Vector2d(-7.0, 3.0);
  const PowerSpectrum s = powerSpectrum(pts, SquareWindow{-7.0, 3.0, 2.5}, 20);
  EXPECT_DOUBLE_EQ(s.frequency_step, 0.4);
  EXPECT_NEAR(s.at(8, 0), 64.0, 1e-6);
  EXPECT_NEAR(s.at(0, 0), 64.0, 1e-9);
  EXPECT_LT(s.at(3, 5), 1e-8);
}

TEST(PowerSpectrum, UniformRandomPointsAreWhite) {
  const auto pts = uniformRandom(4000, 1.0, 7);
  const PowerSpectrum s = powerSpectrum(pts, SquareWindow{0.0, 0.0, 1.0}, 48);
  double mean = 0.0;
  for (double p : s.radial_power) mean += p;
  mean /= static_cast<double>(s.radial_power.size());
  EXPECT_NEAR(mean, 1.0, 0.08);  // E[P(k)] = 1 for k != 0
}

TEST(PowerSpectrum, PoissonDiskSetHasLowEnergyAtLowFrequencies) {
  const double r = 0.03;
  const auto pts = dartThrowing(r, 20000, 3);
  const PowerSpectrum s = powerSpectrum(pts, SquareWindow{0.0, 0.0, 1.0}, 60);
  // Blue noise: well below 1 at frequencies much lower than 1/r (~33), about 1 beyond.
  double low = 0.0, high = 0.0;
  for (int b = 1; b <= 10; ++b) low += s.radial_power[static_cast<std::size_t>(b - 1)] / 10.0;
  for (int b = 45; b <= 60; ++b) high += s.radial_power[static_cast<std::size_t>(b - 1)] / 16.0;
  EXPECT_LT(low, 0.3);
  EXPECT_NEAR(high, 1.0, 0.3);
}

TEST(PowerSpectrum, PointsOutsideTheWindowAreIgnoredAndBadInputThrows) {
  std::vector<Eigen::Vector2d> pts = {{0.5, 0.5}, {1.5, 0.5}, {-0.1, 0.2}};
  const PowerSpectrum s = powerSpectrum(pts, SquareWindow{0.0, 0.0, 1.0}, 2);
  EXPECT_EQ(s.points, 1u);
  EXPECT_NEAR(s.at(1, 1), 1.0, 1e-12);
  EXPECT_THROW((void)powerSpectrum(pts, SquareWindow{0.0, 0.0, 1.0}, 0), std::invalid_argument);
  EXPECT_THROW((void)powerSpectrum(pts, SquareWindow{0.0, 0.0, 0.0}, 2), std::invalid_argument);
  const PowerSpectrum empty = powerSpectrum({}, SquareWindow{0.0, 0.0, 1.0}, 3);
  EXPECT_EQ(empty.points, 0u);
  EXPECT_EQ(empty.radial_power.size(), 3u);
}

// ---------------------------------------------------------------------------------------------------------- RDF

TEST(RadialDistribution, RegularGridMatchesBruteForce) {
  const auto pts = regularGrid(20, 1.0);
  for (bool periodic : {true, false}) {
    // 38 bins put the shells (0.05, 0.0707, 0.1, ...) inside bins rather than on their edges.
    const RadialDistribution g = radialDistribution(pts, SquareWindow{0.0, 0.0, 1.0}, 0.2, 38, periodic);
    const auto ref = bruteForceRdf(pts, 1.0, 0.2, 38, periodic);
    ASSERT_EQ(g.g.size(), ref.size());
    for (std::size_t b = 0; b < ref.size(); ++b) EXPECT_NEAR(g.g[b], ref[b], 1e-9 * (1.0 + ref[b])) << b;
    // Nothing below the spacing 0.05; the first shell (4 neighbours at 0.05) lands in bin 9.
    for (std::size_t b = 0; b < 9; ++b) EXPECT_EQ(g.g[b], 0.0) << b;
    EXPECT_GT(g.g[9], 1.0);
    EXPECT_NEAR(g.density, 400.0, 1e-9);
    EXPECT_EQ(g.reference_points, periodic ? 400u : 144u);  // minus sampling keeps the 12 x 12 inner points
  }
}

TEST(RadialDistribution, RandomSetsMatchBruteForceAndAreFlat) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const auto pts = uniformRandom(1500, 2.0, seed);
    for (bool periodic : {true, false}) {
      const RadialDistribution g = radialDistribution(pts, SquareWindow{0.0, 0.0, 2.0}, 0.3, 30, periodic);
      const auto ref = bruteForceRdf(pts, 2.0, 0.3, 30, periodic);
      for (std::size_t b = 0; b < ref.size(); ++b) EXPECT_NEAR(g.g[b], ref[b], 1e-9 * (1.0 + ref[b]));
      double mean = 0.0;
      for (std::size_t b = 5; b < 30; ++b) mean += g.g[b] / 25.0;
      EXPECT_NEAR(mean, 1.0, 0.1) << "seed " << seed << (periodic ? " periodic" : "");
    }
  }
}

TEST(RadialDistribution, SmallWindowsWrapWithoutCountingPairsTwice) {
  // r_max = size / 2 gives 2 buckets per axis; 1 bucket when r_max is barely below.
  const auto pts = uniformRandom(300, 1.0, 11);
  for (double r_max : {0.5, 0.45}) {
    const RadialDistribution g = radialDistribution(pts, SquareWindow{0.0, 0.0, 1.0}, r_max, 25, true);
    const auto ref = bruteForceRdf(pts, 1.0, r_max, 25, true);
    for (std::size_t b = 0; b < ref.size(); ++b) EXPECT_NEAR(g.g[b], ref[b], 1e-9 * (1.0 + ref[b]));
  }
}

TEST(RadialDistribution, PoissonDiskSetIsEmptyBelowItsRadius) {
  const double r = 0.04;
  const auto pts = dartThrowing(r, 8000, 5);
  const RadialDistribution g = radialDistribution(pts, SquareWindow{0.0, 0.0, 1.0}, 4 * r, 40, true);
  for (std::size_t b = 0; b < g.g.size(); ++b) {
    if (g.r[b] + 0.5 * (4 * r / 40) <= r) {
      EXPECT_EQ(g.g[b], 0.0) << "bin at " << g.r[b];
    }
  }
  // Beyond a few radii the correlation fades.
  double far = 0.0;
  for (std::size_t b = 30; b < 40; ++b) far += g.g[b] / 10.0;
  EXPECT_NEAR(far, 1.0, 0.15);
}

TEST(RadialDistribution, RejectsRadiiTheWindowCannotHold) {
  const auto pts = uniformRandom(10, 1.0, 1);
  EXPECT_THROW((void)radialDistribution(pts, SquareWindow{0, 0, 1}, 0.5, 10, false), std::invalid_argument);
  EXPECT_THROW((void)radialDistribution(pts, SquareWindow{0, 0, 1}, 0.6, 10, true), std::invalid_argument);
  EXPECT_THROW((void)radialDistribution(pts, SquareWindow{0, 0, 1}, 0.1, 0, true), std::invalid_argument);
  EXPECT_THROW((void)radialDistribution(pts, SquareWindow{0, 0, 1}, 0.0, 5, true), std::invalid_argument);
}

// ------------------------------------------------------------------------------------- 3D helpers and patches

TEST(NearestNeighbor, MatchesBruteForceIncludingDuplicates) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  std::vector<Eigen::Vector3d> pts(500);
  for (auto &p : pts) p = {u(rng), u(rng), u(rng)};
  pts.push_back(pts[17]);
  const auto nn = nearestNeighborDistances(pts);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    double best = INFINITY;
    for (std::size_t j = 0; j < pts.size(); ++j)
      if (j != i) best = std::min(best, (pts[i] - pts[j]).norm());
    EXPECT_NEAR(nn[i], best, 1e-12);
  }
  EXPECT_EQ(nn[17], 0.0);
  EXPECT_TRUE(std::isinf(nearestNeighborDistances({Eigen::Vector3d::Zero()})[0]));
}

TEST(PlaneFit, RecoversATiltedPlaneAndProjectionKeepsDistances) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, 1.0).normalized();
  const Eigen::Vector3d a = n.unitOrthogonal(), b = n.cross(a);
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 400; ++i) pts.push_back(Eigen::Vector3d(1, 2, 3) + u(rng) * a + u(rng) * b);
  const PlaneFit fit = fitPlane(pts);
  ASSERT_TRUE(fit.valid);
  EXPECT_NEAR(std::abs(fit.normal.dot(n)), 1.0, 1e-12);
  EXPECT_GT(fit.normal.z(), 0.0);
  EXPECT_LT(fit.rms, 1e-12);
  EXPECT_NEAR(fit.u.cross(fit.v).dot(fit.normal), 1.0, 1e-12);
  const auto uv = projectToPlane(pts, fit, 1e-6);
  ASSERT_EQ(uv.size(), pts.size());
  for (std::size_t i = 1; i < pts.size(); ++i)
    EXPECT_NEAR((uv[i] - uv[0]).norm(), (pts[i] - pts[0]).norm(), 1e-9);
  EXPECT_FALSE(fitPlane({{0, 0, 0}, {1, 1, 1}, {2, 2, 2}}).valid);
}

TEST(PlanarPatch, FindsTheGroundUnderObjects) {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  // Dense ground around x in [0, 10), sparse elsewhere, and a dense wall standing on the dense part.
  for (int i = 0; i < 20000; ++i) pts.emplace_back(10 * u(rng), 10 * u(rng), 0.005 * (u(rng) - 0.5));
  for (int i = 0; i < 3000; ++i) pts.emplace_back(10 + 30 * u(rng), 10 * u(rng), 0.0);
  for (int i = 0; i < 6000; ++i) pts.emplace_back(5.0 + 0.01 * u(rng), 10 * u(rng), 3 * u(rng));
  const PlanarPatch patch = findPlanarPatch(pts, 4.0, 0.05);
  ASSERT_TRUE(patch.found);
  EXPECT_LE(patch.center.x(), 10.0);
  EXPECT_NEAR(patch.plane.normal.z(), 1.0, 1e-3);
  EXPECT_NEAR(patch.plane.centroid.z(), 0.0, 0.01);
  EXPECT_FALSE(findPlanarPatch({}, 4.0, 0.05).found);
}

// A square holding more points only because a wall stands on it must lose to a square with more ground: counting
// all points made the choice between near-tied squares depend on the sampling (and so on its seed).
TEST(PlanarPatch, MostPointsOnThePlaneWinNotMostPoints) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 1000; ++i) pts.emplace_back(4 * u(rng), 4 * u(rng), 0.002 * (u(rng) - 0.5));  // clean ground
  for (int i = 0; i < 950; ++i) pts.emplace_back(20 + 4 * u(rng), 4 * u(rng), 0.002 * (u(rng) - 0.5));
  for (int i = 0; i < 150; ++i) pts.emplace_back(22.0 + 0.01 * u(rng), 4 * u(rng), 0.5 + 2 * u(rng));  // a wall
  const PlanarPatch patch = findPlanarPatch(pts, 4.0, 0.05);
  ASSERT_TRUE(patch.found);
  EXPECT_NEAR(patch.center.x(), 2.0, 1e-9);
  EXPECT_NEAR(patch.center.y(), 2.0, 1e-9);
  EXPECT_EQ(patch.inliers, 1000u);
}

// A long drive's map: its most populated squares are walls (every ring hits them), more than the 64 tried first.
// The ground further down the list is still found; and where one of the first 64 qualifies, the rest are not read.
TEST(PlanarPatch, GroundBeyondTheSixtyFourMostPopulatedSquaresIsFound) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  for (int w = 0; w < 80; ++w)  // 80 walls, 8 m apart along x, 4 m high: 2 000 points each
    for (int i = 0; i < 2000; ++i) pts.emplace_back(8.0 * w + 0.01 * u(rng), 200.0 + 4 * u(rng), 4 * u(rng));
  for (int i = 0; i < 1200; ++i) pts.emplace_back(-40 + 4 * u(rng), 4 * u(rng), 0.3 + 0.002 * (u(rng) - 0.5));
  const PlanarPatch patch = findPlanarPatch(pts, 4.0, 0.05);
  ASSERT_TRUE(patch.found);
  EXPECT_NEAR(patch.center.x(), -38.0, 1e-9);
  EXPECT_NEAR(patch.center.y(), 2.0, 1e-9);
  EXPECT_NEAR(patch.plane.centroid.z(), 0.3, 0.01);
  EXPECT_EQ(patch.inliers, 1200u);
}

// ------------------------------------------------------------------------------------------------ baselines

TEST(GridSubsampling, OnePointPerOccupiedCell) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Vector3d> pts(3000);
  for (auto &p : pts) p = {u(rng), u(rng), 0.1 * u(rng)};
  pts.push_back({NAN, 0, 0});
  const double cell = 0.25;
  auto key = [&](const Eigen::Vector3d &p) {
    return std::make_tuple(std::floor(p.x() / cell), std::floor(p.y() / cell), std::floor(p.z() / cell));
  };
  std::map<std::tuple<double, double, double>, std::vector<std::uint32_t>> cells;
  for (std::uint32_t i = 0; i + 1 < pts.size(); ++i) cells[key(pts[i])].push_back(i);

  const auto rnd = gridRandom(pts, cell, 1);
  const auto rnd2 = gridRandom(pts, cell, 2);
  const auto ctr = gridClosestToCenter(pts, cell);
  const auto cen = voxelCentroids(pts, cell);
  EXPECT_EQ(rnd.size(), cells.size());
  EXPECT_EQ(ctr.size(), cells.size());
  EXPECT_EQ(cen.size(), cells.size());
  EXPECT_NE(rnd, rnd2);  // another seed draws other points
  EXPECT_TRUE(std::is_sorted(rnd.begin(), rnd.end()));
  std::set<std::tuple<double, double, double>> seen;
  for (std::uint32_t i : ctr) {
    const auto k = key(pts[i]);
    EXPECT_TRUE(seen.insert(k).second);
    const Eigen::Vector3d c((std::get<0>(k) + 0.5) * cell, (std::get<1>(k) + 0.5) * cell, (std::get<2>(k) + 0.5) * cell);
    for (std::uint32_t j : cells[k]) EXPECT_LE((pts[i] - c).norm(), (pts[j] - c).norm());
  }
  for (const auto &c : cen) {
    const auto &members = cells[key(c)];
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (std::uint32_t j : members) m += pts[j];
    EXPECT_LT((m / members.size() - c).norm(), 1e-12);
  }
  EXPECT_THROW((void)gridRandom(pts, 0.0, 1), std::invalid_argument);
}

TEST(GridSubsampling, OriginShiftsTheCells) {
  // Points at z = +-0.01 straddle the boundary z = 0 of an origin-anchored grid: two cells per column. Half a cell of
  // offset puts them in one.
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 10; ++i) pts.push_back({0.52 + 0.05 * i, 0.6, i % 2 ? 0.01 : -0.01});
  EXPECT_EQ(gridClosestToCenter(pts, 1.0).size(), 2u);
  const Eigen::Vector3d half(0.5, 0.5, 0.5);
  EXPECT_EQ(gridClosestToCenter(pts, 1.0, half).size(), 1u);
  EXPECT_EQ(voxelCentroids(pts, 1.0, half).size(), 1u);
  EXPECT_EQ(gridRandom(pts, 1.0, 3, half).size(), 1u);
  // All share the shifted cell centred at (1, 1, 0); the closest to it is the one at the largest x.
  EXPECT_EQ(gridClosestToCenter(pts, 1.0, half)[0], 9u);
}

TEST(GridSubsampling, GridRandomIsUniformWithinACell) {
  // Four points in one cell: over many seeds each is drawn about a quarter of the time.
  const std::vector<Eigen::Vector3d> pts = {{0.1, 0.1, 0.1}, {0.2, 0.1, 0.1}, {0.3, 0.1, 0.1}, {0.4, 0.1, 0.1}};
  std::vector<int> hits(4, 0);
  for (std::uint64_t s = 0; s < 4000; ++s) ++hits[gridRandom(pts, 1.0, s)[0]];
  for (int h : hits) EXPECT_NEAR(h, 1000, 120);
}

TEST(GridSubsampling, CellForCountHitsTheTarget) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  std::vector<Eigen::Vector3d> pts(20000);
  for (auto &p : pts) p = {u(rng), u(rng), 0.0};
  const std::size_t target = 2500;
  const double cell = cellForCount([&](double c) { return voxelCentroids(pts, c).size(); }, target, 0.01, 10.0);
  const double got = static_cast<double>(voxelCentroids(pts, cell).size());
  EXPECT_NEAR(got, static_cast<double>(target), 0.02 * target);
}

// ------------------------------------------------------------------------------------------------------- PNG

/// Minimal inflater for what the encoder emits (fixed-Huffman and stored blocks); throws on anything else.
class Inflater {
 public:
  explicit Inflater(const std::vector<std::uint8_t> &z) : in_(z) {}
  std::vector<std::uint8_t> run() {
    if (in_.size() < 6 || (in_[0] & 0x0F) != 8 || ((in_[0] << 8) | in_[1]) % 31 != 0) throw std::runtime_error("hdr");
    pos_ = 2;
    std::vector<std::uint8_t> out;
    for (bool last = false; !last;) {
      last = bit();
      const int type = static_cast<int>(bits(2));
      if (type == 0) {
        bitpos_ = 0, ++pos_;
        const unsigned len = in_[pos_] | (in_[pos_ + 1] << 8);
        pos_ += 4;
        out.insert(out.end(), in_.begin() + static_cast<long>(pos_), in_.begin() + static_cast<long>(pos_ + len));
        pos_ += len;
        continue;
      }
      if (type != 1) throw std::runtime_error("only fixed Huffman expected");
      for (;;) {
        const int sym = literal();
        if (sym < 256) {
          out.push_back(static_cast<std::uint8_t>(sym));
        } else if (sym == 256) {
          break;
        } else {
          static const int lb[] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
          static const int le[] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
          static const int db[] = {1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
          static const int de[] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
          const int li = sym - 257;
          const int len = lb[li] + static_cast<int>(bits(le[li]));
          int dcode = 0;
          for (int i = 0; i < 5; ++i) dcode = (dcode << 1) | bit();
          const int dist = db[dcode] + static_cast<int>(bits(de[dcode]));
          if (dist > static_cast<int>(out.size())) throw std::runtime_error("distance beyond output");
          for (int i = 0; i < len; ++i) out.push_back(out[out.size() - static_cast<std::size_t>(dist)]);
        }
      }
    }
    if (bitpos_) bitpos_ = 0, ++pos_;
    std::uint32_t adler = 0;
    for (int i = 0; i < 4; ++i) adler = (adler << 8) | in_.at(pos_ + static_cast<std::size_t>(i));
    if (adler != adler32(out.data(), out.size())) throw std::runtime_error("adler mismatch");
    return out;
  }

 private:
  int bit() {
    const int b = (in_.at(pos_) >> bitpos_) & 1;
    if (++bitpos_ == 8) bitpos_ = 0, ++pos_;
    return b;
  }
  unsigned bits(int n) {
    unsigned v = 0;
    for (int i = 0; i < n; ++i) v |= static_cast<unsigned>(bit()) << i;
    return v;
  }
  int literal() {
    int c = 0;
    for (int i = 0; i < 7; ++i) c = (c << 1) | bit();
    if (c <= 0x17) return 256 + c;
    c = (c << 1) | bit();
    if (c >= 0x30 && c <= 0xBF) return c - 0x30;
    if (c >= 0xC0 && c <= 0xC7) return 280 + (c - 0xC0);
    c = (c << 1) | bit();
    return 144 + (c - 0x190);
  }
  const std::vector<std::uint8_t> &in_;
  std::size_t pos_ = 0;
  int bitpos_ = 0;
};

TEST(Png, ChecksumsMatchPublishedValues) {
  const char *s = "123456789";
  EXPECT_EQ(crc32(reinterpret_cast<const std::uint8_t *>(s), 9), 0xCBF43926u);
  const char *w = "Wikipedia";
  EXPECT_EQ(adler32(reinterpret_cast<const std::uint8_t *>(w), 9), 0x11E60398u);
}

TEST(Png, DeflateRoundTripsVariedData) {
  std::mt19937_64 rng(1);
  std::vector<std::vector<std::uint8_t>> cases;
  cases.push_back({});
  cases.push_back({42});
  cases.push_back(std::vector<std::uint8_t>(100000, 0));  // long runs: overlapping matches
  std::vector<std::uint8_t> noise(70000);
  for (auto &b : noise) b = static_cast<std::uint8_t>(rng());
  cases.push_back(noise);
  std::vector<std::uint8_t> text;
  for (int i = 0; i < 5000; ++i)
    for (char c : std::string("level ") + std::to_string(i % 37) + " ") text.push_back(static_cast<std::uint8_t>(c));
  cases.push_back(text);
  for (const auto &data : cases) {
    const auto z = zlibCompress(data);
    EXPECT_EQ(Inflater(z).run(), data) << "size " << data.size();
  }
  EXPECT_LT(zlibCompress(cases[2]).size(), 1500u);
}

TEST(Png, EncodesAnImageThatDecodesBack) {
  RgbImage img(37, 23, 250, 250, 250);
  for (int y = 0; y < 23; ++y)
    for (int x = 0; x < 37; ++x)
      if ((x * y) % 7 == 0) img.set(x, y, static_cast<std::uint8_t>(x * 6), static_cast<std::uint8_t>(y * 11), 99);
  const auto png = encodePng(img);
  ASSERT_GT(png.size(), 8u + 25u + 12u);
  EXPECT_EQ(std::memcmp(png.data(), "\x89PNG\r\n\x1a\n", 8), 0);
  // Walk the chunks, check CRCs, collect IDAT, undo the filters.
  std::size_t p = 8;
  std::vector<std::uint8_t> idat;
  int w = 0, h = 0;
  while (p + 12 <= png.size()) {
    const std::uint32_t len = (png[p] << 24) | (png[p + 1] << 16) | (png[p + 2] << 8) | png[p + 3];
    const std::string type(png.begin() + static_cast<long>(p + 4), png.begin() + static_cast<long>(p + 8));
    const std::uint32_t crc = (png[p + 8 + len] << 24) | (png[p + 9 + len] << 16) | (png[p + 10 + len] << 8) | png[p + 11 + len];
    EXPECT_EQ(crc, crc32(png.data() + p + 4, len + 4)) << type;
    if (type == "IHDR") {
      w = (png[p + 8] << 24) | (png[p + 9] << 16) | (png[p + 10] << 8) | png[p + 11];
      h = (png[p + 12] << 24) | (png[p + 13] << 16) | (png[p + 14] << 8) | png[p + 15];
      EXPECT_EQ(png[p + 16], 8);
      EXPECT_EQ(png[p + 17], 2);
    }
    if (type == "IDAT") idat.insert(idat.end(), png.begin() + static_cast<long>(p + 8), png.begin() + static_cast<long>(p + 8 + len));
    p += 12 + len;
    if (type == "IEND") break;
  }
  EXPECT_EQ(p, png.size());
  ASSERT_EQ(w, 37);
  ASSERT_EQ(h, 23);
  const auto raw = Inflater(idat).run();
  const std::size_t stride = 3 * 37;
  ASSERT_EQ(raw.size(), (stride + 1) * 23);
  std::vector<std::uint8_t> pix(stride * 23);
  for (int y = 0; y < h; ++y) {
    const int f = raw[static_cast<std::size_t>(y) * (stride + 1)];
    for (std::size_t x = 0; x < stride; ++x) {
      const int a = x >= 3 ? pix[y * stride + x - 3] : 0, b = y > 0 ? pix[(y - 1) * stride + x] : 0;
      const int c = (x >= 3 && y > 0) ? pix[(y - 1) * stride + x - 3] : 0;
      int pred = 0;
      if (f == 1) pred = a;
      if (f == 2) pred = b;
      if (f == 3) pred = (a + b) / 2;
      if (f == 4) {
        const int pp = a + b - c, pa = std::abs(pp - a), pb = std::abs(pp - b), pc = std::abs(pp - c);
        pred = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
      }
      pix[y * stride + x] = static_cast<std::uint8_t>(raw[static_cast<std::size_t>(y) * (stride + 1) + 1 + x] + pred);
    }
  }
  EXPECT_EQ(pix, img.rgb);
}

// ---------------------------------------------------------------------------------------------------- render

TEST(PointRender, NearestPointWinsAndViewsMapAxes) {
  // Two points at the same xy: the higher one is seen from the top; from the side both are visible.
  const std::vector<Eigen::Vector3d> pts = {{0, 0, 0}, {0, 0, 1}, {2, 1, 0}};
  const std::vector<Rgb> col = {Rgb{255, 0, 0}, Rgb{0, 0, 255}, Rgb{0, 255, 0}};
  RenderOptions o;
  o.max_width = 221;
  o.max_height = 121;
  o.margin_px = 10;
  const RgbImage top = renderPoints(pts, col, o);
  EXPECT_EQ(top.width, 221);  // extent 2 x 1 m over 200 x 100 pixel steps -> 100 px per metre
  EXPECT_EQ(top.height, 121);
  const std::uint8_t *origin = top.at(10, 110);  // x = 0 at the left margin, y = 0 at the bottom margin
  EXPECT_EQ(origin[2], 255);
  EXPECT_EQ(origin[0], 0);
  EXPECT_EQ(top.at(210, 10)[1], 255);  // (2, 1) at the top right
  o.view = ViewDirection::Front;
  const RgbImage front = renderPoints(pts, col, o);
  int red = 0, blue = 0;
  for (int y = 0; y < front.height; ++y)
    for (int x = 0; x < front.width; ++x) {
      red += front.at(x, y)[0] == 255 && front.at(x, y)[1] == 0;
      blue += front.at(x, y)[2] == 255 && front.at(x, y)[0] == 0;
    }
  EXPECT_GT(red, 0);
  EXPECT_GT(blue, 0);
  EXPECT_THROW((void)renderPoints(pts, {}, o), std::invalid_argument);
  // A priority overrides depth: the lower point (red) now covers the higher one from the top.
  o.view = ViewDirection::Top;
  const std::vector<double> prio = {2.0, 1.0, 0.0};
  EXPECT_EQ(renderPoints(pts, col, o, &prio).at(10, 110)[0], 255);
}

TEST(PointRender, ColourMaps) {
  EXPECT_EQ(normalColor(Eigen::Vector3d::UnitZ()), (Rgb{128, 128, 255}));
  EXPECT_EQ(normalColor(Eigen::Vector3d(-1, 0, 0)), (Rgb{0, 128, 128}));
  EXPECT_NE(levelColor(0), levelColor(1));
  EXPECT_EQ(levelColor(3), levelColor(15));
  // Lightness grows with the value.
  double prev = -1.0;
  for (int i = 0; i <= 10; ++i) {
    const Rgb c = scalarColor(i / 10.0);
    const double light = 0.3 * c[0] + 0.59 * c[1] + 0.11 * c[2];
    EXPECT_GT(light, prev);
    prev = light;
  }
}

}  // namespace
}  // namespace hpds
