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

/// The code's scale (int16 per coordinate) and the zero vector's own code (-32768 in both halves: never produced by
/// a direction).
inline constexpr double kViewCodeScale = 32767.0;
inline constexpr std::uint32_t kViewZeroCode = 0x80008000u;

/// Packs the direction of v (any length; zero and non-finite give the zero code).
[[nodiscard]] std::uint32_t encodeViewDirection(double vx, double vy, double vz);
/// Unit vector of a packed direction, or (0, 0, 0) for the zero code.
[[nodiscard]] std::array<float, 3> decodeViewDirection(std::uint32_t code);
/// The same direction, not normalised (|out|_1 = 1 up to the code's rounding; (0, 0, 0) for the zero code): for
/// tests that only need signs and angle thresholds, without decodeViewDirection's square root and divisions.
inline void viewDirectionUnscaled(std::uint32_t code, double out[3]) {
  constexpr double kInvScale = 1.0 / kViewCodeScale;
  if (code == kViewZeroCode) {
    out[0] = out[1] = out[2] = 0.0;
    return;
  }
  double x = static_cast<std::int16_t>(code & 0xFFFFu) * kInvScale, y = static_cast<std::int16_t>(code >> 16) * kInvScale;
  const double ax = x < 0.0 ? -x : x, ay = y < 0.0 ? -y : y, z = 1.0 - ax - ay;
  if (z < 0.0) {  // the lower hemisphere's fold (encodeViewDirection)
    const double fx = x < 0.0 ? -(1.0 - ay) : 1.0 - ay, fy = y < 0.0 ? -(1.0 - ax) : 1.0 - ax;
    x = fx;
    y = fy;
  }
  out[0] = x, out[1] = y, out[2] = z;
}

}  // namespace hpds
