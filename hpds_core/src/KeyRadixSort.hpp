// Internal: a stable radix sort of (key, index) records, shared by the bucket grids (BallGrid, FrameGridIndex).
#pragma once

#include <cstdint>
#include <vector>

namespace hpds {

struct KeyedIndex {
  std::uint64_t key;
  std::uint32_t index;
};

/// Sorts `v` by key, keeping the order of equal keys (records given by ascending index come out by (key, index)):
/// LSD passes of at most 11 bits over the low `key_bits` bits of the key (higher bits must be zero). A pass whose
/// digit is the same everywhere moves nothing and is skipped. Linear in v.size(); one scratch array.
void sortByKeyStable(std::vector<KeyedIndex> &v, int key_bits);

}  // namespace hpds
