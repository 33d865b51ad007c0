#include "hpds/FrameGridIndex.hpp"

#include <algorithm>
#include <cmath>

#include "KeyRadixSort.hpp"

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
  // of `radius` and any query within `radius` of an indexed point has non-negative cells.
  if (!subset.empty()) {
    for (int a = 0; a < 3; ++a) origin_[a] = xyz[3 * std::size_t(subset[0]) + a];
    for (std::uint32_t i : subset)
      for (int a = 0; a < 3; ++a) origin_[a] = std::min(origin_[a], xyz[3 * std::size_t(i) + a]);
    for (double &o : origin_) o -= radius;
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
  // The last group looked up: q's 27 cells lie in one to eight groups, mostly one.
  std::uint64_t last_group = kEmptyKey;
  const std::uint64_t *last_mask = nullptr;
  auto hit = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    if (x < 0 || y < 0 || z < 0) return false;  // below the origin: no cell holds a point there
    const std::uint64_t group = pack(x >> 3, y >> 3, z >> 3);
    if (group != last_group) {
      last_group = group;
      last_mask = groupMask(group);
    }
    if (!last_mask || !((last_mask[z & 7] >> ((x & 7) | (y & 7) << 3)) & 1)) return false;
    const std::uint32_t c = cellIndex(pack(x, y, z));
    if (c == kNoCell) return false;
    for (std::size_t i = starts_[c]; i < starts_[c + 1]; ++i) {
      const double *p = xyz_ + 3 * std::size_t(points_[i]);
      const double ax = p[0] - q[0], ay = p[1] - q[1], az = p[2] - q[2];
      if (ax * ax + ay * ay + az * az < r2) return true;
    }
    return false;
  };
  if (hit(k[0], k[1], k[2])) return true;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz)
        if ((dx | dy | dz) != 0 && hit(k[0] + dx, k[1] + dy, k[2] + dz)) return true;
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
