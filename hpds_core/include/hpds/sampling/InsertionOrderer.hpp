// Insertion orders: the sequence in which a frame's points are offered to the hierarchy.
//
// Contract
// - Random: a Fisher-Yates shuffle driven by splitmix64(seed) -- the same on every platform and standard library.
//   From the last index i down to 1, index i is swapped with v % (i + 1), v the next splitmix64 draw (draws at or
//   above the largest multiple of i + 1 that fits 64 bits are redrawn). This is fixed: a seed gives the same order
//   in every version.
// - Input: the candidates as given.
// - Sphericity / SurfaceVariation (paper, section 6.2): local PCA of each point's neighbours within
//   `feature_radius` (metres); points sorted by the feature, descending, so coarse levels take feature points first.
//   Ties keep input order; points with fewer than 3 neighbours get feature 0.
// - Deterministic for the same input, seed and order, whatever the thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "hpds/config/Config.hpp"

namespace hpds {

/// Shuffles `indices` in place with a portable generator.
void seededShuffle(std::vector<std::uint32_t> &indices, std::uint64_t seed);

/// Per-candidate feature values (same length as `candidates`) for the feature orders.
[[nodiscard]] std::vector<float> localFeature(const double *xyz, const std::vector<std::uint32_t> &candidates,
                                              InsertionOrder kind, double feature_radius, int threads);

/// Returns `candidates` (point indices into xyz, 3 doubles each) in the configured order.
[[nodiscard]] std::vector<std::uint32_t> insertionOrder(const double *xyz, std::vector<std::uint32_t> candidates,
                                                        InsertionOrder kind, std::uint64_t seed, double feature_radius,
                                                        int threads);

}  // namespace hpds
