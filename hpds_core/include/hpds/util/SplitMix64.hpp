// SplitMix64 (Steele, Lea & Flood, 2014): the one portable generator behind every seeded random choice in hpds
// (insertion order, synthetic scenes, baselines), so that a seed gives the same result on every platform and
// standard library (std::uniform_int_distribution and friends are implementation-defined).
#pragma once

#include <cstdint>

namespace hpds {

inline constexpr std::uint64_t kSplitMix64Increment = 0x9E3779B97F4A7C15ull;

/// The SplitMix64 output function: a bijective 64-bit mix with good avalanche.
[[nodiscard]] constexpr std::uint64_t splitMix64Mix(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/// Advances `state` and returns the next value of the sequence.
[[nodiscard]] constexpr std::uint64_t splitMix64(std::uint64_t &state) {
  return splitMix64Mix(state += kSplitMix64Increment);
}

/// A double uniform in [0, 1) from the top 53 bits of `bits`.
[[nodiscard]] constexpr double unitInterval(std::uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

}  // namespace hpds
