// The pipeline in map mode: earlier samples never move or change level, the samples hit by the last frame against
// brute force, the levels it stores, eviction bounding memory on a long drive, and scratch memory given back after
// one huge frame.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <map>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "PipelineTestSupport.hpp"
#include "TestData.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {
namespace {

using test::makeFrame;
using test::smallLidar;

TEST(Pipeline, MapModeNeverMovesOrRelevelsEarlierSamples) {
  const SyntheticLidar lidar(smallLidar(SceneKind::Urban, 4));
  HpdsConfig c;
  c.mode = Mode::Map;
  Pipeline p(c);
  std::map<SampleId, std::pair<std::array<double, 3>, int>> seen;
  std::size_t first_coarse = 0;
  for (int i = 0; i < 4; ++i) {
    const FrameResult r = p.addFrame(lidar.frame(i).frame);
    for (const auto &[id, v] : seen) {
      ASSERT_TRUE(p.hierarchy().isLive(id));
      const double *q = p.hierarchy().position(id);
      ASSERT_EQ((std::array<double, 3>{q[0], q[1], q[2]}), v.first);
      ASSERT_EQ(p.hierarchy().level(id), v.second);
    }
    ASSERT_EQ(seen.size() + r.new_samples.size(), p.hierarchy().sampleCount());
    for (SampleId id : r.new_samples) {
      ASSERT_EQ(p.hierarchy().frameIndex(id), static_cast<std::uint32_t>(i));
      const double *q = p.hierarchy().position(id);
      ASSERT_TRUE(seen.emplace(id, std::make_pair(std::array<double, 3>{q[0], q[1], q[2]}, p.hierarchy().level(id))).second);
    }
    std::size_t coarse_new = 0;
    for (SampleId id : r.new_samples) coarse_new += p.hierarchy().level(id) <= 4 ? 1 : 0;
    if (i == 0) first_coarse = coarse_new;
    // Frames 1 m apart see the same street: at 0.2 m spacing most of it is already sampled.
    if (i > 0) {
      EXPECT_LT(coarse_new, first_coarse / 2) << "frame " << i;
    }
  }
}

TEST(Pipeline, SamplesHitByTheLastFrameMatchBruteForce) {
  SyntheticLidarConfig lc = smallLidar(SceneKind::Urban, 3);
  lc.beams = 8;
  lc.azimuth_steps = 360;
  const SyntheticLidar lidar(lc);
  HpdsConfig c;
  c.mode = Mode::Map;
  c.output.level = 4;
  Pipeline p(c);
  p.addFrame(lidar.frame(0).frame);
  p.addFrame(lidar.frame(1).frame);
  const Frame last = lidar.frame(2).frame;
  p.addFrame(last);
  const Hierarchy &h = p.hierarchy();
  const double radius = 2.0 * h.radius(4);
  // The frame's valid points in the map frame, by the pipeline's own rules (no NaN here; zeros are no-returns).
  std::vector<Eigen::Vector3d> pts;
  const PointLayout &l = last.points.layout();
  for (std::size_t i = 0; i < last.points.size(); ++i) {
    const Eigen::Vector3d v(readAsDouble(last.points.record(i), *l.find("x")), readAsDouble(last.points.record(i), *l.find("y")),
                            readAsDouble(last.points.record(i), *l.find("z")));
    if (v.isZero(0.0)) continue;
    pts.push_back(last.sensor_to_fixed.linear() * v + last.sensor_to_fixed.translation());
  }
  const std::vector<SampleId> hit = p.samplesHitByLastFrame(1, 4, radius);
  std::vector<SampleId> want;
  for (SampleId id : h.samplesUpTo(4)) {
    if (h.level(id) < 1) continue;
    const Eigen::Vector3d s(h.position(id)[0], h.position(id)[1], h.position(id)[2]);
    for (const auto &q : pts)
      if ((q - s).squaredNorm() < radius * radius) {
        want.push_back(id);
        break;
      }
  }
  std::vector<SampleId> only_hit, only_want;
  std::set_difference(hit.begin(), hit.end(), want.begin(), want.end(), std::back_inserter(only_hit));
  std::set_difference(want.begin(), want.end(), hit.begin(), hit.end(), std::back_inserter(only_want));
  for (SampleId id : only_hit) ADD_FAILURE() << "extra " << id << " level " << h.level(id);
  for (SampleId id : only_want) ADD_FAILURE() << "missing " << id << " level " << h.level(id);
  EXPECT_EQ(hit, want);
  // Coverage: with radius 2 r_L every point of the sweep has a hit sample of levels 0..L.
  const std::vector<SampleId> all = p.samplesHitByLastFrame(0, 4, radius * (1 + 1e-9));
  for (std::size_t i = 0; i < pts.size(); i += 13) {
    bool covered = false;
    for (SampleId id : all)
      covered = covered || (pts[i] - Eigen::Vector3d(h.position(id)[0], h.position(id)[1], h.position(id)[2])).norm() <= radius * (1 + 1e-9);
    ASSERT_TRUE(covered) << "point " << i;
  }
}

TEST(Pipeline, MapModeStoresOnlyTheLevelsItReadsUnlessAskedToKeepMore) {
  HpdsConfig c;
  c.mode = Mode::Map;
  // The shipped defaults in map mode: output level 5 (r = 0.1 m), nothing finer (the normals average each frame's
  // points per cell of level 7 instead of building levels 6..7).
  EXPECT_EQ(Pipeline(c).buildDepth(), 5);
  // Spacing 0.4 m without normals: output level 3, built alone unless map.keep_depth asks for levels 4..5 too.
  c.output.spacing = 0.4;
  c.normals.enabled = false;
  const SyntheticLidar lidar(smallLidar(SceneKind::Urban, 2));
  Pipeline lean(c);
  c.map.keep_depth = 5;
  Pipeline kept(c);
  ASSERT_EQ(lean.outputLevel(), 3);
  ASSERT_EQ(lean.buildDepth(), 3);
  ASSERT_EQ(kept.buildDepth(), 5);
  for (int i = 0; i < 2; ++i) {
    const Frame f = lidar.frame(i).frame;
    const FrameResult a = lean.addFrame(f), b = kept.addFrame(f);
    EXPECT_EQ(a.counters.accepted_per_level[4] + a.counters.accepted_per_level[5], 0u);
    EXPECT_GT(b.counters.accepted_per_level[4], 0u);
    EXPECT_GT(b.counters.accepted_per_level[5], 0u);
    EXPECT_GT(a.counters.dropped_depth, b.counters.dropped_depth);
  }
  EXPECT_EQ(lean.hierarchy().countAtLevel(4) + lean.hierarchy().countAtLevel(5), 0u);
  EXPECT_GT(kept.hierarchy().countAtLevel(5), 0u);
  EXPECT_LT(lean.hierarchy().memUsage(), kept.hierarchy().memUsage());
  // Both maps keep the Poisson property of their output (levels 0..3 at r_3 = 0.4 m), by brute force.
  for (const Pipeline *p : {&lean, &kept}) {
    const std::vector<SampleId> ids = p->outputSamples();
    ASSERT_GT(ids.size(), 100u);
    double min_d2 = INFINITY;
    for (std::size_t i = 0; i < ids.size(); ++i)
      for (std::size_t j = i + 1; j < ids.size(); ++j) {
        const double *u = p->hierarchy().position(ids[i]), *v = p->hierarchy().position(ids[j]);
        min_d2 = std::min(min_d2, (u[0] - v[0]) * (u[0] - v[0]) + (u[1] - v[1]) * (u[1] - v[1]) + (u[2] - v[2]) * (u[2] - v[2]));
      }
    EXPECT_GE(std::sqrt(min_d2), 0.4);
  }
}

TEST(Pipeline, EvictionBoundsMemoryOnALongDrive) {
  SyntheticLidarConfig lc = smallLidar(SceneKind::Urban, 40);
  lc.speed = 4.0;
  lc.yaw_rate = 0.0;
  const SyntheticLidar lidar(lc);
  HpdsConfig c;
  c.mode = Mode::Map;
  c.map.evict_distance = 30.0;
  c.map.max_samples = 0;
  c.hierarchy.cell_size = 4.0;
  c.hierarchy.max_depth = 6;
  c.output.level = 6;
  c.normals.enabled = false;
  Pipeline p(c);
  std::size_t peak_after_warmup = 0, peak_bytes_late = 0, bytes_at_20 = 0;
  for (int i = 0; i < 40; ++i) {
    const Frame f = lidar.frame(i).frame;
    const FrameResult r = p.addFrame(f);
    const Eigen::Vector3d s = f.sensor_to_fixed.translation();
    for (SampleId id = 0; id < p.hierarchy().idBound(); ++id)
      if (p.hierarchy().isLive(id) && std::find(r.new_samples.begin(), r.new_samples.end(), id) == r.new_samples.end()) {
        const double *q = p.hierarchy().position(id);
        ASSERT_LE((Eigen::Vector3d(q[0], q[1], q[2]) - s).norm(), 30.0 + 1e-9);
      }
    if (i >= 10) peak_after_warmup = std::max(peak_after_warmup, p.hierarchy().sampleCount());
    if (i == 20) bytes_at_20 = p.hierarchy().memUsage();
    if (i > 20) peak_bytes_late = std::max(peak_bytes_late, p.hierarchy().memUsage());
  }
  EXPECT_GT(p.totals().evicted, 0u);
  // 160 m driven, the map keeps ~60 m of street: storage must not keep growing with distance.
  EXPECT_LE(peak_bytes_late, bytes_at_20 * 3 / 2);
  EXPECT_LT(peak_after_warmup, p.totals().accepted / 2);

  HpdsConfig capped = c;
  capped.map.evict_distance = 0.0;
  capped.map.max_samples = 5000;
  Pipeline q(capped);
  // The cap holds after every frame (it used to be exceeded by up to a frame's samples), and the frame's new
  // samples are the ones still stored.
  for (int i = 0; i < 10; ++i) {
    const FrameResult r = q.addFrame(lidar.frame(i).frame);
    ASSERT_LE(q.hierarchy().sampleCount(), 5000u) << "frame " << i;
    for (SampleId id : r.new_samples) ASSERT_TRUE(q.hierarchy().isLive(id)) << "frame " << i;
    if (i >= 2) {
      EXPECT_EQ(q.hierarchy().sampleCount(), 5000u) << "frame " << i;
    }
    (void)q.makeCloud(r.new_samples, false);  // only live ids: it throws for an evicted one
  }
}

TEST(Pipeline, ScratchFromOneHugeFrameIsGivenBackOnceFramesAreSmallAgain) {
  // One frame of 600 k points (a 10 M point frame behaves the same, slower), then small frames: in both modes the
  // memory sized for the huge frame must not stay for the life of the pipeline.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-40.0, 40.0);
  std::vector<std::array<double, 3>> big(600000), small(2000);
  for (auto &p : big) p = {u(rng), u(rng), 0.05 * u(rng)};
  for (auto &p : small) p = {0.2 * u(rng), 0.2 * u(rng), 0.01 * u(rng)};
  const Frame huge = makeFrame(big), little = makeFrame(small);
  for (const Mode mode : {Mode::Scan, Mode::Map}) {
    HpdsConfig c;
    c.mode = mode;
    c.hierarchy.max_depth = 5;
    Pipeline p(c);
    p.addFrame(little);
    const std::size_t before = p.memUsage();
    p.addFrame(huge);
    const std::size_t peak = p.memUsage();
    ASSERT_GT(peak, 20 * before) << "the huge frame must actually need more memory";
    for (int i = 0; i < 40; ++i) p.addFrame(little);
    const std::size_t after = p.memUsage();
    // Scan mode keeps nothing of the huge frame; map mode keeps its samples (no eviction here) but not the
    // per-point scratch (40 B per input point).
    if (mode == Mode::Scan)
      EXPECT_LT(after, 4 * before + (1u << 20)) << "scan mode: " << before << " -> " << peak << " -> " << after;
    else
      EXPECT_LT(after + 30 * big.size(), peak) << "map mode: " << before << " -> " << peak << " -> " << after;
  }
}

}  // namespace
}  // namespace hpds

namespace hpds {
namespace {

double distance(const double *p, const Eigen::Vector3d &q) {
  return (Eigen::Vector3d(p[0], p[1], p[2]) - q).norm();
}

// Map mode keeps per sample the normal of the frame that saw it from closest (MapNormals.hpp), unless that frame left
// it on one scan line (a line-like neighbourhood) and the other did not: a later frame from farther away must not
// replace a planar normal, one from closer must (but not with a line-like one), and a line-like one gives way to a
// planar one from any distance.
TEST(MapNormals, EverySampleKeepsTheNormalOfTheFrameThatSawItFromClosest) {
  SyntheticLidarConfig lc = test::smallLidar(SceneKind::Urban, 2);
  lc.speed = 15.0;
  lc.yaw_rate = 0.0;
  const SyntheticLidar lidar(lc);
  HpdsConfig c;
  c.mode = Mode::Map;
  c.map.evict_distance = 0.0;
  Pipeline p(c);
  const Frame f0 = lidar.frame(0).frame, f1 = lidar.frame(1).frame;
  (void)p.addFrame(f0);
  const std::vector<SampleId> ids = p.outputSamples();
  std::vector<LocalPca> nb_before, nb_after;
  const std::vector<SampleNormal> before = p.normals(ids, &nb_before);
  const FrameResult r1 = p.addFrame(f1);
  EXPECT_GT(r1.seconds_normals, 0.0);
  const std::vector<SampleNormal> after = p.normals(ids, &nb_after);
  const int L = p.outputLevel();
  const std::vector<SampleId> hit = p.samplesHitByLastFrame(0, L, 2.0 * p.hierarchy().radius(L));
  const std::set<SampleId> hit_set(hit.begin(), hit.end());
  const Eigen::Vector3d s0 = f0.sensor_to_fixed.translation(), s1 = f1.sensor_to_fixed.translation();
  // The kept eigenvalues are floats: judged in float, as MapNormals does.
  const float ratio = static_cast<float>(NormalParams{}.line_ratio);
  auto lineLike = [&](const LocalPca &n) { return float(n.l1) < ratio * float(n.l2); };
  std::size_t valid = 0, kept = 0, replaced = 0, could_replace = 0, upgraded = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const double *x = p.hierarchy().position(ids[i]);
    valid += before[i].valid;
    if (!before[i].valid) continue;
    ASSERT_TRUE(after[i].valid) << "a valid normal is never given up";
    const bool same = std::equal(before[i].normal, before[i].normal + 3, after[i].normal) &&
                      before[i].curvature == after[i].curvature;
    const bool was_line = lineLike(nb_before[i]), is_line = lineLike(nb_after[i]);
    // Ranges are compared in float, as kept: a tie keeps the first.
    const bool closer = hit_set.count(ids[i]) &&
                        static_cast<float>(distance(x, s1)) < static_cast<float>(distance(x, s0));
    if (!same) {
      EXPECT_TRUE(hit_set.count(ids[i])) << "sample " << ids[i] << " changed without being hit";
      EXPECT_FALSE(is_line && !was_line) << "sample " << ids[i] << ": a planar normal gave way to a line-like one";
      EXPECT_TRUE(closer || (was_line && !is_line)) << "sample " << ids[i] << " was seen from closer before";
      upgraded += was_line && !is_line && !closer;
    }
    if (!was_line && !closer) {
      kept += same;
      EXPECT_TRUE(same) << "sample " << ids[i] << ": a planar normal seen from closer before";
    }
    if (closer && !was_line) {
      ++could_replace;
      replaced += !same;
    }
    // Faces the sensor of the frame that contributed it.
    const auto v = p.hierarchy().toViewpoint(ids[i]);
    EXPECT_TRUE(test::orientedAsPromised(Eigen::Vector3d(after[i].normal[0], after[i].normal[1], after[i].normal[2]),
                                         Eigen::Vector3d(v[0], v[1], v[2])));
  }
  EXPECT_GT(valid, ids.size() * 95 / 100) << "frame 0's samples get valid normals from frame 0 alone";
  EXPECT_GT(kept, 1000u);
  ASSERT_GT(could_replace, 100u);
  EXPECT_GT(replaced, could_replace / 2) << "samples seen from closer take the closer frame's normal";
  EXPECT_GT(upgraded, 10u) << "line-like normals give way to a farther frame's planar one";
}

}  // namespace
}  // namespace hpds

namespace hpds {
namespace {

// A map that keeps the finer levels anyway (map.keep_depth) reads them for its normals, every frame's points, as
// NormalEstimator does over the hierarchy; without them it keeps per-frame normals (the test above).
TEST(MapNormals, AMapKeepingTheFinerLevelsReadsThem) {
  const SyntheticLidar lidar(test::smallLidar(SceneKind::Urban, 2));
  HpdsConfig c;
  c.mode = Mode::Map;
  c.map.keep_depth = 7;  // output level 5 + neighborhood_level_offset 2
  Pipeline deep(c);
  c.map.keep_depth = -1;
  Pipeline lean(c);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(deep.addFrame(lidar.frame(i).frame).seconds_normals, 0.0) << "nothing kept per frame";
    EXPECT_GT(lean.addFrame(lidar.frame(i).frame).seconds_normals, 0.0);
  }
  ASSERT_EQ(deep.buildDepth(), 7);
  ASSERT_EQ(lean.buildDepth(), 5);
  const std::vector<SampleId> ids = deep.outputSamples();
  const std::vector<SampleNormal> got = deep.normals(ids);
  const std::vector<SampleNormal> want =
      estimateNormals(deep.hierarchy(), ids, normalParamsFor(deep.config(), deep.outputLevel()));
  ASSERT_EQ(got.size(), want.size());
  std::size_t valid = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ASSERT_EQ(got[i].valid, want[i].valid) << i;
    if (!got[i].valid) continue;
    ++valid;
    ASSERT_TRUE(std::equal(got[i].normal, got[i].normal + 3, want[i].normal)) << i;
  }
  EXPECT_GT(valid, ids.size() * 95 / 100);
}

}  // namespace
}  // namespace hpds

namespace hpds {
namespace {

// Map mode estimates every output sample a frame hits (within 2 r_L of its points), earlier frames' samples beyond
// the frame's points too: the search grids over its centroids must serve those queries, not only the ones inside
// the box of its points. Frame B (close) ends at x = 1.40, where the grids' first cell frame left at most 0.06 m of
// margin above its box; frame A (far) reaches x = 2.0.
TEST(MapNormals, SamplesHitBeyondTheFramesPointsTakeTheCloserFramesNormal) {
  HpdsConfig c;
  c.mode = Mode::Map;
  c.hierarchy.cell_size = 1.0;
  c.hierarchy.max_depth = 6;
  c.output.level = 2;  // r_L = 0.217 m; the centroids' cells are of level 4 (6.25 cm)
  c.map.evict_distance = 0.0;
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.003);
  auto plane = [&](double x1) {
    std::vector<std::array<double, 3>> pts;
    for (int i = 0; i * 0.01 <= x1 + 1e-9; ++i)
      for (int j = 0; j <= 100; ++j) pts.push_back({i * 0.01, j * 0.01, noise(rng)});
    return pts;
  };
  Frame a = makeFrame(plane(2.0));
  a.viewpoint = Eigen::Vector3d(-10.0, 0.5, 1.0);
  Frame b = makeFrame(plane(1.40));
  b.viewpoint = Eigen::Vector3d(1.4, 0.5, 0.5);
  Pipeline p(c);
  (void)p.addFrame(a);
  const int L = p.outputLevel();
  const std::vector<SampleId> ids = p.outputSamples();
  const std::vector<SampleNormal> before = p.normals(ids);
  (void)p.addFrame(b);
  const std::vector<SampleId> hit = p.samplesHitByLastFrame(0, L, 2.0 * p.hierarchy().radius(L));
  const std::set<SampleId> hit_set(hit.begin(), hit.end());
  const std::vector<SampleNormal> after = p.normals(ids);
  std::size_t beyond = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (!hit_set.count(ids[i]) || !before[i].valid) continue;
    const double *x = p.hierarchy().position(ids[i]);
    ASSERT_LT(distance(x, b.viewpoint), distance(x, a.viewpoint));
    ASSERT_TRUE(after[i].valid);
    beyond += x[0] > 1.42;
    // Frame B saw it from closer, with its points within the footprint: its estimate replaces frame A's.
    EXPECT_FALSE(std::equal(before[i].normal, before[i].normal + 3, after[i].normal))
        << "sample at x = " << x[0] << " kept the farther frame's normal";
  }
  EXPECT_GE(beyond, 4u) << "samples hit beyond frame B's points";
}

}  // namespace
}  // namespace hpds

namespace hpds {
namespace {

// Map mode keeps one record layout. Frames of the same fields in another order or with other padding are copied
// into it; frames without points neither set nor break it; other fields are refused while the map holds samples.
PointLayout fieldsAt(const std::vector<std::pair<std::string, std::uint32_t>> &at, std::uint32_t step) {
  PointLayout l;
  for (const auto &[name, offset] : at) l.fields.push_back(PointField{name, offset});
  l.point_step = step;
  return l;
}

// A square patch of points 2 cm apart at x0 + [0, 1) x [0, 1), z 0, each with intensity `value` in `l`.
Frame patchIn(const PointLayout &l, double x0, double value) {
  Frame f;
  const int n = 50;
  f.points = PointBuffer(l, std::size_t(n * n));
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      std::uint8_t *r = f.points.record(std::size_t(i * n + j));
      writeFromDouble(r, *l.find("x"), x0 + 0.02 * i);
      writeFromDouble(r, *l.find("y"), 0.02 * j);
      writeFromDouble(r, *l.find("z"), 0.0);
      if (const PointField *in = l.find("intensity")) writeFromDouble(r, *in, value);
    }
  return f;
}

// patchIn with every point's `axis` NaN: a frame with points but no sample.
Frame nanPatchIn(const PointLayout &l, const char *axis) {
  Frame f = patchIn(l, 0.0, 0.0);
  for (std::size_t i = 0; i < f.points.size(); ++i) writeFromDouble(f.points.record(i), *l.find(axis), NAN);
  return f;
}

HpdsConfig layoutTestConfig() {
  HpdsConfig c;
  c.mode = Mode::Map;
  c.normals.enabled = false;
  return c;
}

TEST(PipelineLayout, TheSameFieldsInAnotherOrderOrPaddingAreCopiedIntoTheMapsLayout) {
  const PointLayout map_layout = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}, {"intensity", 12}}, 16);
  const PointLayout padded = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}, {"intensity", 16}}, 32);
  const PointLayout reordered = fieldsAt({{"intensity", 0}, {"x", 4}, {"y", 8}, {"z", 12}}, 16);
  // Oracle: the same frames, every one already in the map's layout.
  Pipeline mixed(layoutTestConfig()), plain(layoutTestConfig());
  const double x0[3] = {0.0, 3.0, 6.0}, value[3] = {10.0, 20.0, 30.0};
  const PointLayout *as[3] = {&map_layout, &padded, &reordered};
  for (int k = 0; k < 3; ++k) {
    ASSERT_NO_THROW((void)mixed.addFrame(patchIn(*as[k], x0[k], value[k]))) << "frame " << k;
    (void)plain.addFrame(patchIn(map_layout, x0[k], value[k]));
  }
  const PointBuffer got = mixed.makeCloud(mixed.outputSamples(), true);
  const PointBuffer want = plain.makeCloud(plain.outputSamples(), true);
  EXPECT_TRUE(got.layout() == want.layout());
  EXPECT_EQ(got.bytes(), want.bytes());
  // Each frame's intensity came along: the patch a sample lies in tells which.
  std::size_t per_frame[3] = {0, 0, 0};
  const PointLayout &out = got.layout();
  for (std::size_t i = 0; i < got.size(); ++i) {
    const int k = static_cast<int>(readAsDouble(got.record(i), *out.find("x")) / 3.0);
    ASSERT_TRUE(k >= 0 && k < 3);
    EXPECT_EQ(readAsDouble(got.record(i), *out.find("intensity")), value[k]);
    ++per_frame[k];
  }
  for (int k = 0; k < 3; ++k) EXPECT_GT(per_frame[k], 20u) << "frame " << k;
}

TEST(PipelineLayout, FramesWithoutPointsNeitherFixNorBreakTheMapsFields) {
  const PointLayout xyz = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}}, 12);
  const PointLayout with_intensity = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}, {"intensity", 12}}, 16);
  Pipeline p(layoutTestConfig());
  // An empty x y z cloud first (what some drivers publish before the first scan): the real frames that follow keep
  // their intensity. It used to fix the map's fields, and every real frame was refused.
  Frame empty;
  empty.points = PointBuffer(xyz, 0);
  ASSERT_NO_THROW((void)p.addFrame(empty));
  ASSERT_NO_THROW((void)p.addFrame(patchIn(with_intensity, 0.0, 42.0)));
  // And empty clouds between them change nothing.
  const std::size_t before = p.hierarchy().sampleCount();
  ASSERT_NO_THROW((void)p.addFrame(empty));
  EXPECT_EQ(p.hierarchy().sampleCount(), before);
  ASSERT_NO_THROW((void)p.addFrame(patchIn(with_intensity, 3.0, 43.0)));
  const PointBuffer out = p.makeCloud(p.outputSamples(), false);
  ASSERT_NE(out.layout().find("intensity"), nullptr);
  for (std::size_t i = 0; i < out.size(); ++i)
    EXPECT_GE(readAsDouble(out.record(i), *out.layout().find("intensity")), 42.0);
}

TEST(PipelineLayout, ALoadedMapWithoutSamplesTakesTheFramesFields) {
  // A map saved before any frame had a sample (here: one frame of NaN points only) keeps that frame's fields; after
  // a restart that loads it, the real frames were all refused. It holds no record, so they are taken.
  const PointLayout xyz = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}}, 12);
  const PointLayout with_intensity = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}, {"intensity", 12}}, 16);
  const std::string path = (test::scratchDir("layout_empty_map") / "empty.hpdsmap").string();
  {
    Pipeline first(layoutTestConfig());
    (void)first.addFrame(nanPatchIn(xyz, "z"));
    ASSERT_EQ(first.hierarchy().sampleCount(), 0u);
    saveMap(path, first);
  }
  Pipeline second(layoutTestConfig());
  (void)loadMap(path, second);
  ASSERT_NO_THROW((void)second.addFrame(patchIn(with_intensity, 0.0, 5.0)));
  const PointBuffer out = second.makeCloud(second.outputSamples(), false);
  ASSERT_GT(out.size(), 0u);
  ASSERT_NE(out.layout().find("intensity"), nullptr);
  EXPECT_EQ(readAsDouble(out.record(0), *out.layout().find("intensity")), 5.0);
}

TEST(PipelineLayout, OtherFieldsAreRefusedOnlyWhileTheMapHoldsSamples) {
  const PointLayout xyz = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}}, 12);
  const PointLayout with_range = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}, {"range", 12}}, 16);
  const PointLayout with_intensity = fieldsAt({{"x", 0}, {"y", 4}, {"z", 8}, {"intensity", 12}}, 16);
  Pipeline p(layoutTestConfig());
  // Points, but none a sample (all NaN): the map has held no sample, so the next frame's fields are taken.
  (void)p.addFrame(nanPatchIn(xyz, "x"));
  ASSERT_EQ(p.hierarchy().sampleCount(), 0u);
  ASSERT_NO_THROW((void)p.addFrame(patchIn(with_intensity, 0.0, 7.0)));
  ASSERT_GT(p.hierarchy().sampleCount(), 0u);
  // Now it holds samples of x y z intensity: other fields would leave their records without a layout.
  try {
    (void)p.addFrame(patchIn(with_range, 3.0, 1.0));
    ADD_FAILURE() << "a frame of other fields was taken";
  } catch (const std::invalid_argument &e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("x y z range as float32 float32 float32 float32, 16 bytes"), std::string::npos) << m;
    EXPECT_NE(m.find("differ from the map's (x y z intensity"), std::string::npos) << m;
  }
  // clearMap is the way out for a stream whose fields changed for good: the map empties, the frame count stays, and
  // the next frame's fields become the map's; its output is that of a fresh pipeline at the same frame index.
  const std::uint32_t frames = p.framesProcessed();
  p.clearMap();
  EXPECT_EQ(p.hierarchy().sampleCount(), 0u);
  EXPECT_EQ(p.framesProcessed(), frames);
  ASSERT_NO_THROW((void)p.addFrame(patchIn(with_range, 3.0, 1.0)));
  Pipeline fresh(layoutTestConfig());
  fresh.setNextFrameIndex(frames);
  (void)fresh.addFrame(patchIn(with_range, 3.0, 1.0));
  const PointBuffer got = p.makeCloud(p.outputSamples(), false), want = fresh.makeCloud(fresh.outputSamples(), false);
  EXPECT_TRUE(got.layout() == want.layout());
  EXPECT_EQ(got.bytes(), want.bytes());
  HpdsConfig scan = layoutTestConfig();
  scan.mode = Mode::Scan;
  Pipeline scanning(scan);
  EXPECT_THROW(scanning.clearMap(), std::invalid_argument);
}

}  // namespace
}  // namespace hpds
