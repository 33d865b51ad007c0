// Helper shared by the normal and covariance tests: a hierarchy built from a point list in a seeded random order.
#pragma once

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

#include "hpds/sampling/Hierarchy.hpp"

namespace hpds::test {

/// Levels 0..max_depth of `xyz` (3 doubles per point) inserted in a shuffle seeded with `seed`, all seen from
/// `viewpoint` (normals are oriented toward it).
inline Hierarchy buildShuffled(const std::vector<double> &xyz, double cell_size, int max_depth, unsigned seed,
                               const double (&viewpoint)[3]) {
  Hierarchy h(cell_size, max_depth);
  std::vector<std::uint32_t> order(xyz.size() / 3);
  std::iota(order.begin(), order.end(), 0u);
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  InsertBatch b;
  b.xyz = xyz.data();
  b.size = xyz.size() / 3;
  b.order = order.data();
  b.order_size = order.size();
  std::copy(viewpoint, viewpoint + 3, b.viewpoint);
  (void)h.insert(b);
  return h;
}

}  // namespace hpds::test
