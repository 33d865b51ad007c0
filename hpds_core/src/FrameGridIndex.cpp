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
  int key_bits = 0;
  while (key_bits < 64 && (widest >> key_bits) != 0) ++key_bits;
  sortByKeyStable(keyed, key_bits);
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

bool FrameGridIndex::range(std::uint64_t key, std::size_t &begin, std::size_t &end) const {
  for (std::size_t slot = mix(key) & table_mask_;; slot = (slot + 1) & table_mask_) {
    const std::uint64_t k = table_keys_[slot];
    if (k == kEmptyKey) return false;
    if (k == key) {
      const std::uint32_t i = table_index_[slot];
      begin = starts_[i];
      end = starts_[i + 1];
      return true;
    }
  }
}

}  // namespace hpds
