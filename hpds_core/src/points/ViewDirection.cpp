#include "hpds/points/ViewDirection.hpp"

#include <cmath>

namespace hpds {

namespace {
constexpr double kScale = kViewCodeScale;
constexpr std::uint32_t kZeroCode = kViewZeroCode;

double signOf(double v) { return v < 0.0 ? -1.0 : 1.0; }
}  // namespace

std::uint32_t encodeViewDirection(double vx, double vy, double vz) {
  const double l1 = std::fabs(vx) + std::fabs(vy) + std::fabs(vz);
  if (!(l1 > 0.0) || !std::isfinite(l1)) return kZeroCode;
  double x = vx / l1, y = vy / l1;
  if (vz < 0.0) {  // lower hemisphere folds onto the outer triangles of the square
    const double fx = (1.0 - std::fabs(y)) * signOf(x), fy = (1.0 - std::fabs(x)) * signOf(y);
    x = fx;
    y = fy;
  }
  const auto q = [](double c) {
    const long v = std::lround(c * kScale);
    return static_cast<std::uint32_t>(static_cast<std::uint16_t>(static_cast<std::int16_t>(v < -32767 ? -32767 : (v > 32767 ? 32767 : v))));
  };
  return q(x) | (q(y) << 16);
}

std::array<float, 3> decodeViewDirection(std::uint32_t code) {
  if (code == kZeroCode) return {0.0f, 0.0f, 0.0f};
  double x = static_cast<std::int16_t>(code & 0xFFFFu) / kScale, y = static_cast<std::int16_t>(code >> 16) / kScale;
  const double z = 1.0 - std::fabs(x) - std::fabs(y);
  if (z < 0.0) {
    const double fx = (1.0 - std::fabs(y)) * signOf(x), fy = (1.0 - std::fabs(x)) * signOf(y);
    x = fx;
    y = fy;
  }
  // "+ 0.0" turns -0.0 into +0.0: the fold gives a signed zero on its edge (|y| = 1 takes x's sign), which encodes
  // back to the code of the other sign; without a signed zero both codes decode to the same bits.
  const double n = std::sqrt(x * x + y * y + z * z);
  return {static_cast<float>(x / n + 0.0), static_cast<float>(y / n + 0.0), static_cast<float>(z / n + 0.0)};
}

}  // namespace hpds
