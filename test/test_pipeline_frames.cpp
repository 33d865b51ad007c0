// The per-frame pipeline on synthetic frames: determinism (seed, thread count), input points carried with every
// field, NaN/Inf/no-return/out-of-range points skipped and counted, bad frames refused before any change, exact
// large coordinates, and the levels each mode builds.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include "PipelineTestSupport.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pipeline/FramePoints.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/sampling/InsertionOrderer.hpp"

namespace hpds {
namespace {

using test::makeFrame;
using test::smallLidar;

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

TEST(Pipeline, NormalsEstimatedBesideTheInsertionAreTheSameBits) {
  // With a second thread, scan mode estimates the neighbourhoods of the samples accepted so far while the frame is
  // still being inserted; how many are ready when the insertion ends depends on timing, the output must not. Dense
  // frames (a long insertion) so that the second thread gets to some; every frame is compared with one thread.
  SyntheticLidarConfig lc = smallLidar(SceneKind::Urban, 6);
  lc.beams = 64;
  lc.azimuth_steps = 2048;
  const SyntheticLidar lidar(lc);
  HpdsConfig c;
  c.normals.enabled = true;
  c.normals.covariances = true;
  c.output.spacing = 0.05;
  Pipeline one(c);
  c.threads = 2;
  Pipeline two(c);
  std::size_t most_ahead = 0;
  for (int i = 0; i < 6; ++i) {
    const Frame f = lidar.frame(i).frame;
    one.addFrame(f);
    const FrameResult r = two.addFrame(f);
    EXPECT_EQ(one.makeCloud(one.outputSamples(), false).bytes(), two.makeCloud(two.outputSamples(), false).bytes())
        << "frame " << i << ", " << r.normals_ahead << " neighbourhoods estimated beside the insertion";
    // A second estimate, without the early neighbourhoods, gives the same again.
    EXPECT_EQ(one.makeCloud(one.outputSamples(), false).bytes(), two.makeCloud(two.outputSamples(), false).bytes());
    most_ahead = std::max(most_ahead, r.normals_ahead);
  }
  EXPECT_GT(most_ahead, 0u) << "the second thread never estimated a neighbourhood during an insertion";
}

// Frame k of a run is ordered by the shuffle of seed + k: node workers (setNextFrameIndex) and a continued map (its
// saved frame counter) reproduce a run by numbering the frames, which only works if the number reaches the seed. A
// frame of the same points numbered 0, 1 and 5 against a hierarchy fed that shuffle directly.
TEST(Pipeline, FrameIndexOffsetsTheRandomOrderSeed) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(1.0f, 4.0f);
  std::vector<std::array<double, 3>> pts(2000);
  for (auto &p : pts) p = {u(rng), u(rng), u(rng)};  // floats, so the frame's float32 x y z hold them exactly
  const Frame f = makeFrame(pts);
  std::vector<double> xyz;
  for (const auto &p : pts) xyz.insert(xyz.end(), p.begin(), p.end());
  HpdsConfig c;
  c.order.type = InsertionOrder::Random;
  c.order.seed = 40;
  for (std::uint32_t k : {0u, 1u, 5u}) {
    Pipeline p(c);
    p.setNextFrameIndex(k);
    p.addFrame(f);
    std::vector<std::uint32_t> order(pts.size());
    std::iota(order.begin(), order.end(), 0u);
    seededShuffle(order, c.order.seed + k);
    Hierarchy want(p.hierarchy().cellSize(), p.hierarchy().maxDepth());
    InsertBatch b;
    b.xyz = xyz.data();
    b.size = pts.size();
    b.order = order.data();
    b.order_size = order.size();
    b.max_level = p.buildDepth();
    (void)want.insert(b);
    const auto samples = [](const Hierarchy &h) {
      std::set<std::tuple<double, double, double, int>> s;
      for (SampleId id : h.samplesUpTo(h.maxDepth()))
        s.emplace(h.position(id)[0], h.position(id)[1], h.position(id)[2], h.level(id));
      return s;
    };
    ASSERT_GT(want.sampleCount(), 100u);
    EXPECT_EQ(samples(p.hierarchy()), samples(want)) << "frame index " << k;
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

// poseFramePoints' identity pose (scan mode in the sensor's frame) skips the product: the same kept points, skip
// counts and position bits as the contract's formula R p + t, -0.0 and range limits included, against an oracle
// that computes that formula; and a pose that is not the identity still goes through it.
TEST(Pipeline, IdentityPosePositionsAreTheFormulasBits) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-60.0, 60.0);
  std::uniform_int_distribution<int> kind(0, 9);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < 3000; ++i) {
    std::array<double, 3> p = {u(rng), u(rng), u(rng) / 10.0};
    const int k = kind(rng);
    if (k == 0) p[i % 3] = NAN;
    if (k == 1) p = {0.0, 0.0, 0.0};
    if (k == 2) p[i % 3] = -0.0;
    if (k == 3) p[(i + 1) % 3] = -INFINITY;
    pts.push_back(p);
  }
  InputConfig in;
  in.min_range = 2.0;
  in.max_range = 50.0;
  Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
  turn.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  turn.translation() = Eigen::Vector3d(-0.0, 4.0, 1.0);
  for (const Eigen::Isometry3d &pose : {Eigen::Isometry3d(Eigen::Isometry3d::Identity()), turn}) {
    Frame f = makeFrame(pts, FieldType::Float32);
    f.sensor_to_fixed = pose;
    std::vector<double> xyz;
    std::vector<std::uint32_t> kept;
    SkippedPoints skipped;
    poseFramePoints(f, in, xyz, kept, skipped);
    std::vector<std::uint32_t> want;
    SkippedPoints want_skipped;
    const Eigen::Matrix3d R = pose.linear();
    const Eigen::Vector3d t = pose.translation();
    for (std::uint32_t i = 0; i < pts.size(); ++i) {
      const double x = static_cast<float>(pts[i][0]), y = static_cast<float>(pts[i][1]), z = static_cast<float>(pts[i][2]);
      if (!(std::isfinite(x) && std::isfinite(y) && std::isfinite(z))) {
        ++want_skipped.invalid;
        continue;
      }
      if (x == 0.0 && y == 0.0 && z == 0.0) {
        ++want_skipped.zero;
        continue;
      }
      const double r2 = x * x + y * y + z * z;
      if (r2 < in.min_range * in.min_range || r2 > in.max_range * in.max_range) {
        ++want_skipped.range;
        continue;
      }
      want.push_back(i);
      const double w[3] = {R(0, 0) * x + R(0, 1) * y + R(0, 2) * z + t.x(), R(1, 0) * x + R(1, 1) * y + R(1, 2) * z + t.y(),
                           R(2, 0) * x + R(2, 1) * y + R(2, 2) * z + t.z()};
      ASSERT_EQ(std::memcmp(w, &xyz[3 * std::size_t(i)], sizeof w), 0) << "point " << i;
    }
    EXPECT_EQ(kept, want);
    EXPECT_EQ(skipped.invalid, want_skipped.invalid);
    EXPECT_EQ(skipped.zero, want_skipped.zero);
    EXPECT_EQ(skipped.range, want_skipped.range);
    EXPECT_GT(want.size(), 1000u);
    EXPECT_GT(want_skipped.range, 100u);
  }
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
  EXPECT_EQ(Pipeline(c).buildDepth(), 4) << "map mode too builds only the levels its outputs read";
  c.map.keep_depth = 8;
  EXPECT_EQ(Pipeline(c).buildDepth(), 8) << "map.keep_depth keeps finer levels for later reads";
  c.map.keep_depth = 3;
  EXPECT_EQ(Pipeline(c).buildDepth(), 4) << "never shallower than what the outputs read";
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

}  // namespace
}  // namespace hpds
