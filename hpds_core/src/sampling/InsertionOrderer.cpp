#include "hpds/sampling/InsertionOrderer.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "hpds/sampling/FrameGridIndex.hpp"
#include "hpds/normals/LocalPca.hpp"
#include "hpds/util/ParallelFor.hpp"
#include "hpds/util/SplitMix64.hpp"

namespace hpds {

namespace {
/// v % b for 2^12 <= b < 2^32, without the 64-bit integer divide, which was half of a shuffle's time (0.87 -> 0.45 ms
/// for 69 k indices). A quotient estimated in floating point is corrected in exact integer arithmetic: the loops
/// make the result exact whatever the estimate; the estimate (v's top 53 bits, b >= 2^12) only keeps them to a step
/// or two.
__extension__ typedef unsigned __int128 Uint128;  // GCC/Clang; __extension__ keeps -Wpedantic quiet
std::uint64_t remainderOf(std::uint64_t v, std::uint64_t b) {
  std::uint64_t q = static_cast<std::uint64_t>(static_cast<double>(v >> 11) * (2048.0 / static_cast<double>(b)));
  Uint128 qb = static_cast<Uint128>(q) * b;
  while (qb > v) qb -= b;
  std::uint64_t r = v - static_cast<std::uint64_t>(qb);
  while (r >= b) r -= b;
  return r;
}
/// Unbiased integer in [0, bound) by rejection: draws at or above the largest multiple of bound are redrawn.
/// That multiple is at least 2^64 - bound, so it is only computed (a second division) for a draw that high.
/// The value is v % bound for every bound (remainderOf is exact): the order of a seed is fixed by the contract.
std::uint64_t below(std::uint64_t &state, std::uint64_t bound) {
  std::uint64_t v = splitMix64(state);
  if (v >= std::uint64_t(0) - bound) {
    const std::uint64_t limit = ~std::uint64_t(0) - (~std::uint64_t(0) % bound);
    while (v >= limit) v = splitMix64(state);
  }
  if (bound < 4096 || bound > 0xFFFFFFFFu) return v % bound;
  return remainderOf(v, bound);
}
}  // namespace

void seededShuffle(std::vector<std::uint32_t> &indices, std::uint64_t seed) {
  std::uint64_t state = seed;
  for (std::size_t i = indices.size(); i > 1; --i) std::swap(indices[i - 1], indices[below(state, i)]);
}

namespace {

// The points that stand for `candidates` in the neighbour search (see the contract), with their weights (indexed by
// point); empty when no cell exceeds the cap, i.e. every candidate stands for itself.
struct Representatives {
  std::vector<std::uint32_t> points;
  std::vector<std::uint32_t> weight;
};

Representatives representatives(const double *xyz, const std::vector<std::uint32_t> &candidates, double radius) {
  struct Keyed {
    std::int64_t k[3];
    std::uint32_t index;
  };
  std::vector<Keyed> keyed;
  keyed.reserve(candidates.size());
  for (std::uint32_t i : candidates) {
    Keyed e{{0, 0, 0}, i};
    for (int a = 0; a < 3; ++a) {
      // Beyond +-2^52 cells a cell key is no longer exact; such far points are their own cell (FrameGridIndex
      // gives them no neighbours anyway).
      const double c = std::floor(xyz[3 * std::size_t(i) + a] / radius);
      e.k[a] = std::isfinite(c) && std::abs(c) < 4.5e15 ? static_cast<std::int64_t>(c) : std::int64_t(i) + (1ll << 60);
    }
    keyed.push_back(e);
  }
  std::sort(keyed.begin(), keyed.end(), [](const Keyed &a, const Keyed &b) {
    if (a.k[0] != b.k[0]) return a.k[0] < b.k[0];
    if (a.k[1] != b.k[1]) return a.k[1] < b.k[1];
    if (a.k[2] != b.k[2]) return a.k[2] < b.k[2];
    return a.index < b.index;
  });
  Representatives r;
  bool capped = false;
  std::uint32_t max_index = 0;
  for (std::uint32_t i : candidates) max_index = std::max(max_index, i);
  for (std::size_t begin = 0, end; begin < keyed.size(); begin = end) {
    for (end = begin + 1; end < keyed.size() && std::equal(keyed[end].k, keyed[end].k + 3, keyed[begin].k); ++end) {
    }
    const std::size_t n = end - begin;
    const std::size_t stride = n > kFeatureCellCap ? (n + kFeatureCellCap - 1) / kFeatureCellCap : 1;
    if (stride > 1 && !capped) {
      capped = true;
      r.weight.assign(std::size_t(max_index) + 1, 1);
      for (std::size_t j = 0; j < begin; ++j) r.points.push_back(keyed[j].index);
    }
    if (!capped) continue;
    for (std::size_t j = begin; j < end; j += stride) {
      r.points.push_back(keyed[j].index);
      r.weight[keyed[j].index] = static_cast<std::uint32_t>(std::min(stride, end - j));
    }
  }
  if (capped) std::sort(r.points.begin(), r.points.end());
  return r;
}

}  // namespace

std::vector<float> localFeature(const double *xyz, const std::vector<std::uint32_t> &candidates, InsertionOrder kind,
                                double feature_radius, int threads, std::uint64_t *neighbours_read) {
  if (!(feature_radius > 0.0)) throw std::invalid_argument("order.feature_radius: must be > 0 for feature orders");
  std::vector<float> feature(candidates.size(), 0.0f);
  const Representatives reps = representatives(xyz, candidates, feature_radius);
  const bool capped = !reps.points.empty();
  const FrameGridIndex index(xyz, capped ? reps.points : candidates, feature_radius);
  std::atomic<std::uint64_t> read{0};
  parallelFor(candidates.size(), threads, [&](std::size_t b, std::size_t e) {
    std::uint64_t visited = 0;
    for (std::size_t i = b; i < e; ++i) {
      PcaAccumulator acc(xyz + 3 * std::size_t(candidates[i]));
      if (capped) {
        index.forEachNeighbor(candidates[i], [&](std::uint32_t j) {
          acc.add(xyz + 3 * std::size_t(j), reps.weight[j]);
          ++visited;
        });
      } else {
        index.forEachNeighbor(candidates[i], [&](std::uint32_t j) { acc.add(xyz + 3 * std::size_t(j)); });
        visited += acc.count();
      }
      if (acc.count() < 3) continue;
      const LocalPca pca = acc.solve(/*accurate=*/false);
      feature[i] = static_cast<float>(kind == InsertionOrder::Sphericity ? pca.sphericity() : pca.surfaceVariation());
    }
    read += visited;
  });
  if (neighbours_read) *neighbours_read = read;
  return feature;
}

std::vector<std::uint32_t> insertionOrder(const double *xyz, std::vector<std::uint32_t> candidates,
                                          InsertionOrder kind, std::uint64_t seed, double feature_radius,
                                          int threads) {
  switch (kind) {
    case InsertionOrder::Input:
      return candidates;
    case InsertionOrder::Random:
      seededShuffle(candidates, seed);
      return candidates;
    case InsertionOrder::Sphericity:
    case InsertionOrder::SurfaceVariation: {
      const std::vector<float> f = localFeature(xyz, candidates, kind, feature_radius, threads);
      std::vector<std::uint32_t> rank(candidates.size());
      std::iota(rank.begin(), rank.end(), 0u);
      std::stable_sort(rank.begin(), rank.end(), [&](std::uint32_t a, std::uint32_t b) { return f[a] > f[b]; });
      std::vector<std::uint32_t> out(candidates.size());
      for (std::size_t i = 0; i < rank.size(); ++i) out[i] = candidates[rank[i]];
      return out;
    }
  }
  return candidates;
}

}  // namespace hpds
