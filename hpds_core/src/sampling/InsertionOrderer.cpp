#include "hpds/sampling/InsertionOrderer.hpp"

#include <algorithm>
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

std::vector<float> localFeature(const double *xyz, const std::vector<std::uint32_t> &candidates, InsertionOrder kind,
                                double feature_radius, int threads) {
  if (!(feature_radius > 0.0)) throw std::invalid_argument("order.feature_radius: must be > 0 for feature orders");
  std::vector<float> feature(candidates.size(), 0.0f);
  const FrameGridIndex index(xyz, candidates, feature_radius);
  parallelFor(candidates.size(), threads, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      PcaAccumulator acc(xyz + 3 * std::size_t(candidates[i]));
      index.forEachNeighbor(candidates[i], [&](std::uint32_t j) { acc.add(xyz + 3 * std::size_t(j)); });
      if (acc.count() < 3) continue;
      const LocalPca pca = acc.solve(/*accurate=*/false);
      feature[i] = static_cast<float>(kind == InsertionOrder::Sphericity ? pca.sphericity() : pca.surfaceVariation());
    }
  });
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
