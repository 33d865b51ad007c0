// Integer cell coordinates of the world-anchored level grids, computed exactly.
//
// Contract
// - Level D of a hierarchy with level-0 edge C has cells [k*e, (k+1)*e) per axis with e = C * 2^-D (exact in double).
// - `exactCellCoord` returns floor(v / e) for the double values given, with no rounding error: the quotient is
//   estimated and then corrected with a fused multiply-add residual, whose sign is exact.
// - Coordinates are limited to |k| < kMaxCellCoord (2^30) so that neighbour offsets never overflow int32; callers
//   check `inCellRange` first and count points outside as out of range instead of producing wrong keys.
#pragma once

#include <cmath>
#include <cstdint>

namespace hpds {

inline constexpr double kMaxCellCoord = 1073741824.0;  // 2^30

struct CellKey {
  std::int32_t x = 0, y = 0, z = 0;
  bool operator==(const CellKey &o) const { return x == o.x && y == o.y && z == o.z; }
  bool operator!=(const CellKey &o) const { return !(*this == o); }
};

/// True when floor(v / edge) is representable with margin (|v / edge| < 2^30 - 8); false for NaN/Inf.
[[nodiscard]] inline bool inCellRange(double v, double inv_edge) {
  const double q = v * inv_edge;
  return std::fabs(q) < kMaxCellCoord - 8.0;  // NaN compares false
}

/// floor(v / edge), exact; `inv_edge` is only a first estimate (1 / edge). Requires inCellRange(v, inv_edge).
[[nodiscard]] inline std::int32_t exactCellCoord(double v, double edge, double inv_edge) {
  const double t = v * inv_edge;
  double q = std::floor(t);
  // |t - v/edge| < 5e-7 for |t| < 2^30 (two roundings of relative 2^-53), so away from an integer the estimate
  // is already the floor; only near a boundary is the exact test needed (fma is a libm call without -mfma).
  const double frac = t - q;
  if (frac > 1e-6 && frac < 1.0 - 1e-6) return static_cast<std::int32_t>(q);
  // v - q*edge computed with one rounding keeps its sign, so the comparisons decide the true floor.
  if (std::fma(-q, edge, v) < 0.0) {
    q -= 1.0;
  } else if (std::fma(-(q + 1.0), edge, v) >= 0.0) {
    q += 1.0;
  }
  return static_cast<std::int32_t>(q);
}

/// Offset of v inside its cell k, within [0, edge] up to an absolute error below 3e-16 * (|v| + edge); callers that
/// prune with it add `pruneSlack`.
[[nodiscard]] inline double offsetInCell(double v, std::int32_t k, double edge) { return v - static_cast<double>(k) * edge; }

/// Absolute slack [m] that covers the rounding of offsetInCell for a query at q (any level, any edge <= `edge`).
[[nodiscard]] inline double pruneSlack(const double q[3], double edge) {
  return 4e-16 * (std::fabs(q[0]) + std::fabs(q[1]) + std::fabs(q[2]) + 3.0 * edge);
}

}  // namespace hpds
