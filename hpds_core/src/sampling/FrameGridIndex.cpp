#include "hpds/sampling/FrameGridIndex.hpp"

#include <algorithm>
#include <cmath>

#include "sampling/AxisMedian.hpp"
#include "sampling/KeyRadixSort.hpp"

namespace hpds {

namespace {
constexpr std::int64_t kAxisBits = 21;
constexpr std::int64_t kAxisMax = (std::int64_t(1) << kAxisBits) - 2;  // keeps k+1 inside 21 bits
// Packed keys use 63 bits, so the all-ones word never names a cell.
constexpr std::uint64_t kEmptyKey = ~std::uint64_t(0);
std::uint64_t mix(std::uint64_t k) {
  k ^= k >> 33;
  k *= 0xFF51AFD7ED558CCDull;
  k ^= k >> 33;
  return k;
}
}  // namespace

FrameGridIndex::FrameGridIndex(const double *xyz, const std::vector<std::uint32_t> &subset, double radius)
    : xyz_(xyz), radius_(radius), inv_(1.0 / radius) {
  // Cells are counted from one radius below the points' minimum corner, so that 21 bits per axis cover 2M cells
  // of `radius` and any query within `radius` of an indexed point has non-negative cells. Where the points span
  // more than that (nearly always a far outlier or a few, such as a glitched return 2 000 km out), counting from
  // the corner would leave the frame's bulk without a cell: the window is centred on the points' median along that
  // axis instead, and what lies beyond it, alone within the radius anyway, has no neighbours.
  if (!subset.empty()) {
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = xyz[3 * std::size_t(subset[0]) + a];
    for (std::uint32_t i : subset)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], xyz[3 * std::size_t(i) + a]);
        hi[a] = std::max(hi[a], xyz[3 * std::size_t(i) + a]);
      }
    for (int a = 0; a < 3; ++a) {
      origin_[a] = lo[a] - radius;
      if (!((hi[a] - lo[a]) * inv_ + 2.0 < static_cast<double>(kAxisMax))) {
        const double median = medianCoordinate(xyz, subset.data(), subset.size(), a, NAN);
        if (std::isfinite(median)) origin_[a] = median - 0.5 * static_cast<double>(kAxisMax) * radius;
      }
    }
  }
  // Points by (cell key, index). A frame's candidates come in ascending index order, so a stable radix sort by key
  // gives that order (a comparison sort of the pairs was a third of a map-mode frame's output selection); any
  // other subset is put in index order first.
  std::vector<KeyedIndex> keyed;
  keyed.reserve(subset.size());
  std::uint64_t widest = 0;
  for (std::uint32_t i : subset) {
    std::int64_t k[3];
    if (!cellOf(xyz + 3 * std::size_t(i), k)) continue;
    keyed.push_back(KeyedIndex{pack(k[0], k[1], k[2]), i});
    widest |= keyed.back().key;
  }
  if (!std::is_sorted(subset.begin(), subset.end()))
    std::sort(keyed.begin(), keyed.end(), [](const KeyedIndex &a, const KeyedIndex &b) { return a.index < b.index; });
  sortByKeyStable(keyed, bitWidth(widest));
  points_.reserve(keyed.size());
  for (std::size_t i = 0; i < keyed.size(); ++i) {
    if (i == 0 || keyed[i].key != keyed[i - 1].key) {
      keys_.push_back(keyed[i].key);
      starts_.push_back(static_cast<std::uint32_t>(i));
    }
    points_.push_back(keyed[i].index);
  }
  starts_.push_back(static_cast<std::uint32_t>(keyed.size()));
  std::size_t cap = 16;
  while (cap < 2 * keys_.size()) cap *= 2;
  table_mask_ = cap - 1;
  table_keys_.assign(cap, kEmptyKey);
  table_index_.assign(cap, 0);
  for (std::size_t i = 0; i < keys_.size(); ++i) {
    std::size_t slot = mix(keys_[i]) & table_mask_;
    while (table_keys_[slot] != kEmptyKey) slot = (slot + 1) & table_mask_;
    table_keys_[slot] = keys_[i];
    table_index_[slot] = static_cast<std::uint32_t>(i);
  }
  // Occupancy of 8x8x8-cell groups. keys_ ascends in x, then y, then z, so a group's cells are not adjacent in it:
  // each cell finds (or opens) its group in the table.
  const std::uint64_t m = (std::uint64_t(1) << kAxisBits) - 1;
  std::size_t gcap = 16;
  while (gcap < 2 * keys_.size()) gcap *= 2;  // at most one group per cell: at most half full
  group_mask_ = gcap - 1;
  group_keys_.assign(gcap, kEmptyKey);
  group_index_.assign(gcap, 0);
  std::size_t groups = 0;
  for (const std::uint64_t key : keys_) {
    const std::uint64_t x = (key >> (2 * kAxisBits)) & m, y = (key >> kAxisBits) & m, z = key & m;
    const std::uint64_t group = pack(static_cast<std::int64_t>(x >> 3), static_cast<std::int64_t>(y >> 3),
                                     static_cast<std::int64_t>(z >> 3));
    std::size_t slot = mix(group) & group_mask_;
    while (group_keys_[slot] != kEmptyKey && group_keys_[slot] != group) slot = (slot + 1) & group_mask_;
    if (group_keys_[slot] == kEmptyKey) {
      group_keys_[slot] = group;
      group_index_[slot] = static_cast<std::uint32_t>(groups++);
      group_masks_.resize(8 * groups, 0);
    }
    group_masks_[8 * std::size_t(group_index_[slot]) + (z & 7)] |= std::uint64_t(1) << ((x & 7) | (y & 7) << 3);
  }
}

const std::uint64_t *FrameGridIndex::groupMask(std::uint64_t group) const {
  for (std::size_t slot = mix(group) & group_mask_;; slot = (slot + 1) & group_mask_) {
    const std::uint64_t k = group_keys_[slot];
    if (k == kEmptyKey) return nullptr;
    if (k == group) return &group_masks_[8 * std::size_t(group_index_[slot])];
  }
}

bool FrameGridIndex::anyWithin(const double q[3]) const {
  std::int64_t k[3];
  if (!cellOf(q, k) || keys_.empty()) return false;
  const double r2 = radius_ * radius_;
  const auto cellHasPointWithin = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    const std::uint32_t c = cellIndex(pack(x, y, z));
    if (c == kNoCell) return false;
    for (std::size_t i = starts_[c]; i < starts_[c + 1]; ++i) {
      const double *p = xyz_ + 3 * std::size_t(points_[i]);
      const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
      if (ax * ax + ay * ay + az * az < r2) return true;
    }
    return false;
  };
  // q's own cell first: most hits are there.
  const std::uint64_t own_group = pack(k[0] >> 3, k[1] >> 3, k[2] >> 3);
  const std::uint64_t *own_mask = groupMask(own_group);
  const std::uint64_t own_bit = std::uint64_t(1) << ((k[0] & 7) | (k[1] & 7) << 3);
  if (own_mask && (own_mask[k[2] & 7] & own_bit) && cellHasPointWithin(k[0], k[1], k[2])) return true;
  // q's offset inside its cell, in cells: a neighbour cell whose nearest face (edge, corner) is a radius or more away
  // cannot hold a point strictly within it, and is neither looked up nor tested. The offsets carry at most ~1e-9 cells
  // of rounding (2^21 cells per axis), so a margin of 1e-6 never prunes a cell that the exact test would accept.
  double lower[3], upper[3];
  for (int a = 0; a < 3; ++a) {
    lower[a] = (q[a] - origin_[a]) * inv_ - static_cast<double>(k[a]);
    upper[a] = 1.0 - lower[a];
    lower[a] *= lower[a];
    upper[a] *= upper[a];
  }
  // Then the other 26, a group at a time: the group's occupancy words under the window, so that empty neighbours
  // cost nothing and a q with no point nearby costs a lookup or two. Cells below the origin hold no point.
  std::int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max<std::int64_t>(k[a] - 1, 0);
    hi[a] = k[a] + 1;
  }
  for (std::int64_t gz = lo[2] >> 3; gz <= hi[2] >> 3; ++gz)
    for (std::int64_t gy = lo[1] >> 3; gy <= hi[1] >> 3; ++gy)
      for (std::int64_t gx = lo[0] >> 3; gx <= hi[0] >> 3; ++gx) {
        const std::uint64_t group = pack(gx, gy, gz);
        const std::uint64_t *mask = group == own_group ? own_mask : groupMask(group);
        if (!mask) continue;
        const std::int64_t x0 = std::max(lo[0] - 8 * gx, std::int64_t(0)), x1 = std::min(hi[0] - 8 * gx, std::int64_t(7));
        const std::int64_t y0 = std::max(lo[1] - 8 * gy, std::int64_t(0)), y1 = std::min(hi[1] - 8 * gy, std::int64_t(7));
        const std::int64_t z0 = std::max(lo[2] - 8 * gz, std::int64_t(0)), z1 = std::min(hi[2] - 8 * gz, std::int64_t(7));
        // Bit (x | y << 3): x0..x1 in every row of eight, rows y0..y1.
        const std::uint64_t row = ((std::uint64_t(2) << x1) - (std::uint64_t(1) << x0)) * 0x0101010101010101ull;
        const std::uint64_t rows = (y1 == 7 ? ~std::uint64_t(0) : (std::uint64_t(1) << (8 * (y1 + 1))) - 1) &
                                   ~((std::uint64_t(1) << (8 * y0)) - 1);
        for (std::int64_t z = z0; z <= z1; ++z) {
          std::uint64_t bits = mask[z] & row & rows;
          const std::int64_t cz = 8 * gz + z;
          if (group == own_group && cz == k[2]) bits &= ~own_bit;
          for (; bits != 0; bits &= bits - 1) {
            const unsigned b = static_cast<unsigned>(__builtin_ctzll(bits));
            const std::int64_t cx = 8 * gx + (b & 7), cy = 8 * gy + (b >> 3);
            const double gap = (cx < k[0] ? lower[0] : cx > k[0] ? upper[0] : 0.0) +
                               (cy < k[1] ? lower[1] : cy > k[1] ? upper[1] : 0.0) +
                               (cz < k[2] ? lower[2] : cz > k[2] ? upper[2] : 0.0);
            if (gap >= 1.0 + 1e-6) continue;
            if (cellHasPointWithin(cx, cy, cz)) return true;
          }
        }
      }
  return false;
}

bool FrameGridIndex::cellOf(const double *p, std::int64_t k[3]) const {
  for (int a = 0; a < 3; ++a) {
    const double c = std::floor((p[a] - origin_[a]) * inv_);
    if (!(c >= 0.0 && c <= static_cast<double>(kAxisMax))) return false;  // far outliers: no neighbours
    k[a] = static_cast<std::int64_t>(c);
  }
  return true;
}

std::uint64_t FrameGridIndex::pack(std::int64_t x, std::int64_t y, std::int64_t z) {
  // -1 wraps to the all-ones pattern, which no real cell uses (kAxisMax < 2^21 - 1).
  const std::uint64_t m = (std::uint64_t(1) << kAxisBits) - 1;
  return ((static_cast<std::uint64_t>(x) & m) << (2 * kAxisBits)) | ((static_cast<std::uint64_t>(y) & m) << kAxisBits) |
         (static_cast<std::uint64_t>(z) & m);
}

std::uint32_t FrameGridIndex::cellIndex(std::uint64_t key) const {
  for (std::size_t slot = mix(key) & table_mask_;; slot = (slot + 1) & table_mask_) {
    const std::uint64_t k = table_keys_[slot];
    if (k == kEmptyKey) return kNoCell;
    if (k == key) return table_index_[slot];
  }
}

bool FrameGridIndex::range(std::uint64_t key, std::size_t &begin, std::size_t &end) const {
  const std::uint32_t i = cellIndex(key);
  if (i == kNoCell) return false;
  begin = starts_[i];
  end = starts_[i + 1];
  return true;
}

}  // namespace hpds
