// A tiled map build driven in one process, as python/hpds/map_build.py drives it (bucketing in chunks of frames,
// the four phases in order, then the outputs), for the tiling tests; plus the frames and oracles they share.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "hpds/io/HierarchyFile.hpp"
#include "hpds/pipeline/FramePoints.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/sampling/CellKey.hpp"
#include "hpds/tiling/TileBucket.hpp"
#include "hpds/tiling/TileBuild.hpp"

namespace hpds::test {

namespace fs = std::filesystem;

inline std::string keyName(const TileKey &k) { return std::to_string(k.i) + "_" + std::to_string(k.j); }

struct TiledRun {
  std::vector<TileKey> tiles;  ///< row-major
  std::map<TileKey, std::vector<fs::path>> buckets;
  std::map<TileKey, fs::path> maps, borders, plys;
  std::map<TileKey, TileBuildStats> built;
  std::map<TileKey, TileFinishStats> finished;
};

struct TiledRunOptions {
  std::size_t chunk = 2;           ///< frames per bucketing task
  bool read_borders = true;        ///< false: the negative control, tiles ignore their neighbours
  bool reverse_in_phase = false;   ///< another schedule of the tiles of one phase
};

/// Buckets `frames` in chunks, builds the tiles phase by phase, finishes them; files in `dir`.
inline TiledRun runTiled(const HpdsConfig &config, const TileGrid &grid, const std::vector<Frame> &frames,
                         const fs::path &dir, const TiledRunOptions &o = {}) {
  TiledRun run;
  fs::create_directories(dir);
  for (std::size_t first = 0, c = 0; first < frames.size(); first += o.chunk, ++c) {
    TileBucketer bucketer(config, grid);
    for (std::size_t f = first; f < std::min(frames.size(), first + o.chunk); ++f)
      bucketer.addFrame(frames[f], static_cast<std::uint32_t>(f));
    for (const auto &[key, n] : bucketer.tiles()) {
      const fs::path p = dir / ("c" + std::to_string(c) + "_" + keyName(key) + ".bkt");
      writeTileBucket(p.string(), bucketer.layout(), bucketer.framesOf(key));
      run.buckets[key].push_back(p);
    }
  }
  for (const auto &kv : run.buckets) run.tiles.push_back(kv.first);
  std::sort(run.tiles.begin(), run.tiles.end());
  auto strings = [](const std::vector<fs::path> &ps) {
    std::vector<std::string> s;
    for (const auto &p : ps) s.push_back(p.string());
    return s;
  };
  for (const TileKey &key : run.tiles) {
    run.maps[key] = dir / ("tile_" + keyName(key) + ".hpdsmap");
    run.borders[key] = dir / ("tile_" + keyName(key) + ".border");
    run.plys[key] = dir / ("tile_" + keyName(key) + ".ply");
  }
  for (int phase = 0; phase < 4; ++phase) {
    std::vector<TileKey> order;
    for (const TileKey &key : run.tiles)
      if (TileGrid::phase(key) == phase) order.push_back(key);
    if (o.reverse_in_phase) std::reverse(order.begin(), order.end());
    for (const TileKey &key : order) {
      std::vector<fs::path> borders;
      if (o.read_borders)
        for (const TileKey &n : grid.neighbours(key, kInsertionRing))
          if (run.maps.count(n) && TileGrid::phase(n) < phase) borders.push_back(run.borders[n]);
      run.built[key] = buildTile(config, grid, key, strings(run.buckets[key]), strings(borders),
                                 run.maps[key].string(), run.borders[key].string());
    }
  }
  for (const TileKey &key : run.tiles) {
    std::vector<fs::path> borders;
    for (const TileKey &n : grid.neighbours(key, std::max(1, normalRing(config))))
      if (run.maps.count(n)) borders.push_back(run.borders[n]);
    run.finished[key] =
        finishTile(config, grid, key, run.maps[key].string(), strings(borders), run.plys[key].string());
  }
  return run;
}

struct Sample {
  double xyz[3];
  int level;
  std::uint32_t frame;
  bool operator<(const Sample &o) const {
    return std::lexicographical_compare(xyz, xyz + 3, o.xyz, o.xyz + 3) ||
           (std::equal(xyz, xyz + 3, o.xyz) && level < o.level);
  }
  bool operator==(const Sample &o) const { return std::equal(xyz, xyz + 3, o.xyz) && level == o.level && frame == o.frame; }
};

inline std::vector<Sample> samplesOf(const Hierarchy &h) {
  std::vector<Sample> out;
  for (SampleId id = 0; id < h.idBound(); ++id)
    if (h.isLive(id)) {
      const double *p = h.position(id);
      out.push_back(Sample{{p[0], p[1], p[2]}, h.level(id), h.frameIndex(id)});
    }
  return out;
}

/// Every sample of every tile's map file, sorted.
inline std::vector<Sample> unionOf(const TiledRun &run) {
  std::vector<Sample> all;
  for (const auto &[key, path] : run.maps) {
    const std::vector<Sample> s = samplesOf(loadHierarchy(path.string()).hierarchy);
    all.insert(all.end(), s.begin(), s.end());
  }
  std::sort(all.begin(), all.end());
  return all;
}

/// The posed positions of every point the pipeline inserts (after the skip rules).
inline std::vector<std::array<double, 3>> insertedPoints(const HpdsConfig &config, const std::vector<Frame> &frames) {
  std::vector<std::array<double, 3>> out;
  for (const Frame &f : frames) {
    std::vector<double> xyz;
    std::vector<std::uint32_t> kept;
    SkippedPoints skipped;
    poseFramePoints(f, config.input, xyz, kept, skipped);
    for (std::uint32_t i : kept) out.push_back({xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
  }
  return out;
}

struct Violations {
  std::size_t cells = 0, spacing = 0, coverage = 0;
};

/// The guarantees of one map-mode run, by brute force over all pairs and all points, for levels 0..depth.
inline Violations checkGuarantees(const std::vector<Sample> &samples, const std::vector<std::array<double, 3>> &points,
                                  double cell_size, int depth) {
  Violations v;
  auto radius = [&](int l) { return 0.5 * std::sqrt(3.0) * std::ldexp(cell_size, -l); };
  // (1) at most one sample per cell and level
  std::map<std::array<std::int64_t, 4>, int> cells;
  for (const Sample &s : samples) {
    const double e = std::ldexp(cell_size, -s.level);
    std::array<std::int64_t, 4> k{s.level, 0, 0, 0};
    for (int a = 0; a < 3; ++a) k[a + 1] = static_cast<std::int64_t>(std::floor(s.xyz[a] / e));
    if (++cells[k] > 1) ++v.cells;
  }
  // (2) samples of levels i, j at least r_max(i,j) apart: the union of levels 0..D is r_D-separated
  for (std::size_t a = 0; a < samples.size(); ++a)
    for (std::size_t b = a + 1; b < samples.size(); ++b) {
      const double r = radius(std::max(samples[a].level, samples[b].level));
      double d2 = 0.0;
      for (int k = 0; k < 3; ++k) d2 += (samples[a].xyz[k] - samples[b].xyz[k]) * (samples[a].xyz[k] - samples[b].xyz[k]);
      if (d2 < r * r) ++v.spacing;
    }
  // (3) every inserted point within 2 r_D of the union of levels 0..D
  std::vector<double> best(static_cast<std::size_t>(depth) + 1);
  for (const auto &p : points) {
    std::fill(best.begin(), best.end(), INFINITY);
    for (const Sample &s : samples) {
      double d2 = 0.0;
      for (int k = 0; k < 3; ++k) d2 += (p[k] - s.xyz[k]) * (p[k] - s.xyz[k]);
      for (int D = s.level; D <= depth; ++D) best[D] = std::min(best[D], d2);
    }
    for (int D = 0; D <= depth; ++D)
      if (best[D] > 4.0 * radius(D) * radius(D)) {
        ++v.coverage;
        break;
      }
  }
  return v;
}

/// Frames of a drive past dense geometry: a ground patch, a wall in the plane x = 0 and one in y = 1, both on tile
/// borders for tile edges that divide 1 m; seen from four poses (translated, turned).
inline std::vector<Frame> denseFrames(int frames, int points_per_frame, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Frame> out;
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  layout.append("intensity", FieldType::Float32);
  for (int f = 0; f < frames; ++f) {
    Frame frame;
    const double yaw = 0.3 * f;
    frame.sensor_to_fixed = Eigen::Translation3d(0.4 * f - 0.5, 0.25 * f, 1.2) * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ());
    const Eigen::Isometry3d to_sensor = frame.sensor_to_fixed.inverse();
    frame.points = PointBuffer(layout, static_cast<std::size_t>(points_per_frame));
    for (int i = 0; i < points_per_frame; ++i) {
      Eigen::Vector3d w;
      const int kind = i % 4;
      if (kind < 2) {
        w = Eigen::Vector3d(2.4 * u(rng), 2.4 * u(rng), 0.01 * u(rng));  // ground
      } else if (kind == 2) {
        w = Eigen::Vector3d(0.0 + 0.004 * u(rng), 2.0 * u(rng), 1.0 + u(rng));  // wall on x = 0
      } else {
        w = Eigen::Vector3d(2.0 * u(rng), 1.0 + 0.004 * u(rng), 1.0 + u(rng));  // wall on y = 1
      }
      const Eigen::Vector3f s = (to_sensor * w).cast<float>();
      std::uint8_t *rec = frame.points.record(static_cast<std::size_t>(i));
      std::memcpy(rec, s.data(), 12);
      const float intensity = static_cast<float>(i % 255);
      std::memcpy(rec + 12, &intensity, 4);
    }
    out.push_back(std::move(frame));
  }
  return out;
}

}  // namespace hpds::test
