// The per-frame pipeline: determinism, fields carried through, skipped points, map-mode invariants, eviction,
// normals against ground truth and a brute-force PCA, feature-sensitive orders.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include "TestData.hpp"
#include "hpds/normals/LocalPca.hpp"
#include "hpds/sampling/InsertionOrderer.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"

namespace hpds {
namespace {

PointLayout xyzLayout(FieldType t = FieldType::Float32) {
  PointLayout l;
  l.append("x", t);
  l.append("y", t);
  l.append("z", t);
  l.append("intensity", FieldType::UInt8);
  l.append("t", FieldType::Float64);
  return l;
}

Frame makeFrame(const std::vector<std::array<double, 3>> &pts, FieldType t = FieldType::Float32) {
  Frame f;
  f.points = PointBuffer(xyzLayout(t), pts.size());
  const auto &l = f.points.layout();
  for (std::size_t i = 0; i < pts.size(); ++i) {
    for (int a = 0; a < 3; ++a) writeFromDouble(f.points.record(i), l.fields[a], pts[i][a]);
    writeFromDouble(f.points.record(i), *l.find("intensity"), static_cast<double>(i % 251));
    writeFromDouble(f.points.record(i), *l.find("t"), 1e-3 * static_cast<double>(i));
  }
  return f;
}

SyntheticLidarConfig smallLidar(SceneKind scene = SceneKind::Urban, int frames = 3) {
  SyntheticLidarConfig c;
  c.beams = 16;
  c.azimuth_steps = 720;
  c.frames = frames;
  c.scene = scene;
  return c;
}

double angleDeg(const Eigen::Vector3d &a, const Eigen::Vector3d &b) {
  return std::acos(std::clamp(std::abs(a.normalized().dot(b.normalized())), 0.0, 1.0)) * 180.0 / M_PI;
}

// ---------------------------------------------------------------- determinism

TEST(Pipeline, SameSeedSameBytesAndThreadCountDoesNotMatter) {
  const SyntheticLidar lidar(smallLidar());
  // Scan mode's normals average the frame's cell centroids, made beside the insertion when there are threads.
  for (Mode mode : {Mode::Map, Mode::Scan})
  for (InsertionOrder order : {InsertionOrder::Random, InsertionOrder::Sphericity, InsertionOrder::SurfaceVariation}) {
    std::vector<std::uint8_t> reference;
    for (int threads : {1, 2, 3}) {
      HpdsConfig c;
      c.mode = mode;
      c.order.type = order;
      c.order.seed = 42;
      c.normals.enabled = true;
      c.output.level = 5;
      c.threads = threads;
      Pipeline p(c);
      for (int i = 0; i < 3; ++i) p.addFrame(lidar.frame(i).frame);
      const PointBuffer out = p.makeCloud(p.outputSamples(), false);
      ASSERT_GT(out.size(), 1000u);
      if (reference.empty()) {
        reference = out.bytes();
      } else {
        ASSERT_EQ(out.bytes(), reference) << toString(mode) << ", " << toString(order) << " differs with " << threads
                                          << " threads";
      }
    }
  }
}

TEST(Pipeline, DifferentSeedDifferentSampling) {
  const SyntheticLidar lidar(smallLidar());
  const Frame f = lidar.frame(0).frame;
  HpdsConfig c;
  c.order.seed = 1;
  Pipeline a(c);
  a.addFrame(f);
  c.order.seed = 2;
  Pipeline b(c);
  b.addFrame(f);
  EXPECT_NE(a.makeCloud(a.outputSamples(), false).bytes(), b.makeCloud(b.outputSamples(), false).bytes());
}

// ---------------------------------------------------------------- fields and skipped points

TEST(Pipeline, SamplesAreRealInputPointsWithEveryFieldUnchanged) {
  const SyntheticLidar lidar(smallLidar());
  const SyntheticFrame sf = lidar.frame(1);
  Frame f = sf.frame;
  f.sensor_to_fixed.setIdentity();  // compare in the sensor frame
  HpdsConfig c;
  Pipeline p(c);
  p.addFrame(f);
  const PointBuffer out = p.makeCloud(p.outputSamples(), false);
  const PointLayout &in = f.points.layout();
  std::map<std::array<float, 3>, std::size_t> by_xyz;
  for (std::size_t i = 0; i < f.points.size(); ++i) {
    std::array<float, 3> k;
    std::memcpy(k.data(), f.points.record(i), 12);
    by_xyz.emplace(k, i);
  }
  ASSERT_GT(out.size(), 0u);
  for (const char *name : {"intensity", "ring", "time"}) ASSERT_NE(out.layout().find(name), nullptr) << name;
  for (std::size_t s = 0; s < out.size(); ++s) {
    std::array<float, 3> k;
    for (int a = 0; a < 3; ++a) k[a] = static_cast<float>(readAsDouble(out.record(s), out.layout().fields[a]));
    const auto it = by_xyz.find(k);
    ASSERT_NE(it, by_xyz.end()) << "sample " << s << " is not an input point";
    for (const char *name : {"intensity", "ring", "time"}) {
      const PointField &fi = *in.find(name), &fo = *out.layout().find(name);
      ASSERT_EQ(fi.type, fo.type);
      ASSERT_EQ(std::memcmp(f.points.record(it->second) + fi.offset, out.record(s) + fo.offset, fi.byteSize()), 0)
          << name;
    }
  }
}

TEST(Pipeline, NanInfAndNoReturnPointsAreSkippedAndCounted) {
  std::vector<std::array<double, 3>> pts = {{1, 2, 3},          {NAN, 0, 0},          {0, INFINITY, 0},
                                            {0, 0, 0},          {0, 0, -INFINITY},    {5, 5, 5},
                                            {0, 0, 0},          {0.5, 0.5, NAN},      {100, 0, 0}};
  for (FieldType t : {FieldType::Float32, FieldType::Float64}) {
    HpdsConfig c;
    c.input.max_range = 50.0;
    Pipeline p(c);
    const FrameResult r = p.addFrame(makeFrame(pts, t));
    EXPECT_EQ(r.counters.input, 9u);
    EXPECT_EQ(r.counters.skipped_invalid, 4u);
    EXPECT_EQ(r.counters.skipped_zero, 2u);
    EXPECT_EQ(r.counters.skipped_range, 1u);
    EXPECT_EQ(r.counters.accepted, 2u);
    for (SampleId id : p.outputSamples()) EXPECT_TRUE(std::isfinite(p.hierarchy().position(id)[0]));
  }
  HpdsConfig keep;
  keep.input.skip_zero_points = false;
  Pipeline p(keep);
  EXPECT_EQ(p.addFrame(makeFrame({{0, 0, 0}, {0, 0, 0}})).counters.accepted, 1u);
}

TEST(Pipeline, EmptyAndAllInvalidFramesAreHarmless) {
  Pipeline p(HpdsConfig{});
  EXPECT_EQ(p.addFrame(makeFrame({})).counters.accepted, 0u);
  EXPECT_EQ(p.addFrame(makeFrame({{NAN, NAN, NAN}, {0, 0, 0}})).counters.accepted, 0u);
  EXPECT_EQ(p.makeCloud(p.outputSamples(), false).size(), 0u);
  HpdsConfig n;
  n.normals.enabled = true;
  Pipeline q(n);
  q.addFrame(makeFrame({}));
  EXPECT_EQ(q.makeCloud(q.outputSamples(), false).size(), 0u);
}

TEST(Pipeline, BadFramesThrowBeforeChangingTheMap) {
  HpdsConfig c;
  c.mode = Mode::Map;
  Pipeline p(c);
  PointLayout no_z;
  no_z.append("x", FieldType::Float32);
  no_z.append("y", FieldType::Float32);
  Frame bad;
  bad.points = PointBuffer(no_z, 3);
  EXPECT_THROW(p.addFrame(bad), std::invalid_argument);
  p.addFrame(makeFrame({{1, 1, 1}, {2, 2, 2}}));
  const std::size_t before = p.hierarchy().sampleCount();
  EXPECT_THROW(p.addFrame(makeFrame({{3, 3, 3}}, FieldType::Float64)), std::invalid_argument);  // other layout
  Frame nan_pose = makeFrame({{3, 3, 3}});
  nan_pose.sensor_to_fixed.translation().x() = NAN;
  EXPECT_THROW(p.addFrame(nan_pose), std::invalid_argument);
  EXPECT_EQ(p.hierarchy().sampleCount(), before);
}

TEST(Pipeline, LargeCoordinatesThroughThePoseAreExact) {
  HpdsConfig c;
  c.mode = Mode::Map;
  c.hierarchy.cell_size = 1.0;
  c.hierarchy.max_depth = 10;  // ~1 mm cells at 1e6 m
  Pipeline p(c);
  Frame f = makeFrame({{0.25, 0.5, 1.0}, {0.75, 0.5, 1.0}, {3.0, 1.0, 0.125}}, FieldType::Float64);
  f.sensor_to_fixed = Eigen::Translation3d(1e6, -1e6, 250.0) * Eigen::Isometry3d::Identity();
  const FrameResult r = p.addFrame(f);
  EXPECT_EQ(r.counters.out_of_range, 0u);
  ASSERT_EQ(r.counters.accepted, 3u);
  std::set<std::array<double, 3>> got;
  for (SampleId id : r.new_samples) {
    const double *q = p.hierarchy().position(id);
    got.insert({q[0], q[1], q[2]});
  }
  EXPECT_TRUE(got.count({1e6 + 0.25, -1e6 + 0.5, 251.0}));
  EXPECT_TRUE(got.count({1e6 + 3.0, -1e6 + 1.0, 250.125}));

  HpdsConfig fine = c;
  fine.hierarchy.max_depth = 21;
  Pipeline q(fine);
  EXPECT_EQ(q.addFrame(f).counters.out_of_range, 3u);  // 1e6 m at 2^-21 m cells: refused, counted
}

TEST(Pipeline, ScanModeBuildsOnlyTheLevelsItsOutputsReadAndTheyComeOutTheSame) {
  HpdsConfig c;
  c.hierarchy.cell_size = 4.0;
  c.hierarchy.max_depth = 8;
  c.output.level = 4;
  c.normals.enabled = false;
  EXPECT_EQ(Pipeline(c).buildDepth(), 4);
  c.normals.enabled = true;  // neighborhood_level_offset 2: averaged from the frame's points, no level deeper
  EXPECT_EQ(Pipeline(c).buildDepth(), 4);
  c.normals.neighborhood_level_offset = 7;
  EXPECT_EQ(Pipeline(c).buildDepth(), 4);
  c.normals.neighborhood_level_offset = 2;
  c.map.keep_depth = 8;
  EXPECT_EQ(Pipeline(c).buildDepth(), 4) << "scan mode keeps nothing: map.keep_depth does not apply";
  c.mode = Mode::Map;
  c.map.keep_depth = -1;
  EXPECT_EQ(Pipeline(c).buildDepth(), 6) << "map mode too builds only the levels its outputs read";
  c.map.keep_depth = 8;
  EXPECT_EQ(Pipeline(c).buildDepth(), 8) << "map.keep_depth keeps finer levels for later reads";
  c.map.keep_depth = 3;
  EXPECT_EQ(Pipeline(c).buildDepth(), 6) << "never shallower than what the outputs read";
  c.map.keep_depth = -1;
  c.mode = Mode::Scan;
  {
    Pipeline p(c);
    p.requireLevel(7);
    EXPECT_EQ(p.buildDepth(), 7);
    p.requireLevel(3);
    EXPECT_EQ(p.buildDepth(), 7) << "a level already built stays built";
    EXPECT_THROW(p.requireLevel(9), std::invalid_argument);
    EXPECT_THROW(p.requireLevel(-1), std::invalid_argument);
  }

  // The same frames through a pipeline built to the output level 4 and one built to max_depth: the same output
  // samples with the same ids, fields and normals (from the frame's points either way), byte for byte; the shallow
  // one stores nothing deeper and counts as dropped exactly the points the deep one took at deeper levels or dropped.
  const SyntheticLidar lidar(smallLidar(SceneKind::Urban, 2));
  Pipeline shallow(c), deep(c);
  deep.requireLevel(8);
  for (int i = 0; i < 2; ++i) {
    const Frame f = lidar.frame(i).frame;
    const FrameResult a = shallow.addFrame(f), b = deep.addFrame(f);
    for (int d = 0; d <= 4; ++d) EXPECT_EQ(a.counters.accepted_per_level[d], b.counters.accepted_per_level[d]) << d;
    std::uint64_t deeper = 0;
    for (int d = 5; d <= 8; ++d) {
      EXPECT_EQ(a.counters.accepted_per_level[d], 0u);
      deeper += b.counters.accepted_per_level[d];
    }
    EXPECT_GT(deeper, 0u) << "levels 5 to 8 must hold samples for this comparison to mean something";
    EXPECT_EQ(a.counters.dropped_depth, b.counters.dropped_depth + deeper);
    const std::vector<SampleId> ids = shallow.outputSamples();
    ASSERT_EQ(ids, deep.outputSamples());
    const PointBuffer out = shallow.makeCloud(ids, false);
    ASSERT_TRUE(out.layout().find("normal_x"));
    EXPECT_TRUE(out.bytes() == deep.makeCloud(ids, false).bytes()) << "frame " << i;
    EXPECT_LT(shallow.hierarchy().sampleCount(), deep.hierarchy().sampleCount());
  }
}

// ---------------------------------------------------------------- map mode

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
  // The shipped defaults in map mode: output level 5 (r = 0.1 m) and the normals' levels 6..7, nothing finer.
  EXPECT_EQ(Pipeline(c).buildDepth(), 7);
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
  for (int i = 0; i < 10; ++i) {
    const FrameResult r = q.addFrame(lidar.frame(i).frame);
    EXPECT_LE(q.hierarchy().sampleCount(), 5000u + r.counters.accepted);
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

// ---------------------------------------------------------------- normals

TEST(Normals, MatchBruteForcePcaAndAreOrientedTowardTheSensor) {
  const SyntheticLidar lidar(smallLidar());
  HpdsConfig c;
  c.normals.enabled = true;
  // The plain estimator (levels 0..L within the radius) is what this oracle computes; the refinements have their
  // own tests (test_refined_normals).
  c.normals.neighborhood_level_offset = 0;
  c.normals.max_growth = 1.0;
  c.output.level = 5;
  Pipeline p(c);
  p.addFrame(lidar.frame(0).frame);
  const Hierarchy &h = p.hierarchy();
  const std::vector<SampleId> ids = p.outputSamples();
  const NormalParams params = normalParamsFor(c, 5);
  const auto normals = estimateNormals(h, ids, params);
  std::size_t valid = 0;
  for (std::size_t i = 0; i < ids.size(); i += 7) {
    const double *q = h.position(ids[i]);
    std::vector<const double *> nb;
    for (SampleId o : ids) {
      const double *r = h.position(o);
      const double d2 = (r[0] - q[0]) * (r[0] - q[0]) + (r[1] - q[1]) * (r[1] - q[1]) + (r[2] - q[2]) * (r[2] - q[2]);
      if (d2 < params.radius * params.radius) nb.push_back(r);
    }
    if (static_cast<int>(nb.size()) < params.min_neighbors) {
      ASSERT_FALSE(normals[i].valid);
      ASSERT_TRUE(std::isnan(normals[i].normal[0]));
      continue;
    }
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (auto *r : nb) mean += Eigen::Vector3d(r[0], r[1], r[2]);
    mean /= static_cast<double>(nb.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (auto *r : nb) {
      const Eigen::Vector3d d = Eigen::Vector3d(r[0], r[1], r[2]) - mean;
      cov += d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov / static_cast<double>(nb.size()));
    if (es.eigenvalues()(1) < 1e-6 * es.eigenvalues().sum()) continue;  // degenerate: either answer is fine
    ASSERT_TRUE(normals[i].valid);
    ++valid;
    const Eigen::Vector3d n(normals[i].normal[0], normals[i].normal[1], normals[i].normal[2]);
    EXPECT_NEAR(n.norm(), 1.0, 1e-5);
    EXPECT_LT(angleDeg(n, es.eigenvectors().col(0)), 0.1);
    EXPECT_NEAR(normals[i].curvature, es.eigenvalues()(0) / es.eigenvalues().sum(), 1e-4);
    const std::array<float, 3> v = h.toViewpoint(ids[i]);
    EXPECT_GT(n.dot(Eigen::Vector3d(v[0], v[1], v[2])), 0.0) << "normal must face the sensor";
  }
  EXPECT_GT(valid, 50u);
}

TEST(Normals, AccurateOnPlanarSceneAgainstGroundTruth) {
  SyntheticLidarConfig lc = smallLidar(SceneKind::PlanarUrban, 1);
  lc.beams = 32;
  lc.azimuth_steps = 1800;
  const SyntheticLidar lidar(lc);
  const SyntheticFrame sf = lidar.frame(0);
  Frame f = sf.frame;
  f.sensor_to_fixed.setIdentity();
  HpdsConfig c;
  c.normals.enabled = true;
  c.output.level = 4;  // r = 0.22 m
  Pipeline p(c);
  p.addFrame(f);
  const std::vector<SampleId> ids = p.outputSamples();
  const auto normals = p.normals(ids);  // scan mode: from the frame's cell centroids
  std::map<std::array<float, 3>, std::size_t> by_xyz;
  for (std::size_t i = 0; i < f.points.size(); ++i) {
    std::array<float, 3> k;
    std::memcpy(k.data(), f.points.record(i), 12);
    by_xyz.emplace(k, i);
  }
  std::vector<double> errors;
  std::size_t wrong_side = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (!normals[i].valid) continue;
    const double *q = p.hierarchy().position(ids[i]);
    const std::size_t src = by_xyz.at({static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2])});
    const Eigen::Vector3d truth = sf.normals[src].cast<double>();
    const Eigen::Vector3d n(normals[i].normal[0], normals[i].normal[1], normals[i].normal[2]);
    errors.push_back(angleDeg(n, truth));
    // A flip is a right line with the wrong sign; large line errors (corners) are measured by `errors`.
    // At grazing incidence (the far ground) a few degrees of error cross the view plane; viewpoint orientation
    // cannot decide there, so flips are only counted where the sensor sees the surface at > 15 degrees.
    const Eigen::Vector3d to_sensor = -Eigen::Vector3d(q[0], q[1], q[2]).normalized();
    if (errors.back() < 30.0 && truth.dot(to_sensor) > std::sin(15.0 * M_PI / 180.0) && n.dot(truth) < 0) ++wrong_side;
  }
  ASSERT_GT(errors.size(), 500u);
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  EXPECT_LT(errors[errors.size() / 2], 5.0) << "median angular error in degrees";
  EXPECT_LT(static_cast<double>(wrong_side), 0.005 * errors.size()) << "normals must face the sensor";
}

// ---------------------------------------------------------------- insertion orders

// Every order of a small set must come out equally often (a biased index draw or an off-by-one in the swap loop
// shows up as a skewed count).
TEST(InsertionOrder, RandomOrdersAreUniform) {
  std::map<std::vector<std::uint32_t>, int> seen;
  const int trials = 60000;
  for (int t = 0; t < trials; ++t) {
    std::vector<std::uint32_t> v = {0, 1, 2, 3};
    seededShuffle(v, 1000003ull * static_cast<std::uint64_t>(t) + 17);
    ++seen[v];
  }
  ASSERT_EQ(seen.size(), 24u);
  for (const auto &kv : seen) EXPECT_NEAR(kv.second, trials / 24.0, 0.08 * trials / 24.0);
}

TEST(InsertionOrder, RandomIsAPermutationAndSeedDependent) {
  std::vector<std::uint32_t> a(1000);
  std::iota(a.begin(), a.end(), 0u);
  auto b = a, c = a;
  seededShuffle(b, 7);
  seededShuffle(c, 7);
  EXPECT_EQ(b, c);
  seededShuffle(c, 8);
  EXPECT_NE(b, c);
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
}

// A seed's order is part of the output users reproduce: it must stay the textbook shuffle of the contract, drawn
// with a plain 64-bit remainder, on both sides of the division-free remainder's 4096 threshold.
TEST(InsertionOrder, RandomIsTheContractsFisherYatesForEverySize) {
  const auto reference = [](std::vector<std::uint32_t> v, std::uint64_t state) {
    const auto next = [&state] {
      std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      return z ^ (z >> 31);
    };
    for (std::size_t i = v.size(); i > 1; --i) {
      const std::uint64_t bound = i, limit = ~std::uint64_t(0) - (~std::uint64_t(0) % bound);
      std::uint64_t draw = next();
      while (draw >= limit) draw = next();
      std::swap(v[i - 1], v[draw % bound]);
    }
    return v;
  };
  for (const std::size_t n : {0u, 1u, 2u, 3u, 4095u, 4096u, 4097u, 70001u})
    for (const std::uint64_t seed : {0ull, 1ull, 0x9E3779B97F4A7C15ull, ~0ull}) {
      std::vector<std::uint32_t> v(n);
      std::iota(v.begin(), v.end(), 0u);
      const std::vector<std::uint32_t> expected = reference(v, seed);
      seededShuffle(v, seed);
      ASSERT_EQ(v, expected) << "n = " << n << ", seed = " << seed;
    }
}

TEST(InsertionOrder, FeatureOrdersSortDescendingByBruteForceFeature) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> xyz;
  for (int i = 0; i < 1500; ++i) {  // a plane with a bump and a pole: flat, curved and line-like neighbourhoods
    const double x = u(rng), y = u(rng);
    xyz.insert(xyz.end(), {x, y, 0.3 * std::exp(-10 * (x * x + y * y))});
  }
  for (int i = 0; i < 200; ++i) xyz.insert(xyz.end(), {0.5 + 0.01 * u(rng), 0.5 + 0.01 * u(rng), 1 + u(rng)});
  std::vector<std::uint32_t> all(xyz.size() / 3);
  std::iota(all.begin(), all.end(), 0u);
  const double radius = 0.15;
  for (InsertionOrder kind : {InsertionOrder::Sphericity, InsertionOrder::SurfaceVariation}) {
    const auto order = insertionOrder(xyz.data(), all, kind, 0, radius, 2);
    ASSERT_EQ(order.size(), all.size());
    std::vector<double> feature(all.size());
    for (std::uint32_t i : all) {
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      std::vector<Eigen::Vector3d> nb;
      for (std::uint32_t j : all) {
        const Eigen::Vector3d d(xyz[3 * j] - xyz[3 * i], xyz[3 * j + 1] - xyz[3 * i + 1], xyz[3 * j + 2] - xyz[3 * i + 2]);
        if (d.squaredNorm() < radius * radius) nb.push_back(d);
      }
      for (auto &d : nb) mean += d;
      mean /= static_cast<double>(nb.size());
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (auto &d : nb) cov += (d - mean) * (d - mean).transpose();
      const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov / nb.size()).eigenvalues().cwiseMax(0.0);
      feature[i] = nb.size() < 3 ? 0.0 : (kind == InsertionOrder::Sphericity ? ev(0) / ev(2) : ev(0) / ev.sum());
    }
    for (std::size_t k = 1; k < order.size(); ++k)
      ASSERT_GE(feature[order[k - 1]] + 1e-4, feature[order[k]]) << toString(kind) << " not descending at " << k;
  }
}

// Degenerate input keeps the feature orders linear: 100 000 coincident points (59 s before the cap) and a dense
// cluster under a radius that covers it all read at most 27 * kFeatureCellCap points per PCA; a dense plane keeps its
// features (the representatives are a fair sample); a frame without an overfull cell is computed exactly.
TEST(InsertionOrder, FeatureWorkStaysLinearOnDegenerateInput) {
  const std::size_t n = 100000;
  std::vector<double> same(3 * n, 1.5);
  std::vector<std::uint32_t> all(n);
  std::iota(all.begin(), all.end(), 0u);
  std::uint64_t read = 0;
  std::vector<float> f = localFeature(same.data(), all, InsertionOrder::Sphericity, 0.1, 2, &read);
  EXPECT_LE(read, n * 27 * kFeatureCellCap);
  for (float v : f) ASSERT_EQ(v, 0.0f) << "coincident points have no shape";

  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> plane;
  for (std::size_t i = 0; i < n; ++i) plane.insert(plane.end(), {u(rng), u(rng), 0.001 * u(rng)});
  for (const double radius : {0.2, 1e6}) {  // about a thousand points per cell, and everything in one cell
    SCOPED_TRACE(radius);
    f = localFeature(plane.data(), all, InsertionOrder::SurfaceVariation, radius, 2, &read);
    EXPECT_LE(read, n * 27 * kFeatureCellCap);
    // The exact surface variation of a plane 2 mm thick over 2 m (radius 1e6) or 20 cm: tiny either way.
    for (std::size_t i = 0; i < n; i += 997) EXPECT_LT(f[i], 2e-3) << i;
  }

  // Below the cap: exactly the brute-force PCA of every neighbour within the radius.
  std::vector<double> sparse;
  for (int i = 0; i < 2000; ++i) sparse.insert(sparse.end(), {u(rng), u(rng), 0.2 * u(rng) * u(rng)});
  std::vector<std::uint32_t> few(2000);
  std::iota(few.begin(), few.end(), 0u);
  const double radius = 0.2;
  f = localFeature(sparse.data(), few, InsertionOrder::Sphericity, radius, 1, &read);
  std::uint64_t expected_read = 0;
  for (std::uint32_t i : few) {
    PcaAccumulator acc(&sparse[3 * i]);
    for (std::uint32_t j : few) {
      const double dx = sparse[3 * j] - sparse[3 * i], dy = sparse[3 * j + 1] - sparse[3 * i + 1],
                   dz = sparse[3 * j + 2] - sparse[3 * i + 2];
      if (dx * dx + dy * dy + dz * dz < radius * radius) acc.add(&sparse[3 * j]);
    }
    expected_read += acc.count();
    const float exact = acc.count() < 3 ? 0.0f : static_cast<float>(acc.solve(false).sphericity());
    ASSERT_NEAR(f[i], exact, 1e-5) << i;
  }
  EXPECT_EQ(read, expected_read);
}

TEST(InsertionOrder, SphericityPutsFeaturePointsIntoCoarseLevels) {
  const SyntheticLidar lidar(smallLidar(SceneKind::CurvedObjects, 1));
  const Frame f = lidar.frame(0).frame;
  auto coarseMeanSphericity = [&](InsertionOrder order) {
    HpdsConfig c;
    c.order.type = order;
    c.output.level = 4;
    Pipeline p(c);
    p.addFrame(f);
    // Mean sphericity (same radius as the pipeline's default) of the samples of levels 0..2.
    std::vector<double> xyz;
    std::vector<std::uint32_t> idx;
    const PointLayout &l = f.points.layout();
    for (std::size_t i = 0; i < f.points.size(); ++i) {
      const double v[3] = {readAsDouble(f.points.record(i), *l.find("x")), readAsDouble(f.points.record(i), *l.find("y")),
                           readAsDouble(f.points.record(i), *l.find("z"))};
      if (v[0] == 0 && v[1] == 0 && v[2] == 0) continue;
      const Eigen::Vector3d w = f.sensor_to_fixed.linear() * Eigen::Vector3d(v[0], v[1], v[2]) + f.sensor_to_fixed.translation();
      idx.push_back(static_cast<std::uint32_t>(xyz.size() / 3));
      xyz.insert(xyz.end(), {w.x(), w.y(), w.z()});
    }
    const auto feat = localFeature(xyz.data(), idx, InsertionOrder::Sphericity, 2.0 * p.hierarchy().radius(4), 1);
    std::map<std::array<double, 3>, float> feature_at;
    for (std::size_t i = 0; i < idx.size(); ++i) feature_at[{xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}] = feat[i];
    double sum = 0.0;
    std::size_t n = 0;
    for (SampleId id : p.hierarchy().samplesUpTo(2)) {
      const double *q = p.hierarchy().position(id);
      sum += feature_at.at({q[0], q[1], q[2]});
      ++n;
    }
    return sum / static_cast<double>(n);
  };
  const double random_share = coarseMeanSphericity(InsertionOrder::Random);
  const double feature_share = coarseMeanSphericity(InsertionOrder::Sphericity);
  EXPECT_GT(feature_share, 2.0 * random_share) << "random " << random_share << " sphericity " << feature_share;
}

// ---------------------------------------------------------------- real frames

TEST(RealFrames, Vlp16FieldsSurviveAndHdl32PairBuildsOneMap) {
  HPDS_REQUIRE_SHARED_DATA();
  const auto dir = test::sharedLidarDir();
  Frame vlp;
  vlp.points = readPointCloud((dir / "velodyne_vlp16.pcd").string());
  HpdsConfig c;
  c.output.level = 6;
  Pipeline p(c);
  p.addFrame(vlp);
  const PointBuffer out = p.makeCloud(p.outputSamples(), false);
  for (const char *name : {"intensity", "return_type", "channel", "azimuth", "elevation", "distance", "time_stamp"}) {
    const PointField *fi = vlp.points.layout().find(name), *fo = out.layout().find(name);
    ASSERT_TRUE(fi && fo) << name;
    EXPECT_EQ(fi->type, fo->type) << name;
  }
  // Dual-return sensors repeat xyz with other field values, so a sample must match one of the candidates fully.
  std::multimap<std::array<float, 3>, std::size_t> by_xyz;
  const PointLayout &il = vlp.points.layout();
  auto xyzOf = [](const PointBuffer &b, std::size_t i) {
    const PointLayout &l = b.layout();
    return std::array<float, 3>{static_cast<float>(readAsDouble(b.record(i), *l.find("x"))),
                                static_cast<float>(readAsDouble(b.record(i), *l.find("y"))),
                                static_cast<float>(readAsDouble(b.record(i), *l.find("z")))};
  };
  for (std::size_t i = 0; i < vlp.points.size(); ++i) by_xyz.emplace(xyzOf(vlp.points, i), i);
  const char *carried[] = {"intensity", "return_type", "channel", "azimuth", "elevation", "distance", "time_stamp"};
  for (std::size_t s = 0; s < out.size(); ++s) {
    const auto [lo, hi] = by_xyz.equal_range(xyzOf(out, s));
    bool matched = false;
    for (auto it = lo; it != hi && !matched; ++it) {
      matched = true;
      for (const char *name : carried) {
        const PointField &fi = *il.find(name), &fo = *out.layout().find(name);
        matched = matched && std::memcmp(vlp.points.record(it->second) + fi.offset, out.record(s) + fo.offset, fi.byteSize()) == 0;
      }
    }
    ASSERT_TRUE(matched) << "sample " << s << " matches no input record field for field";
  }

  // hdl32_b's pose in hdl32_a's frame (4x4 row-major) from the data set.
  std::ifstream rel(dir / "hdl32_relative.txt");
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int k = 0; k < 4; ++k) rel >> m(r, k);
  ASSERT_TRUE(rel);
  HpdsConfig mc;
  mc.mode = Mode::Map;
  Pipeline map(mc);
  Frame a, b;
  a.points = readPointCloud((dir / "hdl32_a.pcd").string());
  b.points = readPointCloud((dir / "hdl32_b.pcd").string());
  b.sensor_to_fixed.matrix() = m;
  const FrameResult ra = map.addFrame(a);
  EXPECT_EQ(ra.counters.skipped_zero, 5032u);
  const FrameResult rb = map.addFrame(b);
  // Two consecutive scans of one scene: at 0.2 m spacing (levels 0..4) most of b lands on what a covers.
  std::uint64_t coarse_a = 0, coarse_b = 0;
  for (int d = 0; d <= 4; ++d) coarse_a += ra.counters.accepted_per_level[d], coarse_b += rb.counters.accepted_per_level[d];
  EXPECT_LT(coarse_b, coarse_a / 2) << coarse_a << " then " << coarse_b;
  // The relative pose must register b onto a: without it b overlaps the map clearly less.
  Pipeline unregistered(mc);
  unregistered.addFrame(a);
  b.sensor_to_fixed.setIdentity();
  const FrameResult rb_id = unregistered.addFrame(b);
  std::uint64_t coarse_b_id = 0;
  for (int d = 0; d <= 4; ++d) coarse_b_id += rb_id.counters.accepted_per_level[d];
  EXPECT_LT(coarse_b * 4, coarse_b_id * 3) << "registered " << coarse_b << " vs unregistered " << coarse_b_id;
  // Spot-check the additive property across the two frames by brute force on a neighbourhood.
  const Hierarchy &h = map.hierarchy();
  std::vector<SampleId> ids = h.samplesUpTo(5);
  for (std::size_t i = 0; i < ids.size(); i += 17)
    for (std::size_t j = 0; j < ids.size(); ++j) {
      if (i == j) continue;
      const double *x = h.position(ids[i]), *y = h.position(ids[j]);
      const double d2 = (x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) + (x[2] - y[2]) * (x[2] - y[2]);
      const double r = h.radius(std::max(h.level(ids[i]), h.level(ids[j])));
      ASSERT_GE(d2, r * r);
    }
}

}  // namespace
}  // namespace hpds
