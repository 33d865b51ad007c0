// The tiled map build's core (hpds/tiling/): tile geometry against its definitions, buckets, and whole builds whose
// union is checked by brute force (cells, pairwise spacing, coverage) and equals a one-hierarchy oracle that inserts
// the same batches in phase order; a build that ignores its neighbours (the negative control) breaks at the seams.
// Core only: runs in a build without PCL.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <set>
#include <stdexcept>

#include "TestData.hpp"
#include "TiledRun.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/tiling/TileGrid.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;
using test::TiledRun;
using test::TiledRunOptions;

// Every level down to `depth` built and output, no normals, nothing evicted (a tiled build keeps every sample).
HpdsConfig mapConfig(double cell, int depth) {
  HpdsConfig c;
  c.mode = Mode::Map;
  c.hierarchy.cell_size = cell;
  c.hierarchy.max_depth = depth;
  c.output.level = depth;
  c.normals.enabled = false;
  c.map.evict_distance = 0.0;
  c.map.max_samples = 0;
  return c;
}

HierarchyConfig hier(double cell, int depth) {
  HierarchyConfig h;
  h.cell_size = cell;
  h.max_depth = depth;
  return h;
}

TEST(TileGrid, TileSizeMustBeAWholeMultipleOfTheCellSize) {
  EXPECT_EQ(TileGrid(hier(4.0, 8), 4.0).cellsPerTile(), 1);
  EXPECT_EQ(TileGrid(hier(4.0, 8), 32.0).cellsPerTile(), 8);
  EXPECT_EQ(TileGrid(hier(0.3, 8), 0.9 * (1 + 1e-12)).cellsPerTile(), 3);
  EXPECT_DOUBLE_EQ(TileGrid(hier(0.3, 8), 0.9).tileSize(), 3 * 0.3);
  for (double bad : {0.0, -4.0, 2.0, 6.0, 4.1, double(NAN), double(INFINITY), 4.0 * (1 << 21), 1e300, 1e-7}) {
    try {
      (void)TileGrid(hier(4.0, 8), bad);
      ADD_FAILURE() << "tile size " << bad << " accepted";
    } catch (const std::invalid_argument &e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("tile size"), std::string::npos) << what;
      // The size as given, in a few digits (not 301 of them, nor 0.000000 for 1e-7).
      EXPECT_LT(what.size(), 200u) << what;
      if (bad == 1e300) {
        EXPECT_NE(what.find("got 1e+300 m"), std::string::npos) << what;
      }
      if (bad == 1e-7) {
        EXPECT_NE(what.find("got 1e-07 m"), std::string::npos) << what;
      }
    }
  }
  // The shipped defaults derive the cell from output.spacing (3.69504 m for 0.1 m): the error names valid sizes,
  // and each of them is accepted.
  const HierarchyConfig derived = resolvedConfig(HpdsConfig{}).hierarchy;
  try {
    (void)TileGrid(derived, 8.0);
    ADD_FAILURE() << "tile size 8 accepted with a " << derived.cell_size << " m cell";
  } catch (const std::invalid_argument &e) {
    const std::string what = e.what();
    const auto at = what.find("(nearest: ");
    ASSERT_NE(at, std::string::npos) << what;
    double below = 0, above = 0;
    ASSERT_EQ(std::sscanf(what.c_str() + at, "(nearest: %lf or %lf m)", &below, &above), 2) << what;
    EXPECT_EQ(TileGrid(derived, below).cellsPerTile(), 2);
    EXPECT_EQ(TileGrid(derived, above).cellsPerTile(), 3);
  }
}

TEST(TileGrid, TileOfIsTheHierarchysOwnLevelZeroCellDividedByK) {
  // The oracle is the hierarchy itself: a restored sample's level-0 cell key, floor-divided by k.
  const double cell = 0.75;
  const TileGrid grid(hier(cell, 6), 3 * cell);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-20.0, 20.0);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < 2000; ++i) pts.push_back({u(rng), u(rng), u(rng)});
  // Points on and next to tile boundaries, where a rounded division would go wrong.
  for (int t = -4; t <= 4; ++t) {
    const double b = t * 3 * cell;
    for (double x : {b, std::nextafter(b, -INFINITY), std::nextafter(b, INFINITY)})
      pts.push_back({x, std::nextafter(-b, INFINITY), 0.5});
  }
  for (const auto &p : pts) {
    Hierarchy h(cell, 6);
    h.restoreSample(p.data(), 0, 0, std::array<float, 3>{0, 0, 1}.data(), nullptr);
    CellKey k0;
    h.grid(0).forEach([&](const CellKey &k, SampleId) { k0 = k; });
    TileKey key;
    ASSERT_TRUE(grid.tileOf(p.data(), key));
    EXPECT_EQ(key.i, static_cast<std::int32_t>(std::floor(k0.x / 3.0))) << p[0];
    EXPECT_EQ(key.j, static_cast<std::int32_t>(std::floor(k0.y / 3.0))) << p[1];
  }
  const double far[3] = {1e12, 0.0, 0.0}, nan[3] = {NAN, 0.0, 0.0};
  TileKey key;
  EXPECT_FALSE(grid.tileOf(far, key));
  EXPECT_FALSE(grid.tileOf(nan, key));
}

TEST(TileGrid, PhasesOfTouchingTilesDifferAndRingsMatchTheirDefinition) {
  const TileGrid grid(hier(1.0, 4), 3.0);  // k = 3
  for (int i = -3; i <= 3; ++i)
    for (int j = -3; j <= 3; ++j) {
      const TileKey key{i, j};
      EXPECT_GE(TileGrid::phase(key), 0);
      EXPECT_LT(TileGrid::phase(key), 4);
      for (const TileKey &n : grid.neighbours(key, 1)) EXPECT_NE(TileGrid::phase(n), TileGrid::phase(key));
      for (int ring : {1, 2, 3, 4, 7}) {
        // Brute force: every tile with a column within `ring` columns of the key's columns.
        std::set<std::pair<int, int>> expected, got;
        for (int ti = i - 4; ti <= i + 4; ++ti)
          for (int tj = j - 4; tj <= j + 4; ++tj) {
            if (ti == i && tj == j) continue;
            bool near = false;
            for (std::int64_t cx = ti * 3; cx < ti * 3 + 3; ++cx)
              for (std::int64_t cy = tj * 3; cy < tj * 3 + 3; ++cy) near |= grid.ringOf(key, cx, cy) <= ring;
            if (near) expected.insert({ti, tj});
          }
        for (const TileKey &n : grid.neighbours(key, ring)) got.insert({n.i, n.j});
        EXPECT_EQ(got, expected) << i << " " << j << " ring " << ring;
      }
    }
  // ringOf and borderDepth by their definitions (Chebyshev distance in columns).
  for (std::int64_t cx = -7; cx <= 7; ++cx)
    for (std::int64_t cy = -7; cy <= 7; ++cy) {
      const TileKey key{0, 0};
      std::int64_t ring = 1 << 20, depth = 1 << 20;
      for (std::int64_t x = 0; x < 3; ++x)
        for (std::int64_t y = 0; y < 3; ++y) ring = std::min(ring, std::max(std::abs(cx - x), std::abs(cy - y)));
      EXPECT_EQ(grid.ringOf(key, cx, cy), ring);
      TileKey own;
      const double p[3] = {cx + 0.5, cy + 0.5, 0.0};
      ASSERT_TRUE(grid.tileOf(p, own));
      for (std::int64_t x = cx - 4; x <= cx + 4; ++x)
        for (std::int64_t y = cy - 4; y <= cy + 4; ++y) {
          const double q[3] = {x + 0.5, y + 0.5, 0.0};
          TileKey other;
          grid.tileOf(q, other);
          if (other != own) depth = std::min(depth, std::max(std::abs(cx - x), std::abs(cy - y)));
        }
      EXPECT_EQ(grid.borderDepth(cx, cy), depth) << cx << " " << cy;
    }
}

TEST(TileBucket, FilesEveryKeptPointOnceInItsTileAndRoundTrips) {
  HpdsConfig config = mapConfig(1.0, 4);
  config.input.min_range = 0.01;
  const TileGrid grid(config.hierarchy, 1.0);
  std::vector<Frame> frames = test::denseFrames(3, 3000, 11);
  // Points the pipeline skips: NaN, a no-return, one closer than min_range (to a viewpoint off the origin, which
  // the buckets keep).
  for (std::size_t k = 0; k < frames.size(); ++k) {
    Frame &f = frames[k];
    f.viewpoint = Eigen::Vector3d(0.0, 0.0005 * double(k + 1), 0.0);
    const float bad[3][3] = {{NAN, 0, 0}, {0, 0, 0}, {0.001f, 0, 0}};
    for (int b = 0; b < 3; ++b) std::memcpy(f.points.record(static_cast<std::size_t>(b)), bad[b], 12);
  }
  TileBucketer bucketer(config, grid);
  std::uint64_t kept = 0, skipped = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const FrameCounters c = bucketer.addFrame(frames[f], static_cast<std::uint32_t>(10 + f));
    EXPECT_EQ(c.input, frames[f].points.size());
    EXPECT_EQ(c.skipped_invalid, 1u);
    EXPECT_EQ(c.skipped_zero, 1u);
    EXPECT_EQ(c.skipped_range, 1u);
    skipped += c.skipped_invalid + c.skipped_zero + c.skipped_range + c.out_of_range;
  }
  std::uint64_t total = 0;
  for (const Frame &f : frames) total += f.points.size();
  const fs::path dir = test::scratchDir("tile_bucket");
  for (const auto &[key, n] : bucketer.tiles()) {
    kept += n;
    const std::vector<BucketFrame> &mine = bucketer.framesOf(key);
    const fs::path p = dir / (test::keyName(key) + ".bkt");
    writeTileBucket(p.string(), bucketer.layout(), mine);
    const std::vector<BucketFrame> back = readTileBucket(p.string());
    ASSERT_EQ(back.size(), mine.size());
    for (std::size_t k = 0; k < back.size(); ++k) {
      EXPECT_EQ(back[k].frame_index, mine[k].frame_index);
      EXPECT_TRUE(back[k].sensor_to_fixed.matrix() == mine[k].sensor_to_fixed.matrix());
      EXPECT_TRUE(back[k].viewpoint == mine[k].viewpoint);
      EXPECT_EQ(back[k].viewpoint.y(), 0.0005 * double(back[k].frame_index - 9));
      EXPECT_EQ(back[k].points.layout(), mine[k].points.layout());
      EXPECT_EQ(back[k].points.bytes(), mine[k].points.bytes());
      // Each point posed again, as the tile's pipeline will, lies in this tile.
      std::vector<double> xyz;
      std::vector<std::uint32_t> idx;
      SkippedPoints s;
      Frame f;
      f.points = back[k].points;
      f.sensor_to_fixed = back[k].sensor_to_fixed;
      f.viewpoint = back[k].viewpoint;
      poseFramePoints(f, config.input, xyz, idx, s);
      ASSERT_EQ(idx.size(), f.points.size());
      for (std::uint32_t i : idx) {
        TileKey at;
        ASSERT_TRUE(grid.tileOf(&xyz[3 * i], at));
        ASSERT_EQ(at, key);
      }
    }
  }
  EXPECT_EQ(kept + skipped, total);
  EXPECT_GT(bucketer.tiles().size(), 16u);
  EXPECT_THROW(bucketer.addFrame(frames[0], 11), std::invalid_argument);  // frame order
}

TEST(TileBucket, DamagedFilesAreRefusedWithTheirPath) {
  const HpdsConfig config = mapConfig(1.0, 4);
  const TileGrid grid(config.hierarchy, 2.0);
  TileBucketer bucketer(config, grid);
  bucketer.addFrame(test::denseFrames(1, 500, 3)[0], 0);
  const fs::path dir = test::scratchDir("tile_bucket_damaged");
  const auto [key, n] = bucketer.tiles().front();
  const fs::path p = dir / "t.bkt";
  writeTileBucket(p.string(), bucketer.layout(), bucketer.framesOf(key));
  std::ifstream in(p, std::ios::binary);
  const std::vector<char> good((std::istreambuf_iterator<char>(in)), {});
  auto refused = [&](const std::vector<char> &bytes, const std::string &what) {
    const fs::path q = dir / "bad.bkt";
    std::ofstream(q, std::ios::binary | std::ios::trunc).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    try {
      (void)readTileBucket(q.string());
      ADD_FAILURE() << what << " accepted";
    } catch (const std::runtime_error &e) {
      EXPECT_NE(std::string(e.what()).find(q.string()), std::string::npos) << e.what();
    }
  };
  std::vector<char> b = good;
  b[b.size() / 2] ^= 0x10;
  refused(b, "flipped bit");
  refused(std::vector<char>(good.begin(), good.end() - 7), "truncated");
  refused(std::vector<char>(good.begin(), good.begin() + 5), "stub");
  b = good;
  b.insert(b.end() - 4, 'x');
  refused(b, "extra byte");
  b = good;
  b[0] = 'X';
  refused(b, "magic");
  EXPECT_THROW((void)readTileBucket((dir / "missing.bkt").string()), std::runtime_error);
  // No temporary is left beside a written bucket.
  for (const auto &e : fs::directory_iterator(dir)) EXPECT_EQ(e.path().filename().string().find("tmp"), std::string::npos);
}

TEST(TiledBuild, RefusesConfigsThatDropSamples) {
  HpdsConfig c = mapConfig(1.0, 4);
  EXPECT_NO_THROW(validateTiledConfig(c));
  c.map.evict_distance = 50.0;
  EXPECT_THROW(validateTiledConfig(c), std::invalid_argument);
  c = mapConfig(1.0, 4);
  c.map.max_samples = 1000;
  try {
    validateTiledConfig(c);
    ADD_FAILURE();
  } catch (const std::invalid_argument &e) {
    EXPECT_EQ(std::string(e.what()).rfind("map.max_samples", 0), 0u) << e.what();
  }
  c = mapConfig(1.0, 4);
  c.mode = Mode::Scan;
  EXPECT_THROW(validateTiledConfig(c), std::invalid_argument);
}

// The union of the tiles keeps one map run's guarantees, and is exactly what one hierarchy gives when it is fed the
// same batches in phase order: a tile sees every sample that can reject any of its points.
void checkBuildAgainstOracles(const HpdsConfig &config, double tile, int frames, int points, const std::string &tag) {
  const TileGrid grid(config.hierarchy, tile);
  const std::vector<Frame> input = test::denseFrames(frames, points, 21);
  const TiledRun run = test::runTiled(config, grid, input, test::scratchDir(tag));
  ASSERT_GE(run.tiles.size(), 9u);
  const std::vector<test::Sample> tiled = test::unionOf(run);
  ASSERT_GT(tiled.size(), 500u);

  Pipeline oracle(config);
  for (int phase = 0; phase < 4; ++phase)
    for (const TileKey &key : run.tiles) {
      if (TileGrid::phase(key) != phase) continue;
      for (const fs::path &bucket : run.buckets.at(key))
        for (BucketFrame &f : readTileBucket(bucket.string())) {
          Frame frame;
          frame.points = std::move(f.points);
          frame.sensor_to_fixed = f.sensor_to_fixed;
          frame.viewpoint = f.viewpoint;
          oracle.setNextFrameIndex(f.frame_index);
          oracle.addFrame(frame);
        }
    }
  std::vector<test::Sample> one = test::samplesOf(oracle.hierarchy());
  std::sort(one.begin(), one.end());
  ASSERT_EQ(tiled.size(), one.size());
  EXPECT_TRUE(tiled == one) << "the tiles differ from one hierarchy fed the same batches";

  const int depth = oracle.buildDepth();
  const test::Violations v =
      test::checkGuarantees(tiled, test::insertedPoints(config, input), config.hierarchy.cell_size, depth);
  EXPECT_EQ(v.cells, 0u);
  EXPECT_EQ(v.spacing, 0u);
  EXPECT_EQ(v.coverage, 0u);

  // Counts add up: every point of the tiles' buckets went through a tile's pipeline.
  std::uint64_t accepted = 0, written = 0;
  for (const auto &[key, s] : run.built) {
    accepted += s.counters.accepted;
    EXPECT_EQ(s.samples, s.counters.accepted);
  }
  for (const auto &[key, s] : run.finished) written += s.samples;
  EXPECT_EQ(accepted, tiled.size());
  const int out = resolveOutputLevel(config);
  EXPECT_EQ(written, static_cast<std::uint64_t>(std::count_if(tiled.begin(), tiled.end(),
                                                              [&](const test::Sample &s) { return s.level <= out; })));
}

TEST(TiledBuild, BordersOnDenseWallsKeepEveryGuaranteeAndMatchOneHierarchy) {
  checkBuildAgainstOracles(mapConfig(1.0, 3), 1.0, 4, 6000, "tiled_k1");
}

TEST(TiledBuild, LargerTilesAndAFeatureOrderToo) {
  HpdsConfig c = mapConfig(0.5, 3);
  c.order.type = InsertionOrder::SurfaceVariation;
  checkBuildAgainstOracles(c, 1.0, 3, 6000, "tiled_k2");
}

TEST(TiledBuild, TilesIgnoringTheirNeighboursBreakAtTheSeams) {
  // The negative control: the same build without the border samples has violations, so the checks above can fail.
  const HpdsConfig config = mapConfig(1.0, 3);
  const TileGrid grid(config.hierarchy, 1.0);
  const std::vector<Frame> input = test::denseFrames(4, 6000, 21);
  TiledRunOptions o;
  o.read_borders = false;
  const TiledRun run = test::runTiled(config, grid, input, test::scratchDir("tiled_blind"), o);
  const test::Violations v = test::checkGuarantees(test::unionOf(run), {}, config.hierarchy.cell_size, 3);
  EXPECT_EQ(v.cells, 0u);  // cells never cross a tile border
  EXPECT_GT(v.spacing, 20u);
}

TEST(TiledBuild, ScheduleAndChunkingDoNotChangeABit) {
  const HpdsConfig config = mapConfig(1.0, 3);
  const TileGrid grid(config.hierarchy, 1.0);
  const std::vector<Frame> input = test::denseFrames(4, 3000, 8);
  const TiledRun a = test::runTiled(config, grid, input, test::scratchDir("tiled_sched_a"));
  TiledRunOptions o;
  o.reverse_in_phase = true;
  o.chunk = 3;
  const TiledRun b = test::runTiled(config, grid, input, test::scratchDir("tiled_sched_b"), o);
  ASSERT_EQ(a.tiles.size(), b.tiles.size());
  for (const TileKey &key : a.tiles) {
    EXPECT_EQ(test::readText(a.maps.at(key)), test::readText(b.maps.at(key))) << test::keyName(key);
    EXPECT_EQ(test::readText(a.plys.at(key)), test::readText(b.plys.at(key))) << test::keyName(key);
  }
}

TEST(TiledBuild, DifferentFieldsAcrossFramesAreRefused) {
  const HpdsConfig config = mapConfig(1.0, 3);
  const TileGrid grid(config.hierarchy, 1.0);
  std::vector<Frame> input = test::denseFrames(2, 500, 8);
  TileBucketer bucketer(config, grid);
  bucketer.addFrame(input[0], 0);
  PointLayout other;
  other.append("x", FieldType::Float32);
  other.append("y", FieldType::Float32);
  other.append("z", FieldType::Float32);
  Frame f;
  f.points = PointBuffer(other, 10);
  EXPECT_THROW(bucketer.addFrame(f, 1), std::invalid_argument);
}

// neighborhoodReach: samples beyond it never change a normal (the tiled build's normals read no farther).
TEST(NormalReach, SamplesBeyondTheReachDoNotChangeTheNormals) {
  const HpdsConfig base = mapConfig(0.5, 5);
  Pipeline p(base);
  for (const Frame &f : test::denseFrames(2, 8000, 4)) p.addFrame(f);
  const Hierarchy &full = p.hierarchy();
  std::vector<NormalParams> cases;
  for (int k : {0, 8})
    for (double radius : {0.0, 0.12, 1.4})
      for (int offset : {0, 2})
        for (double growth : {1.0, 8.0}) {
          if (k == 0 && radius == 0.0 && offset == 0 && growth == 1.0) continue;  // not a config normalParamsFor makes
          NormalParams np;
          np.level = 3;
          np.k = k;
          np.radius = radius;
          np.min_neighbors = 5;
          np.neighborhood_level_offset = offset;
          np.max_growth = growth;
          cases.push_back(np);
        }
  // Queries: the level-<=3 samples in a small box; the cut hierarchy keeps only samples within reach of one of them.
  std::vector<SampleId> queries;
  for (SampleId id = 0; id < full.idBound(); ++id) {
    const double *q = full.position(id);
    if (full.level(id) <= 3 && std::fabs(q[0] - 0.2) < 0.3 && std::fabs(q[1] + 0.4) < 0.3) queries.push_back(id);
  }
  ASSERT_GT(queries.size(), 10u);
  for (const NormalParams &np : cases) {
    const double reach = neighborhoodReach(np, full.cellSize(), full.radius(np.level));
    Hierarchy cut(full.cellSize(), full.maxDepth());
    std::vector<SampleId> cut_queries;
    std::size_t dropped = 0;
    for (SampleId id = 0; id < full.idBound(); ++id) {
      bool near = false;
      for (SampleId q : queries) {
        double d2 = 0.0;
        for (int a = 0; a < 3; ++a) d2 += (full.position(id)[a] - full.position(q)[a]) * (full.position(id)[a] - full.position(q)[a]);
        near |= d2 <= reach * reach;
      }
      if (!near) {
        ++dropped;
        continue;
      }
      const auto v = full.toViewpoint(id);
      const SampleId nid = cut.restoreSample(full.position(id), full.level(id), full.frameIndex(id), v.data(), nullptr);
      if (std::find(queries.begin(), queries.end(), id) != queries.end()) cut_queries.push_back(nid);
    }
    ASSERT_EQ(cut_queries.size(), queries.size());
    const std::vector<SampleNormal> a = estimateNormals(full, queries, np), b = estimateNormals(cut, cut_queries, np);
    const std::string what = "k " + std::to_string(np.k) + " radius " + std::to_string(np.radius) + " offset " +
                             std::to_string(np.neighborhood_level_offset) + " growth " + std::to_string(np.max_growth);
    if (reach < 1.0) {
      EXPECT_GT(dropped, 0u) << what;  // the cut must actually remove something
    }
    for (std::size_t i = 0; i < queries.size(); ++i) {
      ASSERT_EQ(a[i].valid, b[i].valid) << what;
      if (!a[i].valid) continue;
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[i].normal[c], b[i].normal[c], 1e-5) << what;
      EXPECT_NEAR(a[i].curvature, b[i].curvature, 1e-6) << what;
    }
  }
}

}  // namespace
}  // namespace hpds
