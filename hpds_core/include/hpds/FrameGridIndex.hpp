// FrameGridIndex: fixed-radius neighbour search over one frame's points, for the feature-sensitive orders and
// the map-mode output selection (Pipeline::samplesHitByLastFrame).
//
// Contract: built once per frame from a subset of point indices; cells of edge = radius, points bucketed by
// sorting their packed cell keys, then hashing the distinct keys (a few allocations per build, none per query). The hierarchy is not built yet when
// the order is computed, so this is the one search structure outside it. Const queries are thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace hpds {

class FrameGridIndex {
 public:
  /// `xyz`: 3 doubles per point (kept by pointer, must outlive the index); `subset`: the indices to index.
  FrameGridIndex(const double *xyz, const std::vector<std::uint32_t> &subset, double radius);

  /// Calls fn(point_index) for every indexed point strictly within `radius` of point `center` (itself included).
  template <typename Fn>
  void forEachNeighbor(std::uint32_t center, Fn &&fn) const {
    forEachWithin(xyz_ + 3 * std::size_t(center), fn);
  }

  /// True when some indexed point lies strictly within `radius` of `q` (any position, indexed or not). Stops at the
  /// first such point, looking in q's own cell first (where one most often is).
  [[nodiscard]] bool anyWithin(const double q[3]) const {
    std::int64_t k[3];
    if (!cellOf(q, k)) return false;
    const double r2 = radius_ * radius_;
    auto inCell = [&](std::int64_t dx, std::int64_t dy, std::int64_t dz) {
      std::size_t b, e;
      if (!range(pack(k[0] + dx, k[1] + dy, k[2] + dz), b, e)) return false;
      for (std::size_t i = b; i < e; ++i) {
        const double *p = xyz_ + 3 * std::size_t(points_[i]);
        const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
        if (ax * ax + ay * ay + az * az < r2) return true;
      }
      return false;
    };
    if (inCell(0, 0, 0)) return true;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz)
          if ((dx | dy | dz) != 0 && inCell(dx, dy, dz)) return true;
    return false;
  }

  /// Calls fn(point_index) for every indexed point strictly within `radius` of `q`.
  template <typename Fn>
  void forEachWithin(const double q[3], Fn &&fn) const {
    std::int64_t k[3];
    if (!cellOf(q, k)) return;
    const double r2 = radius_ * radius_;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          std::size_t b, e;
          if (!range(pack(k[0] + dx, k[1] + dy, k[2] + dz), b, e)) continue;
          for (std::size_t i = b; i < e; ++i) {
            const double *p = xyz_ + 3 * std::size_t(points_[i]);
            const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
            if (ax * ax + ay * ay + az * az < r2) fn(points_[i]);
          }
        }
  }

 private:
  bool cellOf(const double *p, std::int64_t k[3]) const;
  static std::uint64_t pack(std::int64_t x, std::int64_t y, std::int64_t z);
  bool range(std::uint64_t key, std::size_t &begin, std::size_t &end) const;

  const double *xyz_;
  double radius_, inv_;
  double origin_[3] = {0, 0, 0};
  std::vector<std::uint32_t> points_;  // sorted by cell key
  std::vector<std::uint64_t> keys_;    // distinct cell keys, ascending
  std::vector<std::uint32_t> starts_;  // keys_[i]'s points are points_[starts_[i] .. starts_[i+1])
  // Open-addressing table key -> i (linear probing, half load): a lookup is a hash and a probe or two, where a
  // binary search over keys_ cost a dozen unpredictable branches per cell.
  std::vector<std::uint64_t> table_keys_;
  std::vector<std::uint32_t> table_index_;
  std::size_t table_mask_ = 0;
};

}  // namespace hpds
