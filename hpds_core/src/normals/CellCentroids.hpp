// Internal: the centroid of a frame's points per occupied cell of a world-anchored grid, the averaging points of the
// scan-mode normals (NormalParams::neighborhood_level_offset without building the finer levels). Not public API.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hpds {

/// Centroids of the points xyz[3 * indices[i] ..] (i < count) per occupied cell [k e, (k+1) e)^3 of edge `edge`,
/// 3 doubles each, in increasing cell order (x-major, z fastest), so the result depends on the point set and its
/// order only. Points with a non-finite coordinate are left out. Single-threaded; reads only its inputs. Linear
/// (radix sort) unless the points span 2^21 cells or more on some axis (~65 km at 3 cm): then a comparison sort.
/// `box`, when given: lo x y z, hi x y z of a box holding every kept point (a few cells wider than their extent), or
/// NaNs when there is none or the points span too many cells for the linear path. `interrupt`: read between the
/// passes (util/Interrupt.hpp; a second of them on millions of points).
[[nodiscard]] std::vector<double> cellCentroids(const double *xyz, const std::uint32_t *indices, std::size_t count,
                                                double edge, double *box = nullptr,
                                                const std::atomic<bool> *interrupt = nullptr);

}  // namespace hpds
