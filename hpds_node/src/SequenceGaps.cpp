#include "hpds_node/SequenceGaps.hpp"

namespace hpds_node {

std::uint64_t SequenceGaps::observe(const std::string &publisher, std::uint32_t seq) {
  const auto [it, first] = last_.try_emplace(publisher, seq);
  if (first) return 0;
  const std::uint32_t previous = it->second;
  it->second = seq;
  // Unsigned difference: wraps around 2^32 correctly; a step of half the range or more is a seq that went back.
  const std::uint32_t step = seq - previous;
  if (step == 0 || step >= 0x80000000u) return 0;
  return step - 1;
}

}  // namespace hpds_node
