#include "KeyRadixSort.hpp"

#include <algorithm>
#include <cstddef>
#include <utility>

namespace hpds {

void sortByKeyStable(std::vector<KeyedIndex> &v, int key_bits) {
  const std::size_t n = v.size();
  if (n < 2 || key_bits <= 0) return;
  const int passes = (key_bits + 10) / 11, width = (key_bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << width;
  std::vector<std::uint32_t> count(buckets * static_cast<std::size_t>(passes), 0);
  for (const KeyedIndex &x : v)
    for (int p = 0; p < passes; ++p) ++count[static_cast<std::size_t>(p) * buckets + ((x.key >> (p * width)) & (buckets - 1))];
  std::vector<KeyedIndex> tmp(n);
  for (int p = 0; p < passes; ++p) {
    std::uint32_t *c = &count[static_cast<std::size_t>(p) * buckets];
    if (*std::max_element(c, c + buckets) == n) continue;
    std::uint32_t sum = 0;
    for (std::size_t b = 0; b < buckets; ++b) sum += std::exchange(c[b], sum);
    for (const KeyedIndex &x : v) tmp[c[(x.key >> (p * width)) & (buckets - 1)]++] = x;
    v.swap(tmp);
  }
}

}  // namespace hpds
