// FrameGridIndex: fixed-radius neighbour search over one frame's points, for the feature-sensitive orders and
// the map-mode output selection (Pipeline::samplesHitByLastFrame).
//
// Contract: built once per frame from a subset of point indices; cells of edge = radius, points bucketed by
// sorting their packed cell keys, then hashing the distinct keys (a few allocations per build, none per query).
// Keys address 2^21 cells per axis, from the points' minimum corner or, where they span more, a window centred on
// their median along that axis: points outside it (far outliers) have no neighbours and are nobody's. The hierarchy
// is not built yet when the order is computed, so this is the one search structure outside it. Const queries are
// thread-safe.
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

  /// True when some indexed point lies strictly within `radius` of `q` (any position, indexed or not). Reads the
  /// occupancy masks of the (one to eight) 8x8x8-cell groups around q first, so a q with no point nearby costs a
  /// lookup or two instead of 27, and skips neighbour cells whose nearest corner is a radius away; stops at the first
  /// point within the radius, q's own cell tried first.
  [[nodiscard]] bool anyWithin(const double q[3]) const;

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
  static constexpr std::uint32_t kNoCell = 0xFFFFFFFFu;
  /// Index of the cell with packed key `key` in keys_, or kNoCell.
  [[nodiscard]] std::uint32_t cellIndex(std::uint64_t key) const;
  bool range(std::uint64_t key, std::size_t &begin, std::size_t &end) const;
  /// The 512-bit occupancy mask (8 words; word z & 7, bit (x & 7) | (y & 7) << 3) of the group of cells with group
  /// key `group` (cell coordinates >> 3, packed), or nullptr when none of its cells holds a point.
  [[nodiscard]] const std::uint64_t *groupMask(std::uint64_t group) const;

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
  // Groups of 8x8x8 cells that hold points: the same kind of table, to their occupancy masks (8 words each).
  std::vector<std::uint64_t> group_keys_;
  std::vector<std::uint32_t> group_index_;
  std::vector<std::uint64_t> group_masks_;
  std::size_t group_mask_ = 0;
};

}  // namespace hpds
