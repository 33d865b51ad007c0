#include "hpds/tiling/TileGrid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/sampling/CellKey.hpp"
#include "hpds/sampling/Hierarchy.hpp"

namespace hpds {

namespace {
std::int64_t floorDiv(std::int64_t a, std::int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
}  // namespace

TileGrid::TileGrid(const HierarchyConfig &hierarchy, double tile_size) : cell_size_(hierarchy.cell_size) {
  if (!(cell_size_ > 0.0) || !std::isfinite(cell_size_))
    throw std::invalid_argument("hierarchy.cell_size: must be a finite number > 0");
  if (hierarchy.max_depth < 0 || hierarchy.max_depth > kMaxDepthLimit)
    throw std::invalid_argument("hierarchy.max_depth: must be in 0..21");
  const double ratio = tile_size / cell_size_;
  const double k = std::round(ratio);
  if (!std::isfinite(tile_size) || !(k >= 1.0) || k > double(1 << 20) || std::fabs(ratio - k) > 1e-9 * k) {
    // A cell derived from output.spacing is an odd number (3.69504 m for 0.1 m): name the nearest valid sizes.
    std::string nearest;
    if (std::isfinite(ratio) && ratio > 0.0 && ratio < double(1 << 20)) {
      const double below = std::max(1.0, std::floor(ratio)), above = std::max(1.0, std::ceil(ratio));
      char buf[96];
      std::snprintf(buf, sizeof buf, " (nearest: %.17g or %.17g m)", below * cell_size_, above * cell_size_);
      nearest = buf;
    }
    char sizes[96];  // %g: std::to_string would print 1e300 as 301 digits and 1e-7 as 0.000000
    std::snprintf(sizes, sizeof sizes, "(%.9g m), so that tiles hold whole cells; got %.9g m", cell_size_, tile_size);
    throw std::invalid_argument(std::string("tile size: must be a whole multiple (>= 1, <= 2^20) of the level-0 cell ") +
                                sizes + nearest);
  }
  k_ = static_cast<int>(k);
  inv_cell_ = 1.0 / cell_size_;
  finest_inv_edge_ = 1.0 / std::ldexp(cell_size_, -hierarchy.max_depth);
}

bool TileGrid::cellColumn(const double xyz[3], std::int64_t &cx, std::int64_t &cy) const {
  // The hierarchy's own range test (its finest level), so that exactly the points it would insert have a tile.
  for (int a = 0; a < 3; ++a)
    if (!inCellRange(xyz[a], finest_inv_edge_)) return false;
  cx = exactCellCoord(xyz[0], cell_size_, inv_cell_);
  cy = exactCellCoord(xyz[1], cell_size_, inv_cell_);
  return true;
}

bool TileGrid::tileOf(const double xyz[3], TileKey &key) const {
  std::int64_t cx, cy;
  if (!cellColumn(xyz, cx, cy)) return false;
  key = TileKey{static_cast<std::int32_t>(floorDiv(cx, k_)), static_cast<std::int32_t>(floorDiv(cy, k_))};
  return true;
}

std::int64_t TileGrid::ringOf(const TileKey &key, std::int64_t cx, std::int64_t cy) const {
  auto axis = [&](std::int64_t c, std::int64_t t) {
    const std::int64_t lo = t * k_, hi = lo + k_ - 1;
    return c < lo ? lo - c : c > hi ? c - hi : 0;
  };
  return std::max(axis(cx, key.i), axis(cy, key.j));
}

std::int64_t TileGrid::borderDepth(std::int64_t cx, std::int64_t cy) const {
  auto axis = [&](std::int64_t c) {
    const std::int64_t local = c - floorDiv(c, k_) * k_;  // 0..k-1
    return std::min(local, k_ - 1 - local) + 1;
  };
  return std::min(axis(cx), axis(cy));
}

std::vector<TileKey> TileGrid::neighbours(const TileKey &key, int ring) const {
  const std::int32_t reach = static_cast<std::int32_t>((std::max(ring, 1) + k_ - 1) / k_);
  std::vector<TileKey> out;
  for (std::int32_t dj = -reach; dj <= reach; ++dj)
    for (std::int32_t di = -reach; di <= reach; ++di)
      if (di != 0 || dj != 0) out.push_back(TileKey{key.i + di, key.j + dj});
  return out;
}

std::array<double, 4> TileGrid::bounds(const TileKey &key) const {
  const double t = tileSize();
  return {key.i * t, key.j * t, (key.i + 1.0) * t, (key.j + 1.0) * t};
}

int normalRing(const HpdsConfig &given) {
  if (!given.normals.enabled) return 0;
  const HpdsConfig config = resolvedConfig(given);
  const int level = resolveOutputLevel(config);
  const double level_radius = poissonRadius(config.hierarchy.cell_size, level);
  double reach = neighborhoodReach(normalParamsFor(config, level), config.hierarchy.cell_size, level_radius);
  // The covariances' k nearest samples may lie farther than the normals' neighbourhood.
  if (config.normals.covariances && config.normals.covariance_k > 0)
    reach = std::max(reach, neighborhoodReach(covarianceNormalParams(config, level), config.hierarchy.cell_size,
                                              level_radius));
  return static_cast<int>(std::ceil(reach / config.hierarchy.cell_size));
}

int borderRing(const HpdsConfig &config) { return std::max(kInsertionRing, normalRing(config)); }

}  // namespace hpds
