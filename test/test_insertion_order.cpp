// Insertion orders: the seeded random shuffle (uniform, a permutation, the contract's Fisher-Yates for every size)
// and the feature orders (descending by a brute-force feature, linear work on degenerate input, feature points in
// the coarse levels).
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <numeric>
#include <random>
#include <utility>
#include <vector>

#include "PipelineTestSupport.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/normals/LocalPca.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/sampling/InsertionOrderer.hpp"

namespace hpds {
namespace {

using test::smallLidar;

// Every order of a small set must come out equally often (a biased index draw or an off-by-one in the swap loop
// shows up as a skewed count).
TEST(InsertionOrder, RandomOrdersAreUniform) {
  std::map<std::vector<std::uint32_t>, int> seen;
  const int trials = 60000;
  for (int t = 0; t < trials; ++t) {
    std::vector<std::uint32_t> v = {0, 1, 2, 3};
    seededShuffle(v, 1000003ull * static_cast<std::uint64_t>(t) + 17);
    ++seen[v];
  }
  ASSERT_EQ(seen.size(), 24u);
  for (const auto &kv : seen) EXPECT_NEAR(kv.second, trials / 24.0, 0.08 * trials / 24.0);
}

TEST(InsertionOrder, RandomIsAPermutationAndSeedDependent) {
  std::vector<std::uint32_t> a(1000);
  std::iota(a.begin(), a.end(), 0u);
  auto b = a, c = a;
  seededShuffle(b, 7);
  seededShuffle(c, 7);
  EXPECT_EQ(b, c);
  seededShuffle(c, 8);
  EXPECT_NE(b, c);
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
}

// A seed's order is part of the output users reproduce: it must stay the textbook shuffle of the contract, drawn
// with a plain 64-bit remainder, on both sides of the division-free remainder's 4096 threshold.
TEST(InsertionOrder, RandomIsTheContractsFisherYatesForEverySize) {
  const auto reference = [](std::vector<std::uint32_t> v, std::uint64_t state) {
    const auto next = [&state] {
      std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      return z ^ (z >> 31);
    };
    for (std::size_t i = v.size(); i > 1; --i) {
      const std::uint64_t bound = i, limit = ~std::uint64_t(0) - (~std::uint64_t(0) % bound);
      std::uint64_t draw = next();
      while (draw >= limit) draw = next();
      std::swap(v[i - 1], v[draw % bound]);
    }
    return v;
  };
  for (const std::size_t n : {0u, 1u, 2u, 3u, 4095u, 4096u, 4097u, 70001u})
    for (const std::uint64_t seed : {0ull, 1ull, 0x9E3779B97F4A7C15ull, ~0ull}) {
      std::vector<std::uint32_t> v(n);
      std::iota(v.begin(), v.end(), 0u);
      const std::vector<std::uint32_t> expected = reference(v, seed);
      seededShuffle(v, seed);
      ASSERT_EQ(v, expected) << "n = " << n << ", seed = " << seed;
    }
}

TEST(InsertionOrder, FeatureOrdersSortDescendingByBruteForceFeature) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> xyz;
  for (int i = 0; i < 1500; ++i) {  // a plane with a bump and a pole: flat, curved and line-like neighbourhoods
    const double x = u(rng), y = u(rng);
    xyz.insert(xyz.end(), {x, y, 0.3 * std::exp(-10 * (x * x + y * y))});
  }
  for (int i = 0; i < 200; ++i) xyz.insert(xyz.end(), {0.5 + 0.01 * u(rng), 0.5 + 0.01 * u(rng), 1 + u(rng)});
  std::vector<std::uint32_t> all(xyz.size() / 3);
  std::iota(all.begin(), all.end(), 0u);
  const double radius = 0.15;
  for (InsertionOrder kind : {InsertionOrder::Sphericity, InsertionOrder::SurfaceVariation}) {
    const auto order = insertionOrder(xyz.data(), all, kind, 0, radius, 2);
    ASSERT_EQ(order.size(), all.size());
    std::vector<double> feature(all.size());
    for (std::uint32_t i : all) {
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      std::vector<Eigen::Vector3d> nb;
      for (std::uint32_t j : all) {
        const Eigen::Vector3d d(xyz[3 * j] - xyz[3 * i], xyz[3 * j + 1] - xyz[3 * i + 1], xyz[3 * j + 2] - xyz[3 * i + 2]);
        if (d.squaredNorm() < radius * radius) nb.push_back(d);
      }
      for (auto &d : nb) mean += d;
      mean /= static_cast<double>(nb.size());
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (auto &d : nb) cov += (d - mean) * (d - mean).transpose();
      const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov / nb.size()).eigenvalues().cwiseMax(0.0);
      feature[i] = nb.size() < 3 ? 0.0 : (kind == InsertionOrder::Sphericity ? ev(0) / ev(2) : ev(0) / ev.sum());
    }
    for (std::size_t k = 1; k < order.size(); ++k)
      ASSERT_GE(feature[order[k - 1]] + 1e-4, feature[order[k]]) << toString(kind) << " not descending at " << k;
  }
}

// Degenerate input keeps the feature orders linear: 100 000 coincident points (59 s before the cap) and a dense
// cluster under a radius that covers it all read at most 27 * kFeatureCellCap points per PCA; a dense plane keeps its
// features (the representatives are a fair sample); a frame without an overfull cell is computed exactly.
TEST(InsertionOrder, FeatureWorkStaysLinearOnDegenerateInput) {
  const std::size_t n = 100000;
  std::vector<double> same(3 * n, 1.5);
  std::vector<std::uint32_t> all(n);
  std::iota(all.begin(), all.end(), 0u);
  std::uint64_t read = 0;
  std::vector<float> f = localFeature(same.data(), all, InsertionOrder::Sphericity, 0.1, 2, &read);
  EXPECT_LE(read, n * 27 * kFeatureCellCap);
  for (float v : f) ASSERT_EQ(v, 0.0f) << "coincident points have no shape";

  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> plane;
  for (std::size_t i = 0; i < n; ++i) plane.insert(plane.end(), {u(rng), u(rng), 0.001 * u(rng)});
  for (const double radius : {0.2, 1e6}) {  // about a thousand points per cell, and everything in one cell
    SCOPED_TRACE(radius);
    f = localFeature(plane.data(), all, InsertionOrder::SurfaceVariation, radius, 2, &read);
    EXPECT_LE(read, n * 27 * kFeatureCellCap);
    // The exact surface variation of a plane 2 mm thick over 2 m (radius 1e6) or 20 cm: tiny either way.
    for (std::size_t i = 0; i < n; i += 997) EXPECT_LT(f[i], 2e-3) << i;
  }

  // Below the cap: exactly the brute-force PCA of every neighbour within the radius.
  std::vector<double> sparse;
  for (int i = 0; i < 2000; ++i) sparse.insert(sparse.end(), {u(rng), u(rng), 0.2 * u(rng) * u(rng)});
  std::vector<std::uint32_t> few(2000);
  std::iota(few.begin(), few.end(), 0u);
  const double radius = 0.2;
  f = localFeature(sparse.data(), few, InsertionOrder::Sphericity, radius, 1, &read);
  std::uint64_t expected_read = 0;
  for (std::uint32_t i : few) {
    PcaAccumulator acc(&sparse[3 * i]);
    for (std::uint32_t j : few) {
      const double dx = sparse[3 * j] - sparse[3 * i], dy = sparse[3 * j + 1] - sparse[3 * i + 1],
                   dz = sparse[3 * j + 2] - sparse[3 * i + 2];
      if (dx * dx + dy * dy + dz * dz < radius * radius) acc.add(&sparse[3 * j]);
    }
    expected_read += acc.count();
    const float exact = acc.count() < 3 ? 0.0f : static_cast<float>(acc.solve(false).sphericity());
    ASSERT_NEAR(f[i], exact, 1e-5) << i;
  }
  EXPECT_EQ(read, expected_read);
}

TEST(InsertionOrder, SphericityPutsFeaturePointsIntoCoarseLevels) {
  const SyntheticLidar lidar(smallLidar(SceneKind::CurvedObjects, 1));
  const Frame f = lidar.frame(0).frame;
  auto coarseMeanSphericity = [&](InsertionOrder order) {
    HpdsConfig c;
    c.order.type = order;
    c.output.level = 4;
    Pipeline p(c);
    p.addFrame(f);
    // Mean sphericity (same radius as the pipeline's default) of the samples of levels 0..2.
    std::vector<double> xyz;
    std::vector<std::uint32_t> idx;
    const PointLayout &l = f.points.layout();
    for (std::size_t i = 0; i < f.points.size(); ++i) {
      const double v[3] = {readAsDouble(f.points.record(i), *l.find("x")), readAsDouble(f.points.record(i), *l.find("y")),
                           readAsDouble(f.points.record(i), *l.find("z"))};
      if (v[0] == 0 && v[1] == 0 && v[2] == 0) continue;
      const Eigen::Vector3d w = f.sensor_to_fixed.linear() * Eigen::Vector3d(v[0], v[1], v[2]) + f.sensor_to_fixed.translation();
      idx.push_back(static_cast<std::uint32_t>(xyz.size() / 3));
      xyz.insert(xyz.end(), {w.x(), w.y(), w.z()});
    }
    const auto feat = localFeature(xyz.data(), idx, InsertionOrder::Sphericity, 2.0 * p.hierarchy().radius(4), 1);
    std::map<std::array<double, 3>, float> feature_at;
    for (std::size_t i = 0; i < idx.size(); ++i) feature_at[{xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}] = feat[i];
    double sum = 0.0;
    std::size_t n = 0;
    for (SampleId id : p.hierarchy().samplesUpTo(2)) {
      const double *q = p.hierarchy().position(id);
      sum += feature_at.at({q[0], q[1], q[2]});
      ++n;
    }
    return sum / static_cast<double>(n);
  };
  const double random_share = coarseMeanSphericity(InsertionOrder::Random);
  const double feature_share = coarseMeanSphericity(InsertionOrder::Sphericity);
  EXPECT_GT(feature_share, 2.0 * random_share) << "random " << random_share << " sphericity " << feature_share;
}

}  // namespace
}  // namespace hpds
