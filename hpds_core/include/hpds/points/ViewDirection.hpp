// ViewDirection: the direction from a sample to its frame's viewpoint, packed into 32 bits.
//
// Contract
// - Only the direction is kept (normal orientation needs the sign of a dot product, not the distance): an
//   octahedral map of the unit sphere, two int16 coordinates, worst-case angular error below 5e-4 rad (0.03 degrees).
// - The zero vector (a sample at its viewpoint) has its own code and decodes to (0, 0, 0).
// - Decoding then encoding gives a code that decodes to the same bits (the same code, except on the fold's edge,
//   where two codes decode to one direction), so saved maps reload and save again bit-identically.
#pragma once

#include <array>
#include <cstdint>

namespace hpds {

/// Packs the direction of v (any length; zero and non-finite give the zero code).
[[nodiscard]] std::uint32_t encodeViewDirection(double vx, double vy, double vz);
/// Unit vector of a packed direction, or (0, 0, 0) for the zero code.
[[nodiscard]] std::array<float, 3> decodeViewDirection(std::uint32_t code);

}  // namespace hpds
