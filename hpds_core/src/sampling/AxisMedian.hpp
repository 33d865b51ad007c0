// Internal: the coordinate the bucket grids (BallGrid, FrameGridIndex) centre their 2^21-cell key window on when the
// data spans more than that, nearly always because of a far outlier or a few.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hpds {

/// The median along `axis` of the points whose three coordinates are finite, point i at xyz + 3 * index[i] (index
/// null: xyz + 3 * i), i < count; `fallback` when there is none. O(count); meant for that rare path only.
[[nodiscard]] inline double medianCoordinate(const double *xyz, const std::uint32_t *index, std::size_t count,
                                             int axis, double fallback) {
  std::vector<double> v;
  v.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    const double *p = xyz + 3 * std::size_t(index ? index[i] : i);
    if (std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])) v.push_back(p[axis]);
  }
  if (v.empty()) return fallback;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace hpds
