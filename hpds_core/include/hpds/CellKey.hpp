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
  double q = std::floor(v * inv_edge);
  // v - q*edge computed with one rounding keeps its sign, so the comparisons decide the true floor.
  if (std::fma(-q, edge, v) < 0.0) {
    q -= 1.0;
  } else if (std::fma(-(q + 1.0), edge, v) >= 0.0) {
    q += 1.0;
  }
  return static_cast<std::int32_t>(q);
}

/// Offset of v inside its cell k, in [0, edge] up to one rounding (exact sign).
[[nodiscard]] inline double offsetInCell(double v, std::int32_t k, double edge) {
  return std::fma(-static_cast<double>(k), edge, v);
}

}  // namespace hpds
