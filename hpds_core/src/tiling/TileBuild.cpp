#include "hpds/tiling/TileBuild.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "hpds/io/HierarchyFile.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/normals/SampleCovariance.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/tiling/TileBucket.hpp"

namespace hpds {

namespace {

std::string tileName(const TileKey &key) {
  return "tile (" + std::to_string(key.i) + ", " + std::to_string(key.j) + ")";
}

/// Puts a copy of sample `id` of `from` into `into` (same cell size and depth).
void copySample(const Hierarchy &from, SampleId id, Hierarchy &into) {
  const std::array<float, 3> v = from.toViewpoint(id);
  into.restoreSample(from.position(id), from.level(id), from.frameIndex(id), v.data(), from.record(id));
}

/// Restores into `into` the samples of the hierarchy file `path` whose cell column is 1..`ring` columns from tile
/// `key`; returns how many.
std::uint64_t restoreBand(Hierarchy &into, const std::string &path, const HpdsConfig &config, const TileGrid &grid,
                          const TileKey &key, int ring) {
  const LoadedHierarchy loaded = loadHierarchy(path, &config.hierarchy);
  const Hierarchy &src = loaded.hierarchy;
  if (src.recordLayout() != into.recordLayout()) {
    if (into.idBound() > 0)
      throw std::invalid_argument(path + ": point fields differ from those of the other neighbours' samples");
    into.setRecordLayout(src.recordLayout());
  }
  std::uint64_t n = 0;
  for (SampleId id = 0; id < src.idBound(); ++id) {
    if (!src.isLive(id)) continue;
    std::int64_t cx, cy;
    if (!grid.cellColumn(src.position(id), cx, cy)) throw std::runtime_error(path + ": a sample lies out of range");
    const std::int64_t r = grid.ringOf(key, cx, cy);
    if (r == 0) throw std::runtime_error(path + ": holds a sample inside " + tileName(key) + ", not a neighbour's border");
    if (r > ring) continue;
    try {
      copySample(src, id, into);
    } catch (const std::invalid_argument &e) {
      throw std::runtime_error(path + ": " + e.what());
    }
    ++n;
  }
  return n;
}

}  // namespace

void validateTiledConfig(const HpdsConfig &config) {
  validateConfig(config);
  if (config.mode != Mode::Map) throw std::invalid_argument("mode: a tiled map build needs map mode");
  if (config.map.evict_distance != 0.0)
    throw std::invalid_argument("map.evict_distance: must be 0 in a tiled map build (it keeps every sample)");
  if (config.map.max_samples != 0)
    throw std::invalid_argument("map.max_samples: must be 0 in a tiled map build (it keeps every sample)");
}

HpdsConfig tilePipelineConfig(const HpdsConfig &given) {
  HpdsConfig config = resolvedConfig(given);
  config.map.keep_depth = std::max(config.map.keep_depth, normalsAveragingLevel(config, config.output.level));
  return config;
}

TileBuildStats buildTile(const HpdsConfig &given, const TileGrid &grid, const TileKey &key,
                         const std::vector<std::string> &bucket_paths, const std::vector<std::string> &border_paths,
                         const std::string &map_path, const std::string &border_path) {
  validateTiledConfig(given);
  // The cell a pipeline runs with (derived from the spacing), and the finer levels finishTile's normals read.
  const HpdsConfig config = tilePipelineConfig(given);
  TileBuildStats stats;
  Hierarchy own(config.hierarchy.cell_size, config.hierarchy.max_depth);
  {
    // 1. The earlier phases' samples near the tile: all that any insertion here can be rejected by.
    Hierarchy band(config.hierarchy.cell_size, config.hierarchy.max_depth);
    for (const std::string &path : border_paths)
      stats.band_samples += restoreBand(band, path, config, grid, key, kInsertionRing);
    const PointLayout band_layout = band.recordLayout();
    Pipeline pipeline(config);
    pipeline.replaceMap(std::move(band), 0);

    // 2. The tile's frames, in frame order, through map mode's pipeline.
    bool have_frame = false;
    std::uint32_t last_frame = 0;
    std::size_t bucket_bytes = 0;
    for (const std::string &path : bucket_paths) {
      std::vector<BucketFrame> frames = readTileBucket(path);
      std::size_t bytes = 0;
      for (const BucketFrame &f : frames) bytes += f.points.bytes().size();
      bucket_bytes = std::max(bucket_bytes, bytes);
      for (BucketFrame &f : frames) {
        if (have_frame && f.frame_index <= last_frame)
          throw std::runtime_error(path + ": frame " + std::to_string(f.frame_index) + " comes after frame " +
                                   std::to_string(last_frame) + " (bucket files out of frame order)");
        if (stats.band_samples > 0 && f.points.layout() != band_layout)
          throw std::invalid_argument(tileName(key) + ": frame " + std::to_string(f.frame_index) +
                                      "'s point fields differ from the neighbours' samples'");
        have_frame = true;
        last_frame = f.frame_index;
        Frame frame;
        frame.points = std::move(f.points);
        frame.stamp = static_cast<double>(f.frame_index);
        frame.sensor_to_fixed = f.sensor_to_fixed;
        frame.viewpoint = f.viewpoint;
        pipeline.setNextFrameIndex(f.frame_index);
        FrameResult r;
        try {
          r = pipeline.addFrame(frame);
        } catch (const std::invalid_argument &e) {
          throw std::invalid_argument(tileName(key) + ", frame " + std::to_string(f.frame_index) + ": " + e.what());
        }
        // The bucketing placed these points with the pipeline's own arithmetic; a sample outside the tile would
        // mean it did not, and the seams' guarantees would not hold.
        for (SampleId id : r.new_samples) {
          TileKey at;
          if (!grid.tileOf(pipeline.hierarchy().position(id), at) || at != key)
            throw std::logic_error(tileName(key) + ": accepted a sample outside the tile");
        }
        stats.counters += r.counters;
        ++stats.frames;
      }
    }
    stats.memory_bytes = pipeline.memUsage() + bucket_bytes;

    // 3. The tile's own samples: those after the band's.
    const Hierarchy &h = pipeline.hierarchy();
    own.setRecordLayout(h.recordLayout());
    for (SampleId id = static_cast<SampleId>(stats.band_samples); id < h.idBound(); ++id)
      if (h.isLive(id)) copySample(h, id, own);
  }
  stats.samples = own.sampleCount();

  // 4. The border first, the map last: a present map file means a complete tile.
  const int ring = borderRing(config);
  Hierarchy border(config.hierarchy.cell_size, config.hierarchy.max_depth);
  border.setRecordLayout(own.recordLayout());
  for (SampleId id = 0; id < own.idBound(); ++id) {
    std::int64_t cx, cy;
    grid.cellColumn(own.position(id), cx, cy);
    if (grid.borderDepth(cx, cy) <= ring) copySample(own, id, border);
  }
  stats.border_samples = border.sampleCount();
  saveHierarchy(border_path, border);
  saveHierarchy(map_path, own);
  return stats;
}

TileFinishStats finishTile(const HpdsConfig &given, const TileGrid &grid, const TileKey &key,
                           const std::string &map_path, const std::vector<std::string> &border_paths,
                           const std::string &ply_path) {
  validateTiledConfig(given);
  const HpdsConfig config = resolvedConfig(given);
  TileFinishStats stats;
  LoadedHierarchy loaded = loadHierarchy(map_path, &config.hierarchy);
  Hierarchy &h = loaded.hierarchy;
  // A tile's map is written from a fresh hierarchy (no evictions), so its ids are 0..n-1 and the band's samples
  // restored below come after them; a map with free slots is not one of ours.
  if (h.idBound() != h.sampleCount())
    throw std::runtime_error(map_path + ": not a tile's map (it holds free slots of evicted samples)");
  const SampleId own = static_cast<SampleId>(h.idBound());
  for (SampleId id = 0; id < own; ++id) {
    TileKey at;
    if (!grid.tileOf(h.position(id), at) || at != key)
      throw std::runtime_error(map_path + ": holds a sample outside " + tileName(key));
  }
  const int ring = normalRing(config);
  if (config.normals.enabled)
    for (const std::string &path : border_paths) stats.band_samples += restoreBand(h, path, config, grid, key, ring);

  const int level = resolveOutputLevel(config);
  std::vector<SampleId> ids;
  for (SampleId id = 0; id < own; ++id)
    if (h.level(id) <= level) ids.push_back(id);
  std::vector<SampleNormal> normals;
  std::vector<SampleCovariance> covariances;
  if (config.normals.enabled) {
    std::vector<LocalPca> neighbourhoods;
    normals = estimateNormals(h, ids, normalParamsFor(config, level),
                              config.normals.covariances ? &neighbourhoods : nullptr);
    for (const SampleNormal &n : normals) stats.invalid_normals += n.valid ? 0 : 1;
    if (config.normals.covariances) covariances = estimateCovariances(h, ids, level, normals, neighbourhoods, config);
  }
  const PointBuffer cloud = buildOutputCloud(h, ids, config.normals.enabled ? &normals : nullptr, false,
                                             config.normals.covariances ? &covariances : nullptr,
                                             outputXyzType(config.output));

  const double nan = std::numeric_limits<double>::quiet_NaN();
  stats.bounds = {nan, nan, nan, nan, nan, nan};
  for (SampleId id : ids) {
    ++stats.per_level[h.level(id)];
    const double *p = h.position(id);
    for (int a = 0; a < 3; ++a) {
      stats.bounds[a] = std::isnan(stats.bounds[a]) ? p[a] : std::min(stats.bounds[a], p[a]);
      stats.bounds[3 + a] = std::isnan(stats.bounds[3 + a]) ? p[a] : std::max(stats.bounds[3 + a], p[a]);
    }
  }
  stats.samples = ids.size();
  stats.rounding = positionRounding(cloud);

  writePly(ply_path, cloud, SamplingRecord{h.cellSize(), h.maxDepth(), level});  // atomic: a temporary beside it, renamed when complete
  return stats;
}

}  // namespace hpds
