// The pieces behind the fast normal estimator: BallGrid (all fixed-radius neighbourhoods at once) against brute
// force, PcaAccumulator::solveNormal against Eigen's iterative solver, and estimateNormals with query sets that are
// not the candidate set (subsets, duplicates, unsorted ids, finer-level samples).
#include <gtest/gtest.h>

#include <iomanip>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <vector>

#include "HierarchyTestSupport.hpp"
#include "sampling/BallGrid.hpp"
#include "hpds/sampling/FrameGridIndex.hpp"
#include "hpds/sampling/Hierarchy.hpp"
#include "hpds/normals/LocalPca.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/util/ParallelFor.hpp"

namespace hpds {
namespace {

struct Found {
  std::vector<std::uint32_t> points;  // point indices, visiting order
  std::vector<double> d2;
  int calls = 0;
};

/// Every query's neighbourhood through `grid` (over `points`, for `queries`), visiting the query cells in `chunks`
/// ranges.
std::vector<Found> visitAll(const BallGrid &grid, const PointSet &points, const PointSet &queries, std::size_t chunks) {
  std::vector<Found> out(queries.size);
  const std::size_t n = grid.cellCount(), step = std::max<std::size_t>(1, (n + chunks - 1) / chunks);
  for (std::size_t b = 0; b < n; b += step)
    grid.visit(b, std::min(n, b + step), [&](std::size_t i, const BallView &v) {
      Found &f = out[i];
      ++f.calls;
      for (int a = 0; a < 3; ++a) EXPECT_EQ(v.q[a], queries.at(i)[a]);
      for (std::size_t t = 0; t < v.count; ++t) {
        const std::uint32_t slot = v.inside[t];
        f.points.push_back(v.point[slot]);
        f.d2.push_back(v.d2[t]);
        for (int a = 0; a < 3; ++a) EXPECT_EQ(v.xyz[3 * std::size_t(slot) + a], points.at(v.point[slot])[a]);
      }
    });
  return out;
}

/// Every query's neighbourhood through a BallGrid of its own.
std::vector<Found> viaGrid(const PointSet &points, const PointSet &queries, double radius, std::size_t chunks) {
  return visitAll(BallGrid(points, queries, radius), points, queries, chunks);
}

/// `clusters` clusters of `per_cluster` points: centres uniform in [lo, hi) on x and y and z_scale times that on z,
/// points normally scattered by sigma around them; then copies of the first `duplicates` points.
std::vector<double> clusteredPoints(std::mt19937_64 &rng, int clusters, int per_cluster, double lo, double hi,
                                    double sigma, double z_scale, int duplicates) {
  std::uniform_real_distribution<double> u(lo, hi);
  std::normal_distribution<double> g(0.0, sigma);
  std::vector<double> xyz;
  for (int c = 0; c < clusters; ++c) {
    const double cx = u(rng), cy = u(rng), cz = z_scale * u(rng);
    for (int k = 0; k < per_cluster; ++k) xyz.insert(xyz.end(), {cx + g(rng), cy + g(rng), cz + g(rng)});
  }
  for (int i = 0; i < duplicates; ++i) xyz.insert(xyz.end(), {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
  return xyz;
}

std::vector<std::uint32_t> bruteForce(const PointSet &points, const double *q, double radius) {
  std::vector<std::uint32_t> out;
  for (std::size_t j = 0; j < points.size; ++j) {
    const double *p = points.at(j);
    const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
    if (ax * ax + ay * ay + az * az < radius * radius) out.push_back(static_cast<std::uint32_t>(j));
  }
  return out;
}

TEST(BallGrid, MatchesBruteForceForPointsAndForeignQueries) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::normal_distribution<double> g(0.0, 0.05);
  std::vector<double> xyz;
  // A plane with noise, a dense blob, duplicates, and points exactly on cell-sized offsets (ties with the radius).
  for (int i = 0; i < 3000; ++i) xyz.insert(xyz.end(), {1000.0 + u(rng), -2000.0 + u(rng), 50.0 + g(rng)});
  for (int i = 0; i < 1000; ++i) xyz.insert(xyz.end(), {1001.0 + g(rng), -2001.0 + g(rng), 51.0 + g(rng)});
  for (int i = 0; i < 50; ++i) xyz.insert(xyz.end(), {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
  const double radius = 0.25;
  for (int i = 0; i < 20; ++i) xyz.insert(xyz.end(), {1000.0 + i * radius, -2000.0, 50.0});
  const std::size_t n = xyz.size() / 3;
  const PointSet all{xyz.data(), nullptr, n};

  // Queries = points (one sort serves both).
  for (std::size_t chunks : {1, 7}) {
    const auto found = viaGrid(all, all, radius, chunks);
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(found[i].calls, 1);
      std::vector<std::uint32_t> got = found[i].points;
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, bruteForce(all, all.at(i), radius)) << "query " << i;
    }
  }

  // A subset of the points as an index list, against foreign queries (some far from every point, some repeated).
  std::vector<std::uint32_t> subset;
  for (std::uint32_t i = 0; i < n; i += 3) subset.push_back(i);
  const PointSet some{xyz.data(), subset.data(), subset.size()};
  std::vector<double> qxyz;
  for (int i = 0; i < 500; ++i) qxyz.insert(qxyz.end(), {1000.0 + u(rng), -2000.0 + u(rng), 50.0 + 2.0 * g(rng)});
  qxyz.insert(qxyz.end(), {1100.0, -2000.0, 50.0});  // alone
  qxyz.insert(qxyz.end(), {qxyz[0], qxyz[1], qxyz[2]});
  const PointSet queries{qxyz.data(), nullptr, qxyz.size() / 3};
  const auto once = viaGrid(some, queries, radius, 1), split = viaGrid(some, queries, radius, 5);
  for (std::size_t i = 0; i < queries.size; ++i) {
    ASSERT_EQ(once[i].calls, 1);
    // Same visiting order whatever the chunks: results built from it do not depend on the thread count.
    ASSERT_EQ(once[i].points, split[i].points);
    std::vector<std::uint32_t> got = once[i].points;
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, bruteForce(some, queries.at(i), radius)) << "query " << i;
    for (std::size_t t = 0; t < once[i].points.size(); ++t) {
      const double *p = some.at(once[i].points[t]), *q = queries.at(i);
      const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
      EXPECT_EQ(once[i].d2[t], ax * ax + ay * ay + az * az);
    }
  }
  EXPECT_TRUE(once[queries.size - 2].points.empty());
  EXPECT_EQ(once[0].points, once[queries.size - 1].points);
}

TEST(BallGrid, KeysWiderThan32BitsVisitAsPackedKeysDo) {
  // Clusters in a 30 m box at a 5 cm radius: 27-bit cell keys, sorted packed with the point index. The same points
  // followed by three far beyond the box's upper corner: 48-bit keys, sorted as (key, index) pairs. The lower
  // corner, hence every cell, stays the same, so each original point must see the same neighbours in the same order
  // (cells by x, y, z; a cell's points by index), and they must be brute force's.
  std::mt19937_64 rng(5);
  const std::vector<double> xyz = clusteredPoints(rng, 400, 8, 0.0, 30.0, 0.03, 0.1, 20);
  const std::size_t n = xyz.size() / 3;
  std::vector<double> wide = xyz;
  for (int i = 1; i <= 3; ++i) wide.insert(wide.end(), {40.0 + 3000.0 * i, 40.0 + 3000.0 * i, 10.0 + 50.0 * i});
  const double radius = 0.05;
  const PointSet packed_set{xyz.data(), nullptr, n}, wide_set{wide.data(), nullptr, wide.size() / 3};
  const auto packed = viaGrid(packed_set, packed_set, radius, 1);
  const auto widened = viaGrid(wide_set, wide_set, radius, 3);
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(widened[i].calls, 1);
    ASSERT_EQ(widened[i].points, packed[i].points) << "point " << i;
    ASSERT_EQ(widened[i].d2, packed[i].d2) << "point " << i;
    std::vector<std::uint32_t> got = widened[i].points;
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, bruteForce(packed_set, packed_set.at(i), radius)) << "point " << i;
    pairs += got.size() - 1;
  }
  EXPECT_GT(pairs, 2000u);  // the clusters do overlap the radius
  for (std::size_t i = n; i < wide_set.size; ++i) EXPECT_EQ(widened[i].points, std::vector<std::uint32_t>{std::uint32_t(i)});
  // Foreign queries (an index subset of the points) on the wide keys: the same neighbourhoods.
  std::vector<std::uint32_t> subset;
  for (std::uint32_t i = 0; i < n; i += 4) subset.push_back(i);
  const PointSet queries{xyz.data(), subset.data(), subset.size()};
  const auto foreign = viaGrid(wide_set, queries, radius, 2);
  for (std::size_t t = 0; t < subset.size(); ++t) ASSERT_EQ(foreign[t].points, packed[subset[t]].points) << "query " << t;
}

TEST(FrameGridIndex, NeighboursAndAnyWithinMatchBruteForceInAFixedOrder) {
  // Clustered points with duplicates; the index over every point in ascending order and over the same points in a
  // shuffled order must list each neighbourhood alike (cells by x, y, z; a cell's points by index), as brute force
  // finds it, and anyWithin must agree with brute force for queries anywhere (near, between clusters, far away).
  std::mt19937_64 rng(9);
  const std::vector<double> xyz = clusteredPoints(rng, 300, 10, -20.0, 20.0, 0.1, 0.2, 30);
  std::normal_distribution<double> g(0.0, 0.1);
  const std::size_t n = xyz.size() / 3;
  const double radius = 0.2;
  std::vector<std::uint32_t> ascending(n);
  std::iota(ascending.begin(), ascending.end(), 0u);
  std::vector<std::uint32_t> shuffled = ascending;
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  const FrameGridIndex a(xyz.data(), ascending, radius), b(xyz.data(), shuffled, radius);
  const PointSet all{xyz.data(), nullptr, n};
  std::size_t pairs = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    std::vector<std::uint32_t> from_a, from_b;
    a.forEachNeighbor(i, [&](std::uint32_t j) { from_a.push_back(j); });
    b.forEachNeighbor(i, [&](std::uint32_t j) { from_b.push_back(j); });
    ASSERT_EQ(from_a, from_b) << "point " << i;
    std::sort(from_a.begin(), from_a.end());
    ASSERT_EQ(from_a, bruteForce(all, all.at(i), radius)) << "point " << i;
    pairs += from_a.size() - 1;
  }
  EXPECT_GT(pairs, 3000u);
  std::uniform_real_distribution<double> wide(-25.0, 25.0);
  std::size_t near = 0;
  for (int t = 0; t < 20000; ++t) {
    const std::size_t base = static_cast<std::size_t>(t) % n;
    double q[3] = {xyz[3 * base] + 0.3 * g(rng), xyz[3 * base + 1] + 0.3 * g(rng), xyz[3 * base + 2] + 0.3 * g(rng)};
    if (t % 4 == 0) q[0] = wide(rng), q[1] = wide(rng), q[2] = wide(rng);
    if (t == 1) q[0] = 1e9;  // beyond the index's cells: nothing near
    const bool want = !bruteForce(all, q, radius).empty();
    near += want ? 1 : 0;
    ASSERT_EQ(a.anyWithin(q), want) << "query " << t;
    ASSERT_EQ(b.anyWithin(q), want) << "query " << t;
  }
  EXPECT_GT(near, 5000u);
  EXPECT_LT(near, 19000u);
}

TEST(FrameGridIndex, AnyWithinAtTheRadiusEdgeFarFromTheOriginMatchesBruteForce) {
  // anyWithin skips neighbour cells whose nearest face, edge or corner is a radius away; the skip must never drop a
  // point that the exact test accepts. Sparse points 1e5 m from the origin, queries at the radius times (1 -+ a few
  // ulps to 1e-7) along axes, face and body diagonals and random directions: every answer as brute force gives it.
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double radius = 0.2;
  std::vector<double> xyz;
  for (int i = 0; i < 400; ++i)  // spacing >= 4 radii: each query has one point near it
    for (double c : {1e5 + 0.8 * (i % 20) + 0.1 * u(rng), -2e5 + 0.8 * ((i / 20) % 20) + 0.1 * u(rng), 3e4 + 0.05 * u(rng)})
      xyz.push_back(c);
  const std::size_t n = xyz.size() / 3;
  std::vector<std::uint32_t> all_ids(n);
  std::iota(all_ids.begin(), all_ids.end(), 0u);
  const FrameGridIndex index(xyz.data(), all_ids, radius);
  const PointSet all{xyz.data(), nullptr, n};
  std::vector<std::array<double, 3>> dirs;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z)
        if (x | y | z) dirs.push_back({double(x), double(y), double(z)});
  for (int i = 0; i < 30; ++i) dirs.push_back({u(rng), u(rng), u(rng)});
  std::size_t inside = 0, outside = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (const auto &d : dirs)
      for (double scale : {1.0 - 1e-7, 1.0 - 1e-12, 1.0 - 4e-16, 1.0, 1.0 + 4e-16, 1.0 + 1e-12}) {
        const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        double q[3];
        for (int a = 0; a < 3; ++a) q[a] = xyz[3 * i + a] + d[a] / len * radius * scale;
        const bool want = !bruteForce(all, q, radius).empty();
        (want ? inside : outside) += 1;
        ASSERT_EQ(index.anyWithin(q), want) << "point " << i << " scale " << scale;
      }
  EXPECT_GT(inside, 10000u);  // both sides of the edge are exercised
  EXPECT_GT(outside, 10000u);
}

/// Every query's neighbourhood through a BallGrid over points sorted ahead (BallGridPoints over their box).
std::vector<Found> viaSortedAhead(const BallGridPoints &sorted, const PointSet &points, const PointSet &queries,
                                  std::size_t chunks) {
  return visitAll(BallGrid(sorted, queries), points, queries, chunks);
}

TEST(BallGrid, PointsSortedAheadOverABoxMatchBruteForce) {
  // The point side built before the queries are known (the pipeline's averaging grids): over a box wider than the
  // points, queries inside it find exactly their neighbours, in one order whatever the chunks; queries outside it
  // are never visited; one sorted point side serves several query sets.
  std::mt19937_64 rng(21);
  const std::vector<double> xyz = clusteredPoints(rng, 30, 150, -20.0, 20.0, 0.3, 0.2, 40);
  const PointSet points{xyz.data(), nullptr, xyz.size() / 3};
  const double lo[3] = {-25.0, -25.0, -10.0}, hi[3] = {25.0, 25.0, 10.0}, radius = 0.4;
  const BallGridPoints sorted(points, radius, lo, hi);
  EXPECT_EQ(sorted.radius(), radius);
  EXPECT_GT(sorted.memUsage(), 0u);
  std::uniform_int_distribution<std::size_t> pick(0, points.size - 1);
  std::normal_distribution<double> g(0.0, 0.2);
  for (int set = 0; set < 2; ++set) {
    std::vector<double> qxyz;
    for (int i = 0; i < 400; ++i) {
      const double *p = points.at(pick(rng));
      qxyz.insert(qxyz.end(), {p[0] + g(rng), p[1] + g(rng), p[2] + g(rng)});
    }
    qxyz.insert(qxyz.end(), {24.9, -24.9, 9.9});   // inside the box, far from every point
    qxyz.insert(qxyz.end(), {30.0, 0.0, 0.0});     // outside the box
    qxyz.insert(qxyz.end(), {NAN, 0.0, 0.0});      // not finite
    const PointSet queries{qxyz.data(), nullptr, qxyz.size() / 3};
    const auto once = viaSortedAhead(sorted, points, queries, 1), split = viaSortedAhead(sorted, points, queries, 6);
    for (std::size_t i = 0; i + 2 < queries.size; ++i) {
      ASSERT_EQ(once[i].calls, 1) << "query " << i;
      ASSERT_EQ(once[i].points, split[i].points);
      std::vector<std::uint32_t> got = once[i].points;
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, bruteForce(points, queries.at(i), radius)) << "query " << i;
    }
    EXPECT_TRUE(once[queries.size - 3].points.empty());
    EXPECT_EQ(once[queries.size - 2].calls, 0);
    EXPECT_EQ(once[queries.size - 1].calls, 0);
  }
  // A box that is not one, or a radius that is not positive and finite: nothing is visited.
  const double nan_lo[3] = {NAN, 0.0, 0.0}, inverted_hi[3] = {-30.0, 25.0, 10.0};
  const PointSet one{xyz.data(), nullptr, 1};
  EXPECT_EQ(BallGrid(BallGridPoints(points, radius, nan_lo, hi), one).cellCount(), 0u);
  EXPECT_EQ(BallGrid(BallGridPoints(points, radius, lo, inverted_hi), one).cellCount(), 0u);
  EXPECT_EQ(BallGrid(BallGridPoints(points, 0.0, lo, hi), one).cellCount(), 0u);
}

TEST(BallGrid, GridsGroupedFromAFinerOneMatchBruteForce) {
  // The averaging grids of the larger radii are grouped from the first one's cells (radius doubled 1 to 4 times)
  // instead of sorted again: queries inside the box find exactly their neighbours, and points exactly on the finer
  // cells' faces (a lattice of the finer edge from the box corner) change nothing. Over wide data (an outlier 10 000
  // km out) the frame is a window: sorted afresh, also exact.
  std::mt19937_64 rng(23);
  std::vector<double> xyz = clusteredPoints(rng, 30, 150, -20.0, 20.0, 0.3, 0.2, 40);
  const double lo[3] = {-25.0, -25.0, -10.0}, hi[3] = {25.0, 25.0, 10.0}, radius = 0.3;
  const double edge = radius * (1.0 + 1e-8);
  for (int i = 0; i < 300; ++i)  // on the finer cells' faces
    xyz.insert(xyz.end(), {lo[0] + edge * (60 + i % 20), lo[1] + edge * (60 + i / 20), lo[2] + edge * (30 + i % 3)});
  std::uniform_int_distribution<std::size_t> pick(0, xyz.size() / 3 - 1);
  std::normal_distribution<double> g(0.0, 0.3);
  for (const bool wide : {false, true}) {
    std::vector<double> pts = xyz;
    if (wide) pts.insert(pts.end(), {-1e7, 0.0, 0.0});
    const PointSet points{pts.data(), nullptr, pts.size() / 3};
    const double wide_lo[3] = {-1e7 - 1.0, lo[1], lo[2]};
    const double *box_lo = wide ? wide_lo : lo;
    const BallGridPoints first(points, radius, box_lo, hi);
    std::vector<double> qxyz;
    for (int i = 0; i < 300; ++i) {
      const double *p = points.at(pick(rng));
      qxyz.insert(qxyz.end(), {p[0] + g(rng), p[1] + g(rng), p[2] + g(rng)});
    }
    const PointSet queries{qxyz.data(), nullptr, qxyz.size() / 3};
    for (int doublings = 1; doublings <= 4; ++doublings) {
      const double r = std::ldexp(radius, doublings);
      const BallGridPoints grouped(first, doublings, points, box_lo, hi);
      EXPECT_EQ(grouped.radius(), r);
      const auto once = viaSortedAhead(grouped, points, queries, 1), split = viaSortedAhead(grouped, points, queries, 5);
      // Grouped, a cell's points come in the finer grid's order, not by index: some visit differs from a grid sorted
      // afresh (the same neighbours). The window over wide data is sorted afresh: none does.
      const auto fresh = viaSortedAhead(BallGridPoints(points, r, box_lo, hi), points, queries, 1);
      std::size_t other_order = 0;
      for (std::size_t i = 0; i < queries.size; ++i) other_order += once[i].points != fresh[i].points ? 1 : 0;
      if (wide)
        EXPECT_EQ(other_order, 0u) << doublings;
      else
        EXPECT_GT(other_order, 0u) << doublings;
      for (std::size_t i = 0; i < queries.size; ++i) {
        ASSERT_EQ(once[i].calls, 1) << "query " << i;
        ASSERT_EQ(once[i].points, split[i].points) << "one order whatever the chunks";
        std::vector<std::uint32_t> got = once[i].points;
        std::sort(got.begin(), got.end());
        ASSERT_EQ(got, bruteForce(points, queries.at(i), r)) << "query " << i << ", radius " << r << (wide ? ", wide" : "");
      }
    }
  }
}

// Far from the origin with small radii the two frames' corners round apart by more than the cells' 1e-8 of spare
// width (|coordinates| / radius above ~5e7), and grouped cells would split pairs closer than the radius across two
// cells of the query's grid. Pairs built exactly on such faces (the grouped face and the coarse grid's own, one ulp
// apart) must still find each other; the grouped grid then sorts afresh.
TEST(BallGrid, GroupedGridsFarFromTheOriginMatchBruteForce) {
  std::mt19937_64 rng(5);
  std::size_t pairs = 0;
  for (const double base : {5.0e6, 9.9e6, 1.0e6, 100.0})
    for (const double radius : {0.005, 0.02})
      for (int doublings = 1; doublings <= 3; ++doublings)
        for (int trial = 0; trial < 40; ++trial) {
          const double low = base + std::uniform_real_distribution<double>(0.0, 1.0)(rng);
          const double r = std::ldexp(radius, doublings);
          const double lo[3] = {low, 0.0, 0.0}, hi[3] = {low + 40.0 * r, 10.0, 10.0};
          // The frames' arithmetic (BallGridPoints::frame, no window): finer and coarse edges and corners.
          const double ef = radius * (1.0 + 1e-8), inv_f = 1.0 / ef, of = low - 2.0 * ef;
          const double ec = r * (1.0 + 1e-8), inv_c = 1.0 / ec, oc = low - 2.0 * ec;
          const std::int64_t add = (std::int64_t(2) << doublings) - 2;
          auto grouped = [&](double x) { return (std::int64_t(std::floor((x - of) * inv_f)) + add) >> doublings; };
          auto own = [&](double x) { return std::int64_t(std::floor((x - oc) * inv_c)); };
          auto face = [](auto cell, std::int64_t k, double a, double b) {  // first x in [a, b] with cell(x) >= k
            for (;;) {
              const double m = a + (b - a) / 2;
              if (m == a || m == b) return cell(a) >= k ? a : b;
              (cell(m) >= k ? b : a) = m;
            }
          };
          std::vector<double> pts, qs;
          for (std::int64_t k = 3; k < 30; ++k) {
            const double at = oc + static_cast<double>(k) * ec;
            const double g0 = face(grouped, k, at - 1e-3, at + 1e-3), o0 = face(own, k, at - 1e-3, at + 1e-3);
            const double g1 = face(grouped, k + 1, at + ec - 1e-3, at + ec + 1e-3);
            const double o1 = face(own, k + 1, at + ec - 1e-3, at + ec + 1e-3);
            // A point just below a grouped face with a query just at the next own face, and the other way round.
            for (const auto &[pt, q] : {std::pair{std::nextafter(g0, -INFINITY), o1}, std::pair{g1, std::nextafter(o0, -INFINITY)}})
              if ((pt - q) * (pt - q) < r * r) {
                pts.insert(pts.end(), {pt, 5.0, 5.0});
                qs.insert(qs.end(), {q, 5.0, 5.0});
              }
          }
          if (pts.empty()) continue;
          const PointSet points{pts.data(), nullptr, pts.size() / 3}, queries{qs.data(), nullptr, qs.size() / 3};
          const BallGridPoints first(points, radius, lo, hi);
          const auto found = viaSortedAhead(BallGridPoints(first, doublings, points, lo, hi), points, queries, 1);
          for (std::size_t i = 0; i < queries.size; ++i, ++pairs) {
            std::vector<std::uint32_t> got = found[i].points;
            std::sort(got.begin(), got.end());
            ASSERT_EQ(got, bruteForce(points, queries.at(i), r))
                << std::setprecision(17) << "corner " << low << ", radius " << radius << " x 2^" << doublings;
          }
        }
  EXPECT_GT(pairs, 200u);
}

TEST(BallGrid, AFarOutlierBelowTheFrameLeavesTheRestTheirNeighbours) {
  // One glitched return 10 000 km below a frame on x and y (4e7 cells of 0.25 m): keys reach 2^21 cells per axis,
  // and a window counted from the low corner held only the outlier (every normal of the frame was invalid). Those
  // axes are squeezed now: the frame keeps exactly its neighbourhoods, and the outlier finds itself.
  std::mt19937_64 rng(31);
  std::vector<double> xyz = clusteredPoints(rng, 20, 100, 990.0, 1010.0, 0.2, 0.1, 10);
  xyz.insert(xyz.end(), {1000.0 - 1e7, 1000.0 - 1e7, 0.0});
  const std::size_t n = xyz.size() / 3;
  const PointSet all{xyz.data(), nullptr, n};
  const double radius = 0.25;
  const auto check = [&](const std::vector<Found> &found) {
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(found[i].calls, 1) << "point " << i;
      std::vector<std::uint32_t> got = found[i].points;
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, bruteForce(all, all.at(i), radius)) << "point " << i;
    }
    EXPECT_EQ(found[n - 1].points, std::vector<std::uint32_t>{static_cast<std::uint32_t>(n - 1)});
  };
  check(viaGrid(all, all, radius, 3));
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], all.at(i)[a]), hi[a] = std::max(hi[a], all.at(i)[a]);
  const BallGridPoints sorted(all, radius, lo, hi);
  check(viaSortedAhead(sorted, all, all, 3));
}

TEST(BallGrid, FarApartClustersKeepEveryNeighbourAndTheOrderOfAnUnboundedGrid) {
  // Clusters spread over 2 000 km on x, 50 km on y and 3 km on z at a 5 cm radius (4e7, 1e6 and 6e4 cells): x is
  // squeezed, y and z are not. Beside each cluster, pairs just within one, two and three cell edges along x, and a
  // chain of points half a radius apart, test the squeezing's adjacency. Foreign queries fall in the gaps, below and
  // above every point. Neighbourhoods against brute force, and the visiting order the
  // same whatever the chunks and whether the points are sorted ahead.
  std::mt19937_64 rng(77);
  std::normal_distribution<double> g(0.0, 0.03);
  const double radius = 0.05, edge = radius * (1.0 + 1e-8);
  std::vector<double> xyz;
  const double centres[][3] = {{-1.0e6, 2.0e4, -1.0e3}, {-0.3e6, -3.0e4, 2.0e3}, {0.0, 0.0, 0.0}, {1.0e6, 1.0e3, 5.0}};
  for (const auto &c : centres) {
    for (int i = 0; i < 600; ++i) xyz.insert(xyz.end(), {c[0] + g(rng), c[1] + g(rng), c[2] + g(rng)});
    for (int k = 1; k <= 3; ++k)  // a pair k + 1 cells apart along x, just within or beyond the radius
      xyz.insert(xyz.end(), {c[0] + 1.0, c[1], c[2], c[0] + 1.0 + k * edge - 0.001, c[1], c[2]});
  }
  const double x0 = xyz[0];
  for (int k = 0; k < 6; ++k) xyz.insert(xyz.end(), {x0 + k * 0.5 * radius, 2.0e4, -1.0e3});
  const std::size_t n = xyz.size() / 3;
  const PointSet all{xyz.data(), nullptr, n};
  const auto matches = [&](const std::vector<Found> &found, const PointSet &queries) {
    for (std::size_t i = 0; i < queries.size; ++i) {
      EXPECT_EQ(found[i].calls, 1) << "query " << i;
      std::vector<std::uint32_t> got = found[i].points;
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, bruteForce(all, queries.at(i), radius)) << "query " << i;
    }
  };
  const auto once = viaGrid(all, all, radius, 1), split = viaGrid(all, all, radius, 9);
  matches(once, all);
  for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(once[i].points, split[i].points) << "point " << i;
  std::vector<double> q;
  for (const auto &c : centres)
    q.insert(q.end(), {c[0] + g(rng), c[1] + g(rng), c[2] + g(rng), c[0] + 0.5e5, c[1], c[2], c[0] + 1.0 + 2.5 * edge,
                       c[1], c[2]});
  q.insert(q.end(), {-5.0e6, 0.0, 0.0, 5.0e6, 0.0, 0.0});
  const PointSet queries{q.data(), nullptr, q.size() / 3};
  matches(viaGrid(all, queries, radius, 2), queries);
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], all.at(i)[a]), hi[a] = std::max(hi[a], all.at(i)[a]);
  const BallGridPoints sorted(all, radius, lo, hi);
  const auto ahead = viaSortedAhead(sorted, all, all, 4);
  matches(ahead, all);
  for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(ahead[i].points, once[i].points) << "point " << i;
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < n; ++i) pairs += once[i].points.size() > 1 ? 1 : 0;
  EXPECT_GT(pairs, 2000u);
}

TEST(BallGrid, AnAxisWithTooManyOccupiedCellsToSqueezeIsAWindowAroundTheMedian) {
  // 1.1 M points five cells apart along x (2.2 M squeezed cells: more than 2^21) and a cluster at the median,
  // 2.75 M cells above the lowest point: the axis is a window of 2^21 cells centred there, so the cluster keeps
  // exactly its neighbourhoods (a window from the low corner would not reach it).
  const double radius = 0.1;
  std::vector<double> xyz;
  const std::size_t line = 1100000;
  xyz.reserve(3 * (line + 400));
  for (std::size_t i = 0; i < line; ++i) xyz.insert(xyz.end(), {5.0 * radius * static_cast<double>(i), 0.0, 0.0});
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g(0.0, 0.05);
  const double mid = 5.0 * radius * static_cast<double>(line / 2);
  for (int i = 0; i < 400; ++i) xyz.insert(xyz.end(), {mid + g(rng), 5.0 + g(rng), g(rng)});
  const std::size_t n = xyz.size() / 3;
  const PointSet all{xyz.data(), nullptr, n};
  std::vector<std::uint32_t> cluster(400);
  std::iota(cluster.begin(), cluster.end(), static_cast<std::uint32_t>(line));
  const PointSet queries{xyz.data(), cluster.data(), cluster.size()};
  const auto found = viaGrid(all, queries, radius, 1);
  for (std::size_t i = 0; i < cluster.size(); ++i) {
    std::vector<std::uint32_t> got = found[i].points;
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, bruteForce(all, queries.at(i), radius)) << "query " << i;
  }
}

TEST(FrameGridIndex, AFarOutlierBelowTheFrameLeavesTheRestTheirNeighbours) {
  std::mt19937_64 rng(32);
  std::vector<double> xyz = clusteredPoints(rng, 20, 100, -10.0, 10.0, 0.2, 0.1, 0);
  xyz.insert(xyz.end(), {-2e6, 0.0, -2e6});  // 2e7 cells of 0.1 m below the frame on x and z
  std::vector<std::uint32_t> ids(xyz.size() / 3);
  std::iota(ids.begin(), ids.end(), 0u);
  const double radius = 0.1;
  const FrameGridIndex index(xyz.data(), ids, radius);
  const PointSet all{xyz.data(), nullptr, ids.size()};
  for (std::size_t i = 0; i + 1 < ids.size(); ++i) {
    std::vector<std::uint32_t> got;
    index.forEachNeighbor(static_cast<std::uint32_t>(i), [&](std::uint32_t j) { got.push_back(j); });
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, bruteForce(all, all.at(i), radius)) << "point " << i;
    ASSERT_TRUE(index.anyWithin(all.at(i)));
  }
  std::size_t outlier_neighbours = 0;
  index.forEachNeighbor(static_cast<std::uint32_t>(ids.size() - 1), [&](std::uint32_t) { ++outlier_neighbours; });
  EXPECT_EQ(outlier_neighbours, 0u);
  EXPECT_FALSE(index.anyWithin(all.at(ids.size() - 1)));
}

TEST(BallGrid, EmptyDegenerateAndOutOfRangeInputs) {
  const std::vector<double> one = {1.0, 2.0, 3.0};
  // No points: every query is visited with no neighbours.
  const auto none = viaGrid(PointSet{one.data(), nullptr, 0}, PointSet{one.data(), nullptr, 1}, 0.5, 1);
  ASSERT_EQ(none[0].calls, 1);
  EXPECT_TRUE(none[0].points.empty());
  // No queries, or a radius that is not positive and finite: nothing to visit.
  EXPECT_EQ(BallGrid(PointSet{one.data(), nullptr, 1}, PointSet{}, 0.5).cellCount(), 0u);
  for (double r : {0.0, -1.0, double(NAN), double(INFINITY)})
    EXPECT_EQ(BallGrid(PointSet{one.data(), nullptr, 1}, PointSet{one.data(), nullptr, 1}, r).cellCount(), 0u);
  // All points at one position.
  const std::vector<double> same = {5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0};
  const auto found = viaGrid(PointSet{same.data(), nullptr, 3}, PointSet{same.data(), nullptr, 3}, 0.1, 1);
  for (const auto &f : found) EXPECT_EQ(f.points.size(), 3u);
  // A point 10^9 radii away (beyond 2^21 cells: x is squeezed) finds itself, and the others each other; a
  // non-finite query is never visited.
  std::vector<double> far = {0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 1e8, 0.0, 0.0};
  const auto res = viaGrid(PointSet{far.data(), nullptr, 3}, PointSet{far.data(), nullptr, 3}, 0.1, 1);
  EXPECT_EQ(res[0].points.size(), 2u);
  EXPECT_EQ(res[1].points.size(), 2u);
  EXPECT_EQ(res[2].points, std::vector<std::uint32_t>{2u});
  // Spread over more than 2^32 cells (keys beyond 32 bits: the comparison-sort path): pairs still find each other.
  std::vector<double> spread;
  for (int i = 0; i < 50; ++i) {
    const double c = 1000.0 * i;
    spread.insert(spread.end(), {c, -c, 0.5 * c, c + 0.03, -c, 0.5 * c - 0.04});
  }
  const PointSet sp{spread.data(), nullptr, spread.size() / 3};
  for (const auto &f : viaGrid(sp, sp, 0.1, 3)) EXPECT_EQ(f.points.size(), 2u);
  const std::vector<double> bad = {NAN, 0.0, 0.0};
  const auto nan_query = viaGrid(PointSet{far.data(), nullptr, 2}, PointSet{bad.data(), nullptr, 1}, 0.1, 1);
  EXPECT_EQ(nan_query[0].calls, 0);
}

// ---------------------------------------------------------------- solveNormal

LocalPca iterative(const std::vector<std::array<double, 3>> &pts) {
  PcaAccumulator acc(pts[0].data());
  for (const auto &p : pts) acc.add(p.data());
  return acc.solve(/*accurate=*/true);
}

TEST(SolveNormal, AgreesWithTheIterativeSolver) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  int compared = 0;
  for (double noise : {0.0, 1e-4, 1e-2, 0.3, 1.0})
    for (double elongation : {1.0, 0.1, 0.01})
      for (int t = 0; t < 400; ++t) {
        Eigen::Vector3d n(g(rng), g(rng), g(rng));
        n.normalize();
        const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
        const Eigen::Vector3d origin(5000.0 * u(rng), 5000.0 * u(rng), 100.0 * u(rng));
        std::vector<std::array<double, 3>> pts;
        const int count = 3 + t % 40;
        for (int i = 0; i < count; ++i) {
          const Eigen::Vector3d p =
              origin + 0.3 * (u(rng) * e1 + elongation * u(rng) * e2 + noise * g(rng) * n);
          pts.push_back({p.x(), p.y(), p.z()});
        }
        PcaAccumulator acc(pts[0].data());
        for (const auto &p : pts) acc.add(p.data());
        const LocalPca fast = acc.solveNormal(), ref = acc.solve(true);
        const double trace = ref.l0 + ref.l1 + ref.l2;
        ASSERT_GT(trace, 0.0);
        EXPECT_NEAR(fast.l0, ref.l0, 1e-12 * trace);
        EXPECT_NEAR(fast.l1, ref.l1, 1e-12 * trace);
        EXPECT_NEAR(fast.l2, ref.l2, 1e-12 * trace);
        EXPECT_NEAR(fast.surfaceVariation(), ref.surfaceVariation(), 1e-12);
        if ((ref.l1 - ref.l0) < 1e-6 * trace) continue;  // the normal is not defined to better than round-off
        ASSERT_EQ(fast.valid, ref.valid);
        const double dot = std::fabs(fast.normal[0] * ref.normal[0] + fast.normal[1] * ref.normal[1] +
                                     fast.normal[2] * ref.normal[2]);
        EXPECT_NEAR(dot, 1.0, 1e-12);
        EXPECT_NEAR(std::sqrt(fast.normal[0] * fast.normal[0] + fast.normal[1] * fast.normal[1] +
                              fast.normal[2] * fast.normal[2]),
                    1.0, 1e-14);
        ++compared;
      }
  EXPECT_GT(compared, 5000);
}

TEST(SolveNormal, PrincipalAxisAndMeanAgreeWithTheIterativeSolver) {
  // eigenvector(l2) is the direction planeThroughLine takes for a scan line: checked on lines (noise-free ones too,
  // where l0 = l1 = 0 and the PCA is no plane), strips and planes, far from the origin.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  int compared = 0;
  for (double across : {0.0, 1e-3, 0.05, 0.5})
    for (int t = 0; t < 300; ++t) {
      Eigen::Vector3d d(gauss(rng), gauss(rng), gauss(rng));
      d.normalize();
      const Eigen::Vector3d e1 = d.unitOrthogonal(), e2 = d.cross(e1);
      const Eigen::Vector3d origin(3000.0 * u(rng), 3000.0 * u(rng), 50.0 * u(rng));
      std::vector<std::array<double, 3>> pts;
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      const int count = 3 + t % 60;
      for (int i = 0; i < count; ++i) {
        const Eigen::Vector3d p = origin + 1.5 * u(rng) * d + across * (u(rng) * e1 + 0.3 * u(rng) * e2);
        pts.push_back({p.x(), p.y(), p.z()});
        sum += p - Eigen::Vector3d(pts[0].data());
      }
      PcaAccumulator acc(pts[0].data());
      for (const auto &p : pts) acc.add(p.data());
      double m[3];
      acc.mean(m);
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(m[a], sum(a) / count, 1e-12);
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (const auto &p : pts) {
        const Eigen::Vector3d e = Eigen::Vector3d(p.data()) - Eigen::Vector3d(pts[0].data()) - sum / count;
        cov += e * e.transpose() / count;
      }
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
      const LocalPca pca = acc.solveNormal();
      double axis[3];
      ASSERT_TRUE(acc.eigenvector(pca.l2, axis)) << "across " << across << ", trial " << t;
      const Eigen::Vector3d a(axis[0], axis[1], axis[2]);
      EXPECT_NEAR(a.norm(), 1.0, 1e-14);
      const Eigen::Vector3d ev = es.eigenvalues();
      if (ev(2) - ev(1) < 1e-6 * ev.sum()) continue;  // the axis is not defined to better than round-off
      EXPECT_NEAR(std::fabs(a.dot(es.eigenvectors().col(2))), 1.0, 1e-9) << "across " << across << ", trial " << t;
      ++compared;
    }
  EXPECT_GT(compared, 1000);
  // Two eigenvalues 1 and 1 + g: the axis of 1 + g is defined by g only. Where g is too small against the error of
  // solveNormal's l2 (about 1e-8 of the trace there), no direction rather than a wrong one.
  for (const double g : {1e-2, 1e-3, 1e-6, 1e-8, 1e-10}) {
    const Eigen::Matrix3d rot = Eigen::Quaterniond(0.3, -0.5, 0.7, 0.2).normalized().toRotationMatrix();
    const Eigen::Vector3d spread(std::sqrt(0.3 * 2.0), std::sqrt(2.0), std::sqrt((1.0 + g) * 2.0));
    const double zero[3] = {0.0, 0.0, 0.0};
    PcaAccumulator acc(zero);
    for (int a = 0; a < 3; ++a)  // +-spread along each axis: covariance diag(spread^2) / 2 = (0.3, 1, 1 + g)
      for (const double s : {-1.0, 1.0}) {
        const Eigen::Vector3d p = rot * (s * spread(a) * Eigen::Vector3d::Unit(a));
        acc.add(p.x(), p.y(), p.z());
      }
    double axis[3];
    const bool got = acc.eigenvector(acc.solveNormal().l2, axis);
    const double err = std::acos(std::min(1.0, std::fabs(Eigen::Vector3d(axis[0], axis[1], axis[2]).dot(rot.col(2)))));
    if (g >= 1e-3) {
      ASSERT_TRUE(got) << "gap " << g;
      EXPECT_LT(err, 1e-4) << "gap " << g;
    } else {
      EXPECT_TRUE(!got || err < 1e-4) << "gap " << g << ": " << err << " rad";
      EXPECT_FALSE(got) << "gap " << g;
    }
  }
  // Nothing added, or a repeated eigenvalue (isotropic): no direction.
  const double origin[3] = {0.0, 0.0, 0.0};
  PcaAccumulator none(origin);
  double axis[3];
  EXPECT_FALSE(none.eigenvector(0.0, axis));
  PcaAccumulator iso(origin);
  for (const std::array<double, 3> &p : std::vector<std::array<double, 3>>{{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0},
                                                                          {0, 0, 1}, {0, 0, -1}})
    iso.add(p.data());
  EXPECT_FALSE(iso.eigenvector(iso.solveNormal().l2, axis));
}

TEST(SolveNormal, DegenerateNeighbourhoodsAreInvalid) {
  const std::vector<std::array<double, 3>> line = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {3, 3, 3}};
  const std::vector<std::array<double, 3>> point = {{7, 7, 7}, {7, 7, 7}, {7, 7, 7}};
  for (const auto *pts : {&line, &point}) {
    PcaAccumulator acc((*pts)[0].data());
    for (const auto &p : *pts) acc.add(p.data());
    EXPECT_FALSE(acc.solveNormal().valid);
  }
  PcaAccumulator two(line[0].data());
  two.add(line[0].data());
  two.add(line[1].data());
  EXPECT_FALSE(two.solveNormal().valid);
  // Isotropic (all eigenvalues equal): valid, any unit normal.
  const std::vector<std::array<double, 3>> cube = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  PcaAccumulator iso(cube[0].data());
  for (const auto &p : cube) iso.add(p.data());
  const LocalPca s = iso.solveNormal();
  EXPECT_TRUE(s.valid);
  EXPECT_NEAR(s.surfaceVariation(), 1.0 / 3.0, 1e-12);
  EXPECT_NEAR(std::sqrt(s.normal[0] * s.normal[0] + s.normal[1] * s.normal[1] + s.normal[2] * s.normal[2]), 1.0, 1e-12);
  EXPECT_TRUE(iterative(cube).valid);
}

// ---------------------------------------------------------------- estimateNormals with foreign query sets

TEST(Normals, QueriesNeedNotBeTheCandidateSet) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.0, 3.0);
  std::normal_distribution<double> g(0.0, 0.005);
  std::vector<double> xyz;
  for (int i = 0; i < 30000; ++i) {
    const double x = u(rng), y = u(rng);
    xyz.insert(xyz.end(), {x, y, 0.2 * x + (y > 1.5 ? 0.3 * y : 0.0) + g(rng)});
  }
  const Hierarchy h = test::buildShuffled(xyz, 1.0, 6, 9, {0.0, 0.0, 10.0});
  const int level = 4;
  NormalParams params;
  params.level = level;
  params.radius = 2.5 * h.radius(level);
  const std::vector<SampleId> candidates = h.samplesUpTo(level);
  // Unsorted, repeated, a subset, and samples of finer levels (queried but never neighbours).
  std::vector<SampleId> ids(candidates.begin(), candidates.begin() + candidates.size() / 2);
  std::shuffle(ids.begin(), ids.end(), rng);
  ids.push_back(ids.front());
  for (SampleId id : h.samplesUpTo(6))
    if (h.level(id) > level && ids.size() < candidates.size()) ids.push_back(id);
  for (const int threads : {1, 3}) {
    params.threads = threads;
    const auto normals = estimateNormals(h, ids, params);
    ASSERT_EQ(normals.size(), ids.size());
    std::size_t valid = 0;
    for (std::size_t i = 0; i < ids.size(); i += 5) {
      const double *q = h.position(ids[i]);
      PcaAccumulator acc(q);
      for (SampleId o : candidates) {
        const double *p = h.position(o);
        const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
        if (ax * ax + ay * ay + az * az < params.radius * params.radius) acc.add(p);
      }
      const LocalPca ref = acc.solve(true);
      if (static_cast<int>(acc.count()) < params.min_neighbors || !ref.valid) {
        EXPECT_FALSE(normals[i].valid);
        continue;
      }
      ASSERT_TRUE(normals[i].valid) << i;
      ++valid;
      const double dot = normals[i].normal[0] * ref.normal[0] + normals[i].normal[1] * ref.normal[1] +
                         normals[i].normal[2] * ref.normal[2];
      EXPECT_GT(std::fabs(dot), 1.0 - 1e-6);
      EXPECT_NEAR(normals[i].curvature, ref.surfaceVariation(), 1e-6);
      const std::array<float, 3> v = h.toViewpoint(ids[i]);
      EXPECT_GE(normals[i].normal[0] * v[0] + normals[i].normal[1] * v[1] + normals[i].normal[2] * v[2], 0.0f)
          << "must face the viewpoint";
    }
    EXPECT_GT(valid, 200u);
  }
}

// k nearest without a radius: balls of 2 r_level doubling until k samples of levels 0..level are inside or the
// radius reaches twice the level-0 cell; the k nearest by (distance, id), summed nearest first. The oracle walks
// every candidate for every radius; a sparse far field makes queries end in every round, the last one included.
TEST(Normals, AdaptiveKNearestMatchesBruteForce) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(0.0, 3.0), far(-25.0, 25.0);
  std::normal_distribution<double> g(0.0, 0.005);
  std::vector<double> xyz;
  for (int i = 0; i < 20000; ++i) {
    const double x = u(rng), y = u(rng);
    xyz.insert(xyz.end(), {x, y, 0.2 * x + (y > 1.5 ? 0.3 * y : 0.0) + g(rng)});
  }
  for (int i = 0; i < 400; ++i) {
    const double x = far(rng), y = far(rng);
    xyz.insert(xyz.end(), {x, y, 0.1 * y + g(rng)});
  }
  // A band thinning out with distance (log-uniform in x), as a scan's ground does.
  std::uniform_real_distribution<double> logx(std::log(3.0), std::log(40.0));
  for (int i = 0; i < 3000; ++i) {
    const double x = std::exp(logx(rng)), y = u(rng);
    xyz.insert(xyz.end(), {x, y, 0.6 + 0.05 * x + g(rng)});
  }
  const Hierarchy h = test::buildShuffled(xyz, 1.0, 6, 9, {0.0, 0.0, 10.0});
  const int level = 4;
  NormalParams params;
  params.level = level;
  params.k = 12;
  params.min_neighbors = 5;
  const std::vector<SampleId> candidates = h.samplesUpTo(level);
  std::vector<SampleId> ids = candidates;
  std::shuffle(ids.begin(), ids.end(), rng);
  ids.push_back(ids.front());
  for (SampleId id : h.samplesUpTo(6))
    if (h.level(id) > level && ids.size() < candidates.size() + 500) ids.push_back(id);
  std::map<int, int> rounds;  // how many queries ended at each radius, to show every round is exercised
  for (const int threads : {1, 3}) {
    params.threads = threads;
    const auto normals = estimateNormals(h, ids, params);
    ASSERT_EQ(normals.size(), ids.size());
    std::size_t valid = 0, invalid = 0;
    for (std::size_t i = 0; i < ids.size(); i += 3) {
      const double *q = h.position(ids[i]);
      std::vector<std::pair<double, SampleId>> nb;
      int round = 0;
      for (double r = 2.0 * h.radius(level);; r *= 2.0, ++round) {
        nb.clear();
        for (SampleId o : candidates) {
          const double *p = h.position(o);
          const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
          const double d2 = ax * ax + ay * ay + az * az;
          if (d2 < r * r) nb.emplace_back(d2, o);
        }
        if (nb.size() >= static_cast<std::size_t>(params.k) || r >= 2.0 * h.cellSize()) break;
      }
      if (threads == 1) ++rounds[round];
      std::sort(nb.begin(), nb.end());
      if (nb.size() > static_cast<std::size_t>(params.k)) nb.resize(static_cast<std::size_t>(params.k));
      if (static_cast<int>(nb.size()) < params.min_neighbors) {
        EXPECT_FALSE(normals[i].valid) << i;
        ++invalid;
        continue;
      }
      PcaAccumulator acc(q);
      for (const auto &n : nb) acc.add(h.position(n.second));
      const LocalPca ref = acc.solveNormal();
      ASSERT_EQ(normals[i].valid, ref.valid) << i;
      if (!ref.valid) continue;
      ++valid;
      // The same neighbours summed in the same order: the same bits, up to the orientation's sign.
      for (int c = 0; c < 3; ++c) EXPECT_EQ(std::fabs(normals[i].normal[0 + c]), std::fabs(static_cast<float>(ref.normal[c]))) << i;
      EXPECT_EQ(normals[i].curvature, static_cast<float>(ref.surfaceVariation())) << i;
      const std::array<float, 3> v = h.toViewpoint(ids[i]);
      EXPECT_GE(normals[i].normal[0] * v[0] + normals[i].normal[1] * v[1] + normals[i].normal[2] * v[2], 0.0f);
    }
    EXPECT_GT(valid, 500u);
    EXPECT_GT(invalid, 0u);  // far samples with fewer than min_neighbors within the cap
  }
  EXPECT_GE(rounds.size(), 5u);
  EXPECT_GT(rounds.rbegin()->second, 0);
}

}  // namespace
}  // namespace hpds
