// The tiled map build's output files: each tile's PLY holds its samples of the output levels in the `hpds sample`
// layout, and its normals (and covariances) are those one hierarchy holding the whole map gives (the neighbours'
// border samples are read for them); without the neighbours they are not (the negative control).
#include <gtest/gtest.h>

#include <cstring>

#include "TestData.hpp"
#include "TiledRun.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/normals/SampleCovariance.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/pipeline/OutputCloud.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;

HpdsConfig normalsConfig() {
  HpdsConfig c;
  c.mode = Mode::Map;
  c.hierarchy.cell_size = 1.0;
  c.hierarchy.max_depth = 4;
  c.output.level = 3;
  c.normals.enabled = true;
  c.map.evict_distance = 0.0;  // a tiled build keeps every sample
  c.map.max_samples = 0;
  return c;
}

struct OutputSample {
  float xyz[3];
  int level;
  float normal[3];
  float curvature;
};

std::vector<OutputSample> readTile(const fs::path &ply, const PointLayout &expected_layout) {
  const PointBuffer cloud = readPointCloud(ply.string());
  const PointLayout &l = cloud.layout();
  // The PLY holds the fields' values, not the record padding: names, types and order are what must match.
  EXPECT_EQ(l.fields.size(), expected_layout.fields.size()) << ply;
  for (std::size_t f = 0; f < std::min(l.fields.size(), expected_layout.fields.size()); ++f) {
    EXPECT_EQ(l.fields[f].name, expected_layout.fields[f].name) << ply;
    EXPECT_EQ(l.fields[f].type, expected_layout.fields[f].type) << ply;
  }
  std::vector<OutputSample> out(cloud.size());
  const char *names[8] = {"x", "y", "z", "level", "normal_x", "normal_y", "normal_z", "curvature"};
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    double v[8];
    for (int k = 0; k < 8; ++k) v[k] = readAsDouble(cloud.record(i), *l.find(names[k]));
    out[i] = OutputSample{{float(v[0]), float(v[1]), float(v[2])}, int(v[3]), {float(v[4]), float(v[5]), float(v[6])}, float(v[7])};
  }
  return out;
}

/// One hierarchy holding every tile's samples (the reference for what the tiles wrote), and each sample's id in it
/// by its float position (as the PLYs hold it).
struct MergedTiles {
  Hierarchy h;
  std::map<std::array<float, 3>, SampleId> by_position;
};

MergedTiles mergeTiles(const HpdsConfig &config, const test::TiledRun &run) {
  MergedTiles m{Hierarchy(config.hierarchy.cell_size, config.hierarchy.max_depth), {}};
  for (const TileKey &key : run.tiles) {
    const Hierarchy h = loadHierarchy(run.maps.at(key).string()).hierarchy;
    m.h.setRecordLayout(h.recordLayout());
    for (SampleId id = 0; id < h.idBound(); ++id) {
      const auto v = h.toViewpoint(id);
      const SampleId to = m.h.restoreSample(h.position(id), h.level(id), h.frameIndex(id), v.data(), h.record(id));
      const double *p = h.position(id);
      m.by_position[{float(p[0]), float(p[1]), float(p[2])}] = to;
    }
  }
  return m;
}

TEST(TiledOutput, TilePlysHoldTheOutputLevelsWithTheNormalsOfTheWholeMap) {
  const HpdsConfig config = normalsConfig();
  const TileGrid grid(config.hierarchy, 1.0);
  ASSERT_GE(normalRing(config), 1);
  const std::vector<Frame> input = test::denseFrames(3, 6000, 31);
  const test::TiledRun run = test::runTiled(config, grid, input, test::scratchDir("tiled_out"));

  // One hierarchy holding every tile's samples: the reference for the normals.
  const MergedTiles m = mergeTiles(config, run);
  const Hierarchy &merged = m.h;
  const auto &by_position = m.by_position;
  std::vector<SampleId> queries = merged.samplesUpTo(config.output.level);
  const std::vector<SampleNormal> reference =
      estimateNormals(merged, queries, normalParamsFor(config, config.output.level));
  std::map<SampleId, SampleNormal> expected;
  for (std::size_t i = 0; i < queries.size(); ++i) expected[queries[i]] = reference[i];

  const PointLayout layout = outputLayout(input[0].points.layout(), true, false);
  std::size_t written = 0, valid = 0, near_border = 0;
  for (const TileKey &key : run.tiles) {
    const std::vector<OutputSample> tile = readTile(run.plys.at(key), layout);
    EXPECT_EQ(tile.size(), run.finished.at(key).samples);
    for (const OutputSample &s : tile) {
      ASSERT_LE(s.level, config.output.level);
      const auto it = by_position.find({s.xyz[0], s.xyz[1], s.xyz[2]});
      ASSERT_NE(it, by_position.end());
      ASSERT_EQ(merged.level(it->second), s.level);
      const SampleNormal &e = expected.at(it->second);
      ASSERT_EQ(e.valid, !std::isnan(s.normal[0]));
      ++written;
      std::int64_t cx, cy;
      grid.cellColumn(merged.position(it->second), cx, cy);
      near_border += grid.borderDepth(cx, cy) <= 1 ? 1 : 0;  // with k = 1: every sample
      if (!e.valid) continue;
      ++valid;
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(s.normal[a], e.normal[a], 1e-5);
      EXPECT_NEAR(s.curvature, e.curvature, 1e-6);
    }
  }
  EXPECT_EQ(written, queries.size());
  EXPECT_GT(valid, written / 2);
  EXPECT_EQ(near_border, written);
}

// The tile maps hold the finer levels the normals average (normals.neighborhood_level_offset): map mode alone
// builds none for them (it keeps per-frame normals, which tile map files do not carry).
TEST(TiledOutput, TileMapsHoldTheFinerLevelsTheNormalsAverage) {
  const HpdsConfig config = normalsConfig();
  ASSERT_GT(config.normals.neighborhood_level_offset, 0);
  const int fine = std::min(config.hierarchy.max_depth, config.output.level + config.normals.neighborhood_level_offset);
  ASSERT_GT(fine, config.output.level);
  EXPECT_EQ(Pipeline(tilePipelineConfig(config)).buildDepth(), fine);
  HpdsConfig plain = config;
  plain.normals.enabled = false;
  EXPECT_EQ(Pipeline(tilePipelineConfig(plain)).buildDepth(), config.output.level) << "no normals: nothing finer";

  const TileGrid grid(config.hierarchy, 1.0);
  const std::vector<Frame> input = test::denseFrames(3, 6000, 31);
  const test::TiledRun run = test::runTiled(config, grid, input, test::scratchDir("tiled_fine"));
  const MergedTiles m = mergeTiles(config, run);
  std::size_t finer = 0;
  for (SampleId id = 0; id < m.h.idBound(); ++id) finer += m.h.level(id) > config.output.level;
  EXPECT_GT(finer, m.h.sampleCount() / 2) << "tile maps without the levels below the output";
}

TEST(TiledOutput, NormalsWithoutTheNeighboursSamplesDiffer) {
  const HpdsConfig config = normalsConfig();
  const TileGrid grid(config.hierarchy, 1.0);
  const test::TiledRun run = test::runTiled(config, grid, test::denseFrames(3, 6000, 31), test::scratchDir("tiled_out_b"));
  const PointLayout layout = outputLayout(test::denseFrames(1, 1, 1)[0].points.layout(), true, false);
  std::size_t differ = 0;
  for (const TileKey &key : run.tiles) {
    const fs::path alone = run.plys.at(key).string() + ".alone.ply";
    finishTile(config, grid, key, run.maps.at(key).string(), {}, alone.string());
    const std::vector<OutputSample> a = readTile(run.plys.at(key), layout), b = readTile(alone, layout);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      const bool va = !std::isnan(a[i].normal[0]), vb = !std::isnan(b[i].normal[0]);
      differ += va != vb || (va && std::fabs(a[i].normal[0] - b[i].normal[0]) > 1e-3) ? 1 : 0;
    }
  }
  EXPECT_GT(differ, 50u);
}

// With covariances the tiles also read as far as the covariances' k nearest samples reach (normalRing): each
// tile's covariances are those of one hierarchy holding the whole map, for either plane normal.
TEST(TiledOutput, CovariancesAreWrittenWhenAskedAsTheWholeMapGivesThem) {
  for (const int covariance_k : {0, HpdsConfig{}.normals.covariance_k}) {
    SCOPED_TRACE("covariance_k " + std::to_string(covariance_k));
    HpdsConfig config = normalsConfig();
    config.normals.covariances = true;
    config.normals.covariance_k = covariance_k;
    HpdsConfig without = config;
    without.normals.covariances = false;
    if (covariance_k > 0) {
      EXPECT_GT(normalRing(config), normalRing(without));
    }
    const TileGrid grid(config.hierarchy, 1.0);
    const test::TiledRun run = test::runTiled(config, grid, test::denseFrames(3, 6000, 31),
                                              test::scratchDir("tiled_cov_" + std::to_string(covariance_k)));
    const MergedTiles m = mergeTiles(config, run);
    const int level = config.output.level;
    const std::vector<SampleId> ids = m.h.samplesUpTo(level);
    std::vector<LocalPca> neighbourhoods;
    const std::vector<SampleNormal> normals =
        estimateNormals(m.h, ids, normalParamsFor(config, level), &neighbourhoods);
    const std::vector<SampleCovariance> reference =
        estimateCovariances(m.h, ids, level, normals, neighbourhoods, config);
    std::map<SampleId, std::size_t> index_of;
    for (std::size_t i = 0; i < ids.size(); ++i) index_of[ids[i]] = i;

    std::size_t planes = 0, written = 0;
    const char *names[6] = {"cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"};
    for (const TileKey &key : run.tiles) {
      const PointBuffer cloud = readPointCloud(run.plys.at(key).string());
      const PointLayout &l = cloud.layout();
      for (const char *name : names) ASSERT_NE(l.find(name), nullptr) << name;
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        const std::uint8_t *r = cloud.record(i);
        const std::array<float, 3> at{float(readAsDouble(r, *l.find("x"))), float(readAsDouble(r, *l.find("y"))),
                                      float(readAsDouble(r, *l.find("z")))};
        const SampleCovariance &e = reference.at(index_of.at(m.by_position.at(at)));
        ++written;
        for (int k = 0; k < 6; ++k) {
          const double c = readAsDouble(r, *l.find(names[k]));
          ASSERT_EQ(std::isnan(c), !e.valid) << names[k];
          if (e.valid) {
            EXPECT_NEAR(c, e.cov[k], 1e-5) << names[k];
          }
        }
        planes += e.valid && !(e.cov[0] == 1.0f && e.cov[3] == 1.0f && e.cov[5] == 1.0f) ? 1 : 0;
      }
    }
    EXPECT_EQ(written, ids.size());
    EXPECT_GT(planes, 100u);
  }
}

// Frames already in the fixed frame (a georeferenced survey) with identity poses give a tiled build the normals of the
// same points in their sensor's frame with poses, when each frame's viewpoint says where its sensor was. Bucket files
// used to keep the pose only, and the build refused such frames; without the viewpoint the normals face the origin.
TEST(TiledOutput, WorldFramesWithTheirViewpointsGiveTheSensorFramesNormals) {
  const HpdsConfig config = normalsConfig();
  const TileGrid grid(config.hierarchy, 1.0);
  const std::vector<Frame> sensor = test::denseFrames(3, 6000, 41);
  std::vector<Frame> world, world_at_origin;
  PointLayout l;
  for (const char *axis : {"x", "y", "z"}) l.append(axis, FieldType::Float64);
  l.append("intensity", FieldType::Float32);
  for (const Frame &f : sensor) {
    // Each point where the pipeline poses it, to the bit (R p + t in double): identity poses then give the same map.
    std::vector<double> xyz;
    std::vector<std::uint32_t> kept;
    SkippedPoints skipped;
    poseFramePoints(f, config.input, xyz, kept, skipped);
    ASSERT_EQ(kept.size(), f.points.size());
    Frame w;
    w.points = PointBuffer(l, f.points.size());
    for (std::size_t i = 0; i < f.points.size(); ++i) {
      std::memcpy(w.points.record(i), &xyz[3 * i], 24);
      std::memcpy(w.points.record(i) + 24, f.points.record(i) + 12, 4);
    }
    w.viewpoint = f.sensor_to_fixed.translation();
    world.push_back(w);
    w.viewpoint = Eigen::Vector3d::Zero();
    world_at_origin.push_back(std::move(w));
  }
  const auto normalsOf = [&](const std::vector<Frame> &frames, const std::string &tag) {
    const test::TiledRun run = test::runTiled(config, grid, frames, test::scratchDir(tag));
    std::map<std::array<float, 3>, std::array<float, 3>> out;
    for (const TileKey &key : run.tiles) {
      const PointBuffer cloud = readPointCloud(run.plys.at(key).string());
      const PointLayout &c = cloud.layout();
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        const std::uint8_t *r = cloud.record(i);
        out[{float(readAsDouble(r, *c.find("x"))), float(readAsDouble(r, *c.find("y"))),
             float(readAsDouble(r, *c.find("z")))}] = {float(readAsDouble(r, *c.find("normal_x"))),
                                                       float(readAsDouble(r, *c.find("normal_y"))),
                                                       float(readAsDouble(r, *c.find("normal_z")))};
      }
    }
    return out;
  };
  const auto posed = normalsOf(sensor, "tiled_vp_sensor");
  const auto given = normalsOf(world, "tiled_vp_world");
  const auto origin = normalsOf(world_at_origin, "tiled_vp_origin");
  ASSERT_GT(posed.size(), 500u);
  ASSERT_EQ(given.size(), posed.size());
  std::size_t same = 0, flipped_at_origin = 0;
  for (const auto &[at, n] : posed) {
    const auto it = given.find(at);
    ASSERT_NE(it, given.end()) << "a sample of the posed build is missing from the world-frame one";
    const bool valid = std::isfinite(n[0]);
    EXPECT_EQ(std::isfinite(it->second[0]), valid);
    if (valid && it->second == n) ++same;
    const auto o = origin.find(at);
    ASSERT_NE(o, origin.end());
    if (valid && n[0] * o->second[0] + n[1] * o->second[1] + n[2] * o->second[2] < 0.0f) ++flipped_at_origin;
  }
  std::size_t valid = 0;
  for (const auto &[at, n] : posed) valid += std::isfinite(n[0]) ? 1 : 0;
  EXPECT_EQ(same, valid) << "normals differ between the posed and the world-frame builds";
  // The negative control: the viewpoint matters (the sensors stand 1.2 m above the ground, away from the origin).
  EXPECT_GT(flipped_at_origin, valid / 20) << "the viewpoint changed no normal";
}

}  // namespace
}  // namespace hpds
