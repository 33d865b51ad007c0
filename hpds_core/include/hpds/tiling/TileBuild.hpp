// TileBuild: the two tasks of a tiled map build on one tile. The orchestration (which tasks, in which order, where
// the files go) is the caller's: python/hpds/map_build.py, or any scheduler that respects the phase order.
//
//   bucket (TileBucket.hpp) -> buildTile, phase by phase -> finishTile, any order once the neighbours are built
//
// Contract
// - buildTile runs map mode's pipeline (Pipeline::addFrame) over the tile's bucket, frame by frame in frame-index
//   order, on a hierarchy that starts with the samples its neighbours of earlier phases accepted within
//   kInsertionRing cells of it (read from their border files). It writes the tile's own samples (a hierarchy file,
//   HierarchyFile.hpp) and, first, its border file: the own samples within borderRing(config) cells of the tile's
//   edge, which later phases and finishTile read. Both are written atomically; the map file appears last, so its
//   presence means the tile is complete.
// - Exactness (docs/scaling.md): when every tile's earlier-phase neighbours were built before it, the union of all
//   tiles keeps one map-mode run's guarantees: at most one sample per cell and level, the union of levels 0..D is
//   r_D-separated (samples of levels i, j at least r_max(i,j) apart), every inserted point lies within 2 r_D of it for
//   D up to the build depth. Tiles of one phase are independent: any schedule gives the same bytes.
// - finishTile writes the tile's output: its samples of the output levels (samplesUpTo order) in the `hpds sample`
//   PLY layout (OutputCloud.hpp), with normals when enabled, estimated with every sample within neighborhoodReach of
//   them (its own and its neighbours' border samples, all phases), as one hierarchy holding the whole map gives.
//   Written atomically (AtomicFile.hpp).
// - Errors: std::invalid_argument for a config a tiled build cannot run (eviction, see validateTiledConfig) or frames
//   whose fields differ; std::runtime_error "<path>: ..." for file problems. Nothing is published on error.
// - Reentrant: tasks on different tiles may run concurrently in one process.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/tiling/TileGrid.hpp"

namespace hpds {

/// Throws std::invalid_argument naming the key unless `config` is valid, in map mode, and keeps every sample
/// (map.evict_distance and map.max_samples 0: an evicted sample would leave its neighbours' decisions unexplained).
void validateTiledConfig(const HpdsConfig &config);

/// The config buildTile's map-mode pipeline runs with: resolvedConfig(config), with normals on map.keep_depth
/// down to the level finishTile's normals average (output level + normals.neighborhood_level_offset, clamped to
/// max_depth). Map mode alone builds no level for its normals (it keeps a per-frame normal per sample, which a
/// tile's map file does not carry): without this the tiles would hold the output levels only and finishTile's
/// normals would average no finer level.
[[nodiscard]] HpdsConfig tilePipelineConfig(const HpdsConfig &config);

struct TileBuildStats {
  FrameCounters counters;            ///< the tile's frames through its pipeline (accepted, dropped, per level)
  std::uint64_t frames = 0;          ///< frames with points in the tile
  std::uint64_t band_samples = 0;    ///< earlier-phase samples read from the neighbours' borders
  std::uint64_t samples = 0;         ///< the tile's own samples (all built levels)
  std::uint64_t border_samples = 0;  ///< of those, written to the border file
  std::size_t memory_bytes = 0;      ///< the pipeline's memory at the end (hierarchy, scratch) plus the bucket read
};

/// Builds tile `key` from its bucket files (bucketing tasks' files, in frame order) and the border files of its
/// neighbours of earlier phases (missing neighbours: no file). See the contract.
TileBuildStats buildTile(const HpdsConfig &config, const TileGrid &grid, const TileKey &key,
                         const std::vector<std::string> &bucket_paths, const std::vector<std::string> &border_paths,
                         const std::string &map_path, const std::string &border_path);

struct TileFinishStats {
  std::uint64_t samples = 0;          ///< written (levels 0..output level)
  std::array<std::uint64_t, 22> per_level{};
  std::uint64_t invalid_normals = 0;  ///< written without a valid normal (normals enabled)
  std::uint64_t band_samples = 0;     ///< neighbours' samples read for the normals
  /// Bounds of the written samples {x_min, y_min, z_min, x_max, y_max, z_max} [m]; NaN when none.
  std::array<double, 6> bounds{};
  /// [m] positionRounding of the written cloud: how far its float32 x y z may round positions (0 for float64).
  double rounding = 0.0;
};

/// Writes tile `key`'s output PLY from its map file and (normals) the border files of every neighbour within
/// normalRing(config). See the contract.
TileFinishStats finishTile(const HpdsConfig &config, const TileGrid &grid, const TileKey &key,
                           const std::string &map_path, const std::vector<std::string> &border_paths,
                           const std::string &ply_path);

}  // namespace hpds
