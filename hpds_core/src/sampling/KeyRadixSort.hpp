// Internal: the stable radix sort of the bucket grids (BallGrid, FrameGridIndex).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace hpds {

/// Bits needed to write v (0 for 0).
[[nodiscard]] inline int bitWidth(std::uint64_t v) {
  int b = 0;
  while (v) ++b, v >>= 1;
  return b;
}

/// Sorts `v` by keyOf(element), keeping the order of equal keys: LSD passes of at most 11 bits over the low
/// `key_bits` bits of the key (higher bits must be zero). A pass whose digit is the same everywhere moves nothing
/// and is skipped. Linear in v.size(); one scratch array.
template <typename T, typename KeyOf>
void sortByKeyStable(std::vector<T> &v, int key_bits, KeyOf &&keyOf) {
  const std::size_t n = v.size();
  if (n < 2 || key_bits <= 0) return;
  const int passes = (key_bits + 10) / 11, width = (key_bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << width;
  std::vector<std::uint32_t> count(buckets * static_cast<std::size_t>(passes), 0);
  for (const T &x : v)
    for (int p = 0; p < passes; ++p) ++count[static_cast<std::size_t>(p) * buckets + ((keyOf(x) >> (p * width)) & (buckets - 1))];
  std::vector<T> tmp(n);
  for (int p = 0; p < passes; ++p) {
    std::uint32_t *c = &count[static_cast<std::size_t>(p) * buckets];
    if (*std::max_element(c, c + buckets) == n) continue;
    std::uint32_t sum = 0;
    for (std::size_t b = 0; b < buckets; ++b) sum += std::exchange(c[b], sum);
    for (const T &x : v) tmp[c[(keyOf(x) >> (p * width)) & (buckets - 1)]++] = x;
    v.swap(tmp);
  }
}

/// A key wider than 32 bits and the index of the element it belongs to.
struct KeyedIndex {
  std::uint64_t key;
  std::uint32_t index;
};

/// sortByKeyStable over KeyedIndex records: given by ascending index, they come out by (key, index).
inline void sortByKeyStable(std::vector<KeyedIndex> &v, int key_bits) {
  sortByKeyStable(v, key_bits, [](const KeyedIndex &x) { return x.key; });
}

}  // namespace hpds
