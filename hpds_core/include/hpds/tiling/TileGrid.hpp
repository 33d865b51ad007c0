// TileGrid: the square tiles of a tiled map build, their colour phases and the bands they exchange.
//
// Contract
// - Tiles cut the fixed frame's xy plane (z is unbounded) into squares of edge T = k * cell_size, k >= 1 whole: tile
//   (i, j) holds the level-0 cell columns [i k, (i+1) k) x [j k, (j+1) k). Tiles are anchored at the origin like the
//   hierarchy's cells, so every cell of every level lies in exactly one tile, and a point's tile is computed from its
//   exact level-0 cell (CellKey.hpp): no rounding can put a point in one tile and its cell in another.
// - Phase (i mod 2) + 2 (j mod 2): two tiles of one phase are at least one tile edge T >= cell_size apart in x or y.
//   Every test by which the hierarchy rejects a point is a distance below r_0 = sqrt(3)/2 cell_size < T or a shared
//   cell, so tiles of one phase never interact, and a tile's insertions only depend on samples within
//   kInsertionRing level-0 cells of it.
// - Rings count level-0 cell columns around a tile (Chebyshev distance in cells, xy only).
// - Coordinates whose finest-level cell would be beyond the hierarchy's exact key range have no tile (tileOf returns
//   false), as the hierarchy counts them out of range.
// - Value type; const methods are thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "hpds/config/Config.hpp"

namespace hpds {

struct TileKey {
  std::int32_t i = 0, j = 0;
  bool operator==(const TileKey &o) const { return i == o.i && j == o.j; }
  bool operator!=(const TileKey &o) const { return !(*this == o); }
  /// Row-major (j, then i): the order tiles are listed in.
  bool operator<(const TileKey &o) const { return j != o.j ? j < o.j : i < o.i; }
};

/// Level-0 cells around a tile whose samples can change its insertions: every conflict is closer than r_0 < c_0.
inline constexpr int kInsertionRing = 1;

class TileGrid {
 public:
  /// Throws std::invalid_argument ("tile size: ...") unless tile_size is finite and a whole multiple k >= 1 of
  /// hierarchy.cell_size (within a relative 1e-9; the tiles then use k * cell_size exactly), k <= 2^20. Pass the
  /// cell the pipeline runs with, resolvedConfig(config).hierarchy: a derived cell_size (0) is refused here.
  TileGrid(const HierarchyConfig &hierarchy, double tile_size);

  [[nodiscard]] double cellSize() const { return cell_size_; }
  [[nodiscard]] int cellsPerTile() const { return k_; }
  [[nodiscard]] double tileSize() const { return cell_size_ * k_; }

  /// The tile holding xyz (fixed frame); false when xyz has none (see the contract).
  bool tileOf(const double xyz[3], TileKey &key) const;
  [[nodiscard]] static int phase(const TileKey &key) { return (key.i & 1) | ((key.j & 1) << 1); }

  /// Level-0 cell column of xyz; false when xyz has no tile.
  bool cellColumn(const double xyz[3], std::int64_t &cx, std::int64_t &cy) const;
  /// Chebyshev distance, in level-0 cell columns, from column (cx, cy) to tile `key`: 0 inside it, 1 for the
  /// columns touching it, ...
  [[nodiscard]] std::int64_t ringOf(const TileKey &key, std::int64_t cx, std::int64_t cy) const;
  /// Distance, in cell columns, from (cx, cy) inside its tile to the nearest column of another tile: 1 on the
  /// tile's outermost columns. A sample within `ring` columns of another tile has borderDepth <= ring.
  [[nodiscard]] std::int64_t borderDepth(std::int64_t cx, std::int64_t cy) const;
  /// The tiles other than `key` with a column within `ring` columns of it (ring >= 1), row-major.
  [[nodiscard]] std::vector<TileKey> neighbours(const TileKey &key, int ring) const;

  /// xy bounds of a tile: {x_min, y_min, x_max, y_max} [m] (the tile is [min, max) on each axis).
  [[nodiscard]] std::array<double, 4> bounds(const TileKey &key) const;

 private:
  double cell_size_;
  double inv_cell_;
  double finest_inv_edge_;
  int k_;
};

/// Level-0 cell rings a tiled build exchanges for `config`: its insertions need kInsertionRing; its normals (when
/// enabled) every sample within neighborhoodReach (NormalEstimator.hpp) of the tile, i.e. ceil(reach / cell_size),
/// and with covariances the reach of their k nearest samples (covarianceNormalParams) too.
[[nodiscard]] int normalRing(const HpdsConfig &config);
/// max(kInsertionRing, normalRing): the depth of the border files a tile writes for its neighbours.
[[nodiscard]] int borderRing(const HpdsConfig &config);

}  // namespace hpds
