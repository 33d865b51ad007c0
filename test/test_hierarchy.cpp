// The hierarchy against brute-force oracles: a naive O(N*S) implementation of the same greedy rule must make
// exactly the same decisions, and the guarantees (one sample per cell, additive Poisson property, coverage) are
// checked pairwise on the output.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <tuple>

#include "hpds/sampling/CellKey.hpp"
#include "hpds/sampling/Hierarchy.hpp"
#include "hpds/sampling/LevelGrid.hpp"
#include "hpds/points/ViewDirection.hpp"

namespace hpds {
namespace {

// ---------------------------------------------------------------- exact cell coordinates

TEST(CellKey, FloorIsExactAtCellBoundaries) {
  std::mt19937_64 rng(7);
  for (double cell : {1.0, 0.3, 0.1, 4.0, 0.7071}) {
    for (int depth : {0, 5, 10, 21}) {
      const double e = std::ldexp(cell, -depth), ie = 1.0 / e;
      std::uniform_int_distribution<std::int64_t> kd(-1000000, 1000000);
      for (int i = 0; i < 2000; ++i) {
        const std::int64_t k = kd(rng);
        const double v = static_cast<double>(k) * e;  // the boundary, rounded
        for (double x : {v, std::nextafter(v, -INFINITY), std::nextafter(v, INFINITY)}) {
          if (!inCellRange(x, ie)) continue;
          const std::int32_t q = exactCellCoord(x, e, ie);
          // Oracle in 113-bit arithmetic: q*e and (q+1)*e are exact there.
          const __float128 lo = static_cast<__float128>(q) * static_cast<__float128>(e);
          const __float128 hi = static_cast<__float128>(q + 1) * static_cast<__float128>(e);
          ASSERT_TRUE(lo <= static_cast<__float128>(x) && static_cast<__float128>(x) < hi)
              << "x=" << x << " e=" << e << " q=" << q;
        }
      }
    }
  }
}

// A power-of-two multiple of the edge is a boundary exactly representable in a double, and for about one edge in
// eight (none of the round ones above) v * (1 / e) rounds to just below the integer: only the exact residual test
// puts v in the cell it starts. Cell sizes come from arbitrary spacings, so edges are drawn at random.
TEST(CellKey, FloorIsExactAtPowerOfTwoMultiplesOfAnyEdge) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> edge(0.01, 10.0);
  std::uniform_int_distribution<int> power(0, 29);
  std::size_t rounded_below = 0;
  for (int i = 0; i < 20000; ++i) {
    const double e = edge(rng), ie = 1.0 / e;
    const int j = power(rng);
    for (const double sign : {1.0, -1.0}) {
      const double v = sign * std::ldexp(e, j);  // exactly +-2^j cells
      if (!inCellRange(v, ie)) continue;
      rounded_below += v * ie < sign * std::ldexp(1.0, j) ? 1 : 0;
      EXPECT_EQ(exactCellCoord(v, e, ie), static_cast<std::int32_t>(sign * std::ldexp(1.0, j)))
          << "v=" << v << " e=" << e;
    }
  }
  EXPECT_GT(rounded_below, 100u) << "the estimate never rounded below the boundary: the case is not tested";
}

TEST(CellKey, MillimetreCellsAtAMillionMetres) {
  const double e = std::ldexp(1.0, -10), ie = 1.0 / e;  // ~0.98 mm
  const double x = 1e6 + 0.123456789;
  ASSERT_TRUE(inCellRange(x, ie));
  const std::int32_t q = exactCellCoord(x, e, ie);
  EXPECT_EQ(q, static_cast<std::int32_t>(std::floor(static_cast<long double>(x) * 1024.0L)));
  EXPECT_FALSE(inCellRange(1e7, std::ldexp(1.0, 21)));  // 2e13 cells: refused, not wrapped
  EXPECT_FALSE(inCellRange(std::nan(""), 1.0));
  EXPECT_FALSE(inCellRange(INFINITY, 1.0));
}

// ---------------------------------------------------------------- LevelGrid vs std::map

TEST(LevelGrid, MatchesMapUnderRandomInsertEraseFind) {
  std::mt19937_64 rng(3);
  std::uniform_int_distribution<int> c(-20, 20), op(0, 9);
  LevelGrid grid;
  std::map<std::tuple<int, int, int>, SampleId> ref;
  for (int i = 0; i < 200000; ++i) {
    const CellKey k{c(rng), c(rng), c(rng)};
    const auto t = std::make_tuple(k.x, k.y, k.z);
    const int o = op(rng);
    if (o < 5) {
      const bool inserted = grid.insert(k, static_cast<SampleId>(i));
      const bool ref_inserted = ref.emplace(t, static_cast<SampleId>(i)).second;
      ASSERT_EQ(inserted, ref_inserted);
    } else if (o < 8) {
      ASSERT_EQ(grid.erase(k), ref.erase(t) == 1);
    } else {
      const auto it = ref.find(t);
      ASSERT_EQ(grid.find(k), it == ref.end() ? kNoSample : it->second);
    }
    ASSERT_EQ(grid.size(), ref.size());
  }
  std::size_t visited = 0;
  grid.forEach([&](const CellKey &k, SampleId id) {
    ++visited;
    EXPECT_EQ(ref.at(std::make_tuple(k.x, k.y, k.z)), id);
  });
  EXPECT_EQ(visited, ref.size());
}

TEST(LevelGrid, ChurnInAMovingWindowKeepsMemoryBoundedAndMatchesTheMap) {
  // A map-mode pattern: cells appear ahead and are erased behind, forever. Freed pool chunks must be reused or
  // compacted, not accumulate; every answer must still match a std::map.
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> c(0, 39), big(0, 3);
  LevelGrid grid;
  std::map<std::tuple<int, int, int>, SampleId> ref;
  std::size_t mem_early = 0, mem_late = 0;
  for (int step = 0; step < 400; ++step) {
    for (int i = 0; i < 300; ++i) {
      // Denser blocks now and then, so chunks move between size classes.
      const int x = step * 4 + c(rng) / (big(rng) == 0 ? 8 : 1), y = c(rng), z = c(rng) / 4;
      const SampleId id = static_cast<SampleId>(step * 1000 + i);
      ASSERT_EQ(grid.insert(CellKey{x, y, z}, id), ref.emplace(std::make_tuple(x, y, z), id).second);
    }
    for (auto it = ref.begin(); it != ref.end();) {
      if (std::get<0>(it->first) < step * 4 - 40) {
        ASSERT_TRUE(grid.erase(CellKey{std::get<0>(it->first), std::get<1>(it->first), std::get<2>(it->first)}));
        it = ref.erase(it);
      } else {
        ++it;
      }
    }
    ASSERT_EQ(grid.size(), ref.size());
    if (step == 100) mem_early = grid.memUsage();
    if (step > 100) mem_late = std::max(mem_late, grid.memUsage());
  }
  for (const auto &[k, id] : ref) ASSERT_EQ(grid.find(CellKey{std::get<0>(k), std::get<1>(k), std::get<2>(k)}), id);
  EXPECT_LE(mem_late, mem_early * 2) << "grid memory grew from " << mem_early << " to " << mem_late;
}

TEST(ViewDirection, RoundTripsExactlyAndKeepsTheDirection) {
  std::mt19937_64 rng(9);
  std::normal_distribution<double> g(0.0, 1.0);
  double worst = 0.0;
  for (int i = 0; i < 200000; ++i) {
    double v[3] = {g(rng), g(rng), g(rng)};
    if (i % 7 == 0) v[i % 3] = 0.0;  // on the octahedron's seams
    if (i % 11 == 0) v[2] = -std::fabs(v[2]) * 1e-9;  // just below the equator
    const double s = std::pow(10.0, (i % 9) - 4);  // length never matters
    const std::uint32_t code = encodeViewDirection(s * v[0], s * v[1], s * v[2]);
    const std::array<float, 3> d = decodeViewDirection(code);
    ASSERT_EQ(encodeViewDirection(d[0], d[1], d[2]), code) << "decode then encode must be the identity";
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    const double dot = (d[0] * v[0] + d[1] * v[1] + d[2] * v[2]) / n;
    worst = std::max(worst, std::acos(std::min(1.0, dot)));
  }
  EXPECT_LT(worst, 5e-4) << "radians";
  const std::array<float, 3> zero = decodeViewDirection(encodeViewDirection(0.0, 0.0, 0.0));
  EXPECT_EQ(zero, (std::array<float, 3>{0.0f, 0.0f, 0.0f}));
  EXPECT_EQ(encodeViewDirection(NAN, 1.0, 0.0), encodeViewDirection(0.0, 0.0, 0.0));

  // The fold's edge (one coordinate at +-32767, the lower hemisphere): two codes decode to one direction; both must
  // give the same bits (a -0.0 there made a loaded map save back with different bytes), stable under re-encoding.
  const auto bits = [](const std::array<float, 3> &d) {
    std::array<std::uint32_t, 3> b;
    std::memcpy(b.data(), d.data(), sizeof b);
    return b;
  };
  for (int c = -32767; c <= 32767; ++c)
    for (const std::uint32_t edge : {std::uint32_t(32767), std::uint32_t(std::uint16_t(-32767))})
      for (const std::uint32_t code : {std::uint32_t(std::uint16_t(c)) | edge << 16, edge | std::uint32_t(std::uint16_t(c)) << 16}) {
        const std::array<float, 3> d = decodeViewDirection(code);
        const std::array<float, 3> again = decodeViewDirection(encodeViewDirection(d[0], d[1], d[2]));
        ASSERT_EQ(bits(again), bits(d)) << "code " << std::hex << code;
        for (const float v : d) ASSERT_FALSE(v == 0.0f && std::signbit(v)) << "-0.0 from code " << std::hex << code;
      }
}

TEST(ViewDirection, UnscaledDecodingIsTheSameDirection) {
  // Every code an encoder can produce, sampled on a lattice, plus the fold's edges: the unscaled vector is the decoded
  // unit vector times its length, to float rounding, and the zero code gives the zero vector.
  std::size_t tried = 0;
  for (int a = -32767; a <= 32767; a += 97)
    for (int b = -32767; b <= 32767; b += 89)
      for (const std::uint32_t code : {std::uint32_t(std::uint16_t(a)) | std::uint32_t(std::uint16_t(b)) << 16,
                                       std::uint32_t(std::uint16_t(a)) | std::uint32_t(32767) << 16}) {
        double u[3];
        viewDirectionUnscaled(code, u);
        const double len = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        ASSERT_GT(len, 0.5) << std::hex << code;  // |u|_1 = 1, so |u|_2 >= 1 / sqrt(3)
        const std::array<float, 3> d = decodeViewDirection(code);
        for (int k = 0; k < 3; ++k) ASSERT_NEAR(u[k] / len, d[k], 1e-7) << std::hex << code << " axis " << k;
        ++tried;
      }
  EXPECT_GT(tried, 200000u);
  double z[3] = {1, 1, 1};
  viewDirectionUnscaled(encodeViewDirection(0.0, 0.0, 0.0), z);
  EXPECT_EQ(z[0], 0.0);
  EXPECT_EQ(z[1], 0.0);
  EXPECT_EQ(z[2], 0.0);
}

// ---------------------------------------------------------------- brute-force reference of the greedy rule

struct RefSample {
  std::array<double, 3> p;
  int level;
  std::uint32_t point;
  int batch;
};

double dist2(const double *a, const double *b) {
  const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
  return dx * dx + dy * dy + dz * dz;
}

long long refCell(double v, double e) { return static_cast<long long>(std::floor(static_cast<long double>(v) / e)); }

/// Naive breadth-first insertion: every test is a linear scan over all samples.
struct ReferenceHierarchy {
  double cell;
  int max_depth;
  std::vector<RefSample> samples;
  std::uint64_t dropped = 0;

  double edge(int d) const { return std::ldexp(cell, -d); }
  double radius(int d) const { return 0.5 * std::sqrt(3.0) * edge(d); }

  void insert(const std::vector<double> &xyz, const std::vector<std::uint32_t> &order, int batch) {
    std::vector<std::uint32_t> active(order.size());
    std::iota(active.begin(), active.end(), 0u);  // ranks
    for (int d = 0; d <= max_depth && !active.empty(); ++d) {
      std::vector<std::uint32_t> next;
      for (std::uint32_t rank : active) {
        const double *q = &xyz[3 * order[rank]];
        bool ok = true;
        for (const auto &s : samples) {
          if (s.level == d && refCell(s.p[0], edge(d)) == refCell(q[0], edge(d)) &&
              refCell(s.p[1], edge(d)) == refCell(q[1], edge(d)) && refCell(s.p[2], edge(d)) == refCell(q[2], edge(d)))
            ok = false;
          const double r = radius(std::max(d, s.level));
          if (dist2(s.p.data(), q) < r * r) ok = false;
          if (!ok) break;
        }
        if (ok)
          samples.push_back({{q[0], q[1], q[2]}, d, order[rank], batch});
        else
          next.push_back(rank);
      }
      active.swap(next);
    }
    dropped += active.size();
  }
};

std::vector<double> randomCloud(std::mt19937_64 &rng, std::size_t n, double extent, bool planar) {
  std::uniform_real_distribution<double> u(-extent, extent);
  std::vector<double> xyz(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    xyz[3 * i] = u(rng);
    xyz[3 * i + 1] = u(rng);
    // "2D-like": a thin noisy slab, as a lidar sees a floor.
    xyz[3 * i + 2] = planar ? 0.01 * u(rng) / extent : u(rng);
  }
  return xyz;
}

/// Clustered points with near-duplicates, as scan lines produce.
std::vector<double> scanLineCloud(std::mt19937_64 &rng, std::size_t n, double extent) {
  std::uniform_real_distribution<double> u(-extent, extent);
  std::normal_distribution<double> jitter(0.0, 0.002);
  std::vector<double> xyz(3 * n);
  const int lines = 12;
  for (std::size_t i = 0; i < n; ++i) {
    const int line = static_cast<int>(i % lines);
    xyz[3 * i] = u(rng);
    xyz[3 * i + 1] = -extent + (2.0 * extent * line) / lines + jitter(rng);
    xyz[3 * i + 2] = 0.05 * std::sin(xyz[3 * i]) + jitter(rng);
  }
  return xyz;
}

std::vector<std::uint32_t> shuffledOrder(std::size_t n, std::mt19937_64 &rng) {
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::shuffle(order.begin(), order.end(), rng);
  return order;
}

InsertResult insertAll(Hierarchy &h, const std::vector<double> &xyz, const std::vector<std::uint32_t> &order,
                       std::uint32_t frame = 0) {
  InsertBatch b;
  b.xyz = xyz.data();
  b.size = xyz.size() / 3;
  b.order = order.data();
  b.order_size = order.size();
  b.frame_index = frame;
  return h.insert(b);
}

/// The three guarantees, checked pairwise. `inserted` are all points offered so far (coverage).
void expectGuarantees(const Hierarchy &h, const std::vector<std::array<double, 3>> &inserted) {
  std::vector<SampleId> ids = h.samplesUpTo(h.maxDepth());
  ASSERT_EQ(ids.size(), h.sampleCount());
  for (int d = 0; d <= h.maxDepth(); ++d) {
    const double e = h.edge(d), r = h.radius(d);
    std::map<std::tuple<long long, long long, long long>, int> cells;
    std::vector<SampleId> uni;
    for (SampleId id : ids) {
      const double *p = h.position(id);
      if (h.level(id) == d) {
        const auto cell = std::make_tuple(refCell(p[0], e), refCell(p[1], e), refCell(p[2], e));
        ASSERT_EQ(++cells[cell], 1) << "two samples in a level-" << d << " cell";
      }
      if (h.level(id) <= d) uni.push_back(id);
    }
    for (std::size_t i = 0; i < uni.size(); ++i)
      for (std::size_t j = i + 1; j < uni.size(); ++j)
        ASSERT_GE(dist2(h.position(uni[i]), h.position(uni[j])), r * r)
            << "levels 0.." << d << " violate r_" << d << " between samples " << uni[i] << " and " << uni[j];
    for (const auto &q : inserted) {
      double best = INFINITY;
      for (SampleId id : uni) best = std::min(best, dist2(h.position(id), q.data()));
      ASSERT_LE(best, 4.0 * r * r * (1 + 1e-12)) << "a point is farther than 2 r_" << d << " from levels 0.." << d;
    }
  }
}

struct Case {
  const char *name;
  double cell;
  int depth;
  std::size_t n;
  int kind;  // 0 = 3D uniform, 1 = planar slab, 2 = scan lines
  int batches;
};

/// The same samples (positions) at the same levels as the brute-force reference.
void expectSameSamplesAs(const Hierarchy &h, const ReferenceHierarchy &ref) {
  ASSERT_EQ(h.sampleCount(), ref.samples.size());
  std::map<std::tuple<double, double, double>, int> ref_levels;
  for (const auto &s : ref.samples) ref_levels[{s.p[0], s.p[1], s.p[2]}] = s.level;
  for (SampleId id : h.samplesUpTo(h.maxDepth())) {
    const double *p = h.position(id);
    const auto it = ref_levels.find({p[0], p[1], p[2]});
    ASSERT_NE(it, ref_levels.end()) << "a sample the reference does not have";
    ASSERT_EQ(it->second, h.level(id));
  }
}

class HierarchyOracle : public ::testing::TestWithParam<Case> {};

TEST_P(HierarchyOracle, SameDecisionsAsBruteForceAndGuaranteesHold) {
  const Case c = GetParam();
  for (std::uint64_t seed : {1ull, 2ull, 3ull}) {
    std::mt19937_64 rng(seed * 7919 + c.n);
    Hierarchy h(c.cell, c.depth);
    ReferenceHierarchy ref{c.cell, c.depth, {}, 0};
    std::vector<std::array<double, 3>> inserted;
    std::uint64_t dropped = 0;
    for (int b = 0; b < c.batches; ++b) {
      std::vector<double> xyz = c.kind == 0   ? randomCloud(rng, c.n, 2.0, false)
                                : c.kind == 1 ? randomCloud(rng, c.n, 2.0, true)
                                              : scanLineCloud(rng, c.n, 2.0);
      // Later batches overlap the first but are shifted, as consecutive frames of a moving sensor.
      for (std::size_t i = 0; i < xyz.size(); i += 3) xyz[i] += 0.5 * b;
      const auto order = shuffledOrder(c.n, rng);
      const InsertResult r = insertAll(h, xyz, order, static_cast<std::uint32_t>(b));
      ref.insert(xyz, order, b);
      dropped += r.dropped_depth;
      EXPECT_EQ(r.out_of_range, 0u);
      for (std::size_t i = 0; i < c.n; ++i) inserted.push_back({xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
      // Identical decisions: same points accepted at the same levels, same drops.
      ASSERT_EQ(h.sampleCount(), ref.samples.size()) << c.name << " seed " << seed << " batch " << b;
      std::map<std::tuple<double, double, double>, std::pair<int, int>> ref_levels;
      for (const auto &s : ref.samples) ref_levels[{s.p[0], s.p[1], s.p[2]}] = {s.level, s.batch};
      for (SampleId id : h.samplesUpTo(c.depth)) {
        const double *p = h.position(id);
        const auto it = ref_levels.find({p[0], p[1], p[2]});
        ASSERT_NE(it, ref_levels.end());
        ASSERT_EQ(it->second.first, h.level(id));
        ASSERT_EQ(static_cast<int>(h.frameIndex(id)), it->second.second);
      }
      ASSERT_EQ(dropped, ref.dropped);
    }
    expectGuarantees(h, inserted);
  }
}

INSTANTIATE_TEST_SUITE_P(
    RandomSets, HierarchyOracle,
    ::testing::Values(Case{"uniform3d", 1.0, 5, 400, 0, 1}, Case{"planar", 1.0, 6, 500, 1, 1},
                      Case{"scanlines", 0.8, 6, 500, 2, 1}, Case{"coarse_cells", 3.0, 3, 300, 0, 1},
                      Case{"deep_drops", 1.0, 2, 600, 0, 1}, Case{"stream3d", 1.0, 5, 250, 0, 3},
                      Case{"stream_planar", 0.7, 6, 300, 1, 3}, Case{"stream_scanlines", 1.3, 6, 300, 2, 3},
                      // A map whose finest populated level is 0 (map mode at output level 0) is not empty: later
                      // batches must still be checked against the earlier ones, not only against themselves.
                      Case{"stream_level0_only", 1.0, 0, 300, 0, 3}),
    [](const ::testing::TestParamInfo<Case> &param_info) { return std::string(param_info.param.name); });

// A batch offered down to max_level < max_depth gives exactly the levels 0..max_level of a hierarchy that stops there
// (brute force), with the rest dropped; in map mode too, where the finer levels of earlier batches still count.
TEST(Hierarchy, BatchMaxLevelMatchesAHierarchyThatStopsThere) {
  for (std::uint64_t seed : {4ull, 5ull}) {
    std::mt19937_64 rng(seed);
    Hierarchy h(1.0, 7);
    ReferenceHierarchy ref{1.0, 7, {}, 0};
    for (int b = 0; b < 3; ++b) {
      std::vector<double> xyz = scanLineCloud(rng, 400, 2.0);
      for (std::size_t i = 0; i < xyz.size(); i += 3) xyz[i] += 0.5 * b;
      const auto order = shuffledOrder(400, rng);
      const int max_level = b == 1 ? 6 : 3;  // a deep batch between two shallow ones
      InsertBatch batch;
      batch.xyz = xyz.data();
      batch.size = 400;
      batch.order = order.data();
      batch.order_size = order.size();
      batch.frame_index = static_cast<std::uint32_t>(b);
      batch.max_level = max_level;
      const InsertResult r = h.insert(batch);
      ref.max_depth = max_level;
      const std::uint64_t dropped_before = ref.dropped;
      ref.insert(xyz, order, b);
      EXPECT_EQ(r.dropped_depth, ref.dropped - dropped_before) << "seed " << seed << " batch " << b;
      for (int d = max_level + 1; d <= 7; ++d) EXPECT_EQ(r.accepted_per_level[d], 0u);
      expectSameSamplesAs(h, ref);
    }
  }
}

// The insertion remembers, per small cell, a nearby sample to try first; cells whose coordinates agree in their low
// bits share that memory. Three copies of a dense cloud, 2^19 level-1 cells apart (so every level's cells alias),
// interleaved in one batch: a remembered sample from another copy must never decide a point.
TEST(Hierarchy, AliasedWitnessSlotsNeverDecideAPoint) {
  std::mt19937_64 rng(77);
  const double cell = 1.0, offset = std::ldexp(0.5 * cell, 19);  // 2^19 cells of level 1, i.e. 2^(18+l) of level l
  const std::vector<double> base = scanLineCloud(rng, 300, 2.0);
  std::vector<double> xyz;
  for (int copy = 0; copy < 3; ++copy)
    for (std::size_t i = 0; i < base.size(); i += 3)
      xyz.insert(xyz.end(), {base[i] + copy * offset, base[i + 1], base[i + 2]});
  const auto order = shuffledOrder(xyz.size() / 3, rng);
  Hierarchy h(cell, 6);
  ReferenceHierarchy ref{cell, 6, {}, 0};
  const InsertResult r = insertAll(h, xyz, order);
  ref.insert(xyz, order, 0);
  ASSERT_EQ(r.out_of_range, 0u);
  EXPECT_EQ(r.dropped_depth, ref.dropped);
  expectSameSamplesAs(h, ref);
}

TEST(Hierarchy, DuplicatePointsGoToOneSampleAndDropTheRest) {
  Hierarchy h(1.0, 4);
  std::vector<double> xyz;
  for (int i = 0; i < 10; ++i) xyz.insert(xyz.end(), {0.25, 0.25, 0.25});
  std::vector<std::uint32_t> order(10);
  std::iota(order.begin(), order.end(), 0u);
  const auto r = insertAll(h, xyz, order);
  EXPECT_EQ(h.sampleCount(), 1u);
  EXPECT_EQ(r.dropped_depth, 9u);
  EXPECT_EQ(r.accepted_per_level[0], 1u);
}

TEST(Hierarchy, TranslationByAMillionMetresChangesNothingWithMillimetreCells) {
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<std::int64_t> u(0, (std::int64_t(1) << 26) - 1);
  const std::size_t n = 3000;
  std::vector<double> a(3 * n), b(3 * n);
  const double offset[3] = {1e6, -1e6, 250000.0};  // whole multiples of the level-0 edge
  for (std::size_t i = 0; i < 3 * n; ++i) {
    a[i] = std::ldexp(static_cast<double>(u(rng)), -24);  // [0, 4) m on a 2^-24 lattice: a + offset is exact
    b[i] = a[i] + offset[i % 3];
  }
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  Hierarchy ha(1.0, 10), hb(1.0, 10);  // finest edge 2^-10 m ~ 0.98 mm
  const auto ra = insertAll(ha, a, order), rb = insertAll(hb, b, order);
  EXPECT_EQ(rb.out_of_range, 0u);
  ASSERT_EQ(ra.accepted.size(), rb.accepted.size());
  for (std::size_t i = 0; i < ra.accepted.size(); ++i) {
    ASSERT_EQ(ha.level(ra.accepted[i]), hb.level(rb.accepted[i]));
    for (int k = 0; k < 3; ++k) ASSERT_EQ(ha.position(ra.accepted[i])[k] + offset[k], hb.position(rb.accepted[i])[k]);
  }
  EXPECT_EQ(ra.dropped_depth, rb.dropped_depth);
}

TEST(Hierarchy, CoordinatesBeyondTheExactKeyRangeAreCountedNotInserted) {
  Hierarchy h(1.0, 21);
  std::vector<double> xyz = {1e7, 0, 0, 0.5, 0.5, 0.5, std::nan(""), 0, 0, INFINITY, 1, 1, -3e3, 1, 1};
  std::vector<std::uint32_t> order = {0, 1, 2, 3, 4};
  const auto r = insertAll(h, xyz, order);
  EXPECT_EQ(r.out_of_range, 4u);  // 1e7 and -3e3 m at 2^-21 m cells exceed 2^30 cells; NaN and Inf too
  EXPECT_EQ(h.sampleCount(), 1u);
}

TEST(Hierarchy, EvictionKeepsGridsConsistentAndLaterInsertionsPoisson) {
  std::mt19937_64 rng(5);
  Hierarchy h(1.0, 5);
  std::vector<std::array<double, 3>> kept_points;
  for (int b = 0; b < 4; ++b) {
    auto xyz = randomCloud(rng, 400, 3.0, false);
    for (std::size_t i = 0; i < xyz.size(); i += 3) xyz[i] += 2.0 * b;
    insertAll(h, xyz, shuffledOrder(400, rng), b);
    const double center[3] = {2.0 * b, 0, 0};
    h.evictOutside(center, 3.0);
    for (SampleId id = 0; id < h.idBound(); ++id)
      if (h.isLive(id)) {
        const double *p = h.position(id);
        ASSERT_LE(dist2(p, center), 9.0);
        ASSERT_EQ(h.sampleInCell(h.level(id), p), id);
      }
  }
  std::size_t per_level = 0;
  for (int d = 0; d <= h.maxDepth(); ++d) per_level += h.countAtLevel(d);
  EXPECT_EQ(per_level, h.sampleCount());
  expectGuarantees(h, {});  // coverage is not promised after eviction; spacing and cells are
  const double c[3] = {6, 0, 0};
  h.evictToCap(c, 100);
  EXPECT_EQ(h.sampleCount(), 100u);
  expectGuarantees(h, {});
}

// The cap keeps exactly the nearest samples: the farthest are evicted first, ties (equal distances, which points on
// a lattice around a lattice centre have by the hundred) by id. Against a ranking of every live sample.
TEST(Hierarchy, EvictionToTheCapRemovesTheFarthestByBruteForce) {
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 12; ++trial) {
    Hierarchy h(1.0, 4);
    std::vector<double> xyz;
    std::uniform_int_distribution<int> cell(-40, 40);
    for (int i = 0; i < 3000; ++i)  // lattice points 0.125 m apart: many share a distance to the lattice centre
      for (int a = 0; a < 3; ++a) xyz.push_back(0.125 * cell(rng) * (a == 2 ? 0.25 : 1.0));
    insertAll(h, xyz, shuffledOrder(3000, rng));
    const double center[3] = {0.125 * cell(rng), 0.125 * cell(rng), 0.0};
    std::vector<std::pair<double, SampleId>> ranked;
    for (SampleId id = 0; id < h.idBound(); ++id)
      if (h.isLive(id)) ranked.emplace_back(dist2(h.position(id), center), id);
    std::sort(ranked.begin(), ranked.end(),
              [](const auto &a, const auto &b) { return a.first != b.first ? a.first > b.first : a.second < b.second; });
    const std::size_t cap = trial == 0 ? 0 : std::uniform_int_distribution<std::size_t>(1, ranked.size())(rng);
    ASSERT_EQ(h.evictToCap(center, cap), ranked.size() - cap);
    std::set<SampleId> want, got;
    for (std::size_t i = ranked.size() - cap; i < ranked.size(); ++i) want.insert(ranked[i].second);
    for (SampleId id = 0; id < h.idBound(); ++id)
      if (h.isLive(id)) got.insert(id);
    ASSERT_EQ(got, want) << "trial " << trial << ", cap " << cap;
    EXPECT_EQ(h.evictToCap(center, cap), 0u);
  }
}

// Eviction by distance keeps a sample exactly at the distance ("farther than" is strict): lattice points around a
// lattice centre lie exactly on a 3-4-5 distance by the dozen, as quantised or gridded input has them.
// Against a scan of every live sample.
TEST(Hierarchy, EvictionByDistanceKeepsExactlyTheSamplesWithinByBruteForce) {
  std::mt19937_64 rng(13);
  for (int trial = 0; trial < 8; ++trial) {
    Hierarchy h(1.0, 4);  // r_4 < the lattice spacing: every lattice point becomes a sample
    std::vector<double> xyz;
    for (int x = -16; x <= 16; ++x)
      for (int y = -16; y <= 16; ++y)
        for (int z = -1; z <= 1; ++z) xyz.insert(xyz.end(), {0.125 * x, 0.125 * y, 0.125 * z});
    insertAll(h, xyz, shuffledOrder(xyz.size() / 3, rng));
    std::uniform_int_distribution<int> cell(-8, 8);
    const double center[3] = {0.125 * cell(rng), 0.125 * cell(rng), 0.0};
    const double distance = 0.625 * (1 + trial % 3);  // 5/8 m multiples: (3/8, 4/8) m offsets lie exactly on it
    std::set<SampleId> want;
    std::size_t on_sphere = 0;
    for (SampleId id = 0; id < h.idBound(); ++id)
      if (h.isLive(id)) {
        const double d2 = dist2(h.position(id), center);
        if (d2 <= distance * distance) want.insert(id);
        on_sphere += d2 == distance * distance ? 1 : 0;
      }
    ASSERT_GT(on_sphere, 0u) << "trial " << trial << ": no sample exactly at the distance, the case is not tested";
    const std::size_t live = h.sampleCount();
    ASSERT_EQ(h.evictOutside(center, distance), live - want.size());
    std::set<SampleId> got;
    for (SampleId id = 0; id < h.idBound(); ++id)
      if (h.isLive(id)) got.insert(id);
    ASSERT_EQ(got, want) << "trial " << trial << ", distance " << distance;
  }
}

TEST(Hierarchy, BallQueryMatchesBruteForce) {
  std::mt19937_64 rng(9);
  Hierarchy h(1.0, 6);
  const auto xyz = randomCloud(rng, 3000, 2.0, true);
  insertAll(h, xyz, shuffledOrder(3000, rng));
  std::uniform_real_distribution<double> u(-2, 2);
  for (int t = 0; t < 200; ++t) {
    const double q[3] = {u(rng), u(rng), 0.0};
    const double radius = 0.05 + 0.5 * std::abs(u(rng));
    const int max_level = t % 7;
    std::vector<SampleId> got;
    h.forEachInBall(q, radius, max_level, [&](SampleId id, double d2) {
      EXPECT_DOUBLE_EQ(d2, dist2(h.position(id), q));
      got.push_back(id);
    });
    std::vector<SampleId> want;
    for (SampleId id : h.samplesUpTo(max_level))
      if (dist2(h.position(id), q) < radius * radius) want.push_back(id);
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, want);
  }
}

// Far from the origin, on cell faces and with radii of whole cells: the window of blocks must not lose a cell to
// rounding. The grid is dense enough that the block walk (not the full scan) answers wide balls.
TEST(Hierarchy, BallQueryOnCellFacesFarFromTheOriginMatchesBruteForce) {
  std::mt19937_64 rng(21);
  Hierarchy h(1.0, 4);
  const double offset[3] = {1e5, -3e4, 7.0};
  auto xyz = randomCloud(rng, 20000, 4.0, true);
  for (std::size_t i = 0; i < xyz.size(); ++i) xyz[i] += offset[i % 3];
  insertAll(h, xyz, shuffledOrder(20000, rng));
  ASSERT_GT(h.countAtLevel(4), 2000u);
  std::uniform_int_distribution<int> cell(-60, 60), level(0, 4), cells(1, 24);
  std::uniform_real_distribution<double> u(-4.0, 4.0);
  const std::vector<SampleId> all = h.samplesUpTo(4);
  for (int t = 0; t < 400; ++t) {
    const int l = level(rng);
    const double e = h.edge(4);
    // Half the queries sit exactly on a face in x and y (a multiple of the finest edge, exact in a double).
    const double q[3] = {offset[0] + (t % 2 ? cell(rng) * e : u(rng)), offset[1] + (t % 2 ? cell(rng) * e : u(rng)),
                         offset[2] + (t % 4 == 1 ? 0.0 : 0.002 * u(rng))};
    const double whole = cells(rng) * e;
    const double radius = t % 3 == 0 ? whole : (t % 3 == 1 ? std::nextafter(whole, INFINITY) : whole * 0.7);
    std::vector<SampleId> got;
    h.forEachInBall(q, radius, l, [&](SampleId id, double d2) {
      EXPECT_EQ(d2, dist2(h.position(id), q));
      got.push_back(id);
    });
    std::vector<SampleId> want;
    for (SampleId id : all)
      if (h.level(id) <= l && dist2(h.position(id), q) < radius * radius) want.push_back(id);
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, want) << "query " << t << " level " << l << " radius " << radius;
  }
}

}  // namespace
}  // namespace hpds
