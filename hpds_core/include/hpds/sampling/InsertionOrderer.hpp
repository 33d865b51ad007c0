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
//   The work stays linear in the frame however dense it is (coincident points, a huge radius): a grid cell (edge
//   feature_radius) of more than kFeatureCellCap points takes part through kFeatureCellCap representatives, every
//   s-th of its points in index order standing for s points (weights in the PCA sums), so a PCA reads at most
//   27 * kFeatureCellCap points. Frames without such a cell get the exact feature.
// - Deterministic for the same input, seed and order, whatever the thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "hpds/config/Config.hpp"

namespace hpds {

/// Shuffles `indices` in place with a portable generator.
void seededShuffle(std::vector<std::uint32_t> &indices, std::uint64_t seed);

/// Points of one feature cell beyond which the cell is represented (see contract).
inline constexpr std::size_t kFeatureCellCap = 128;

/// Per-candidate feature values (same length as `candidates`) for the feature orders. With `neighbours_read`, the
/// number of points the PCAs read in total (a representative once) is stored there: the work done.
[[nodiscard]] std::vector<float> localFeature(const double *xyz, const std::vector<std::uint32_t> &candidates,
                                              InsertionOrder kind, double feature_radius, int threads,
                                              std::uint64_t *neighbours_read = nullptr);

/// Returns `candidates` (point indices into xyz, 3 doubles each) in the configured order.
[[nodiscard]] std::vector<std::uint32_t> insertionOrder(const double *xyz, std::vector<std::uint32_t> candidates,
                                                        InsertionOrder kind, std::uint64_t seed, double feature_radius,
                                                        int threads);

}  // namespace hpds
