// Hostile input to the core Pipeline, row by row of docs/reliability.md: every numeric xyz type, broken layouts,
// NaN/Inf in every field and pose, degenerate and 1e7 m coordinates, a 10-million-point frame, stamps, invalid
// configs. Complements test_pipeline_frames (skip counters); the CLI's side is test_hostile_cli.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "HostileTestSupport.hpp"
#include "TiledRun.hpp"
#include "hpds/eval/SamplingVerifier.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {
namespace {

using test::frameOf;
using test::gridPoints;
using test::typedCloud;

/// `n` points on a floor at z = -1.5 and two walls (x = 6, y = 6), 10 m wide: surfaces every sample has a normal on.
std::vector<std::array<double, 3>> wallsAndFloor(int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-5.0, 5.0);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < n; ++i) {
    const double a = u(rng), b = u(rng);
    pts.push_back(i % 3 == 0 ? std::array<double, 3>{a, b, -1.5} : i % 3 == 1 ? std::array<double, 3>{6.0, a, b}
                                                                               : std::array<double, 3>{a, 6.0, b});
  }
  return pts;
}

TEST(HostilePipeline, EveryNumericXyzTypeIsReadByValue) {
  const auto pts = gridPoints(6, 1.0, 1.0);
  for (FieldType t : {FieldType::UInt8, FieldType::Int8, FieldType::UInt16, FieldType::Int16, FieldType::Int32,
                      FieldType::UInt32, FieldType::Float32, FieldType::Float64}) {
    SCOPED_TRACE(fieldTypeName(t));
    HpdsConfig c;
    c.hierarchy.cell_size = 1.0;
    c.hierarchy.max_depth = 2;
    c.output.level = 2;
    Pipeline p(c);
    const FrameResult r = p.addFrame(frameOf(typedCloud(t, pts)));
    EXPECT_EQ(r.counters.accepted, pts.size());  // unit grid at 1 m cells: every point its own level-0 sample
    std::set<std::array<double, 3>> got;
    for (SampleId id : r.new_samples) got.insert({p.hierarchy().position(id)[0], p.hierarchy().position(id)[1],
                                                  p.hierarchy().position(id)[2]});
    const std::set<std::array<double, 3>> expected(pts.begin(), pts.end());
    EXPECT_EQ(got, expected);
  }
}

TEST(HostilePipeline, BrokenLayoutsThrowBeforeAnythingChanges) {
  HpdsConfig c;
  c.mode = Mode::Map;
  Pipeline p(c);
  p.addFrame(frameOf(typedCloud(FieldType::Float32, gridPoints(4, 1.0))));
  const std::size_t before = p.hierarchy().sampleCount();
  const std::uint32_t frames = p.framesProcessed();
  PointLayout beyond;
  beyond.append("x", FieldType::Float32);
  beyond.append("y", FieldType::Float32);
  beyond.append("z", FieldType::Float32);
  beyond.fields[2].offset = 10;  // z reaches past point_step 12
  PointLayout dup = beyond;
  dup.fields[2].offset = 8;
  dup.fields[1].name = "x";
  PointLayout bad_type = dup;
  bad_type.fields[1].name = "y";
  bad_type.fields[1].type = static_cast<FieldType>(11);
  PointLayout vector_x;
  vector_x.append("x", FieldType::Float32, 2);
  vector_x.append("y", FieldType::Float32);
  vector_x.append("z", FieldType::Float32);
  PointLayout shared_xy = vector_x;  // x and y read from the same bytes: every point would lie on x = y
  shared_xy.fields[0].count = 1;
  shared_xy.fields[1].offset = 0;
  PointLayout z_in_y;  // z starting inside y
  for (const char *name : {"x", "y", "z"}) z_in_y.append(name, FieldType::Float32);
  z_in_y.fields[2].offset = 6;
  for (const PointLayout &l : {beyond, dup, bad_type, vector_x, shared_xy, z_in_y}) {
    Frame f;
    f.points = PointBuffer(l, 0);
    f.points.bytes().assign(3 * l.point_step, 0);
    EXPECT_THROW(p.addFrame(f), std::invalid_argument);
  }
  try {
    shared_xy.validate();
    ADD_FAILURE() << "x and y at one offset passed";
  } catch (const std::invalid_argument &e) {
    EXPECT_NE(std::string(e.what()).find("field 'x' (bytes 0..3) overlaps field 'y' (bytes 0..3)"), std::string::npos)
        << e.what();
  }
  PointLayout rgb_in_rgba;  // other overlaps are a cloud's own business: rgb inside rgba, a view of x's bits
  for (const char *name : {"x", "y", "z", "rgba"}) rgb_in_rgba.append(name, FieldType::UInt32);
  rgb_in_rgba.fields.push_back(PointField{"rgb", 12, FieldType::Float32, 1});
  rgb_in_rgba.fields.push_back(PointField{"x_bits", 0, FieldType::UInt32, 1});
  EXPECT_NO_THROW(rgb_in_rgba.validate());
  // An empty frame whose last field is 4 GB long: every size matches, but its count is no real field's, and the
  // output layout's 32-bit point_step would wrap around.
  PointLayout huge;
  for (const char *axis : {"x", "y", "z"}) huge.append(axis, FieldType::Float32);
  huge.fields.push_back(PointField{"blob", 12, FieldType::UInt8, 0xFFFFFFE4u});
  huge.point_step = 0xFFFFFFF0u;
  Frame empty;
  empty.points = PointBuffer(huge, 0);
  EXPECT_THROW(p.addFrame(empty), std::invalid_argument);
  EXPECT_EQ(p.hierarchy().sampleCount(), before);
  EXPECT_EQ(p.framesProcessed(), frames);
  // Nor can a layout be grown past those limits.
  PointLayout grow;
  grow.append("x", FieldType::Float32);
  EXPECT_THROW(grow.append("descriptor", FieldType::Float32, kMaxFieldCount + 1), std::invalid_argument);
  EXPECT_THROW(grow.append("none", FieldType::Float32, 0), std::invalid_argument);
  grow.point_step = 0xFFFFFFFCu;
  EXPECT_THROW(grow.append("y", FieldType::Float64), std::invalid_argument);
  EXPECT_EQ(grow.fields.size(), 1u);
  EXPECT_EQ(grow.point_step, 0xFFFFFFFCu);
  grow.point_step = 0xFFFFFFFBu;
  grow.append("y", FieldType::Float32);  // up to the last byte still fits
  EXPECT_EQ(grow.point_step, 0xFFFFFFFFu);
  // width * height = size() also for a layout without bytes and for a moved-from buffer (a PLY written from one had
  // obj_info 5 x 2 over 0 vertices, which no reader accepts).
  const PointBuffer no_bytes(PointLayout{}, 100);
  EXPECT_EQ(std::uint64_t(no_bytes.width()) * no_bytes.height(), no_bytes.size());
  PointBuffer organised(typedCloud(FieldType::Float32, gridPoints(4, 1.0)));
  organised.resize(10);
  organised.setOrganization(5, 2);
  PointBuffer taken(std::move(organised));
  EXPECT_EQ(taken.width(), 5u);
  EXPECT_EQ(std::uint64_t(organised.width()) * organised.height(), organised.size());  // NOLINT(bugprone-use-after-move)
  PointBuffer assigned;
  assigned = std::move(taken);
  EXPECT_EQ(assigned.size(), 10u);
  EXPECT_EQ(std::uint64_t(taken.width()) * taken.height(), taken.size());  // NOLINT(bugprone-use-after-move)
}

TEST(HostilePipeline, IdsThatAreNoLiveSampleAreRefusedNotRead) {
  // Found using the library: makeCloud of ids from an earlier scan-mode frame returned the records of dead samples
  // (read past the hierarchy's arrays), and an id never issued crashed the normals.
  HpdsConfig c;
  Pipeline p(c);
  EXPECT_THROW((void)p.makeCloud({0, 1, 2}, false), std::invalid_argument) << "no frame yet";
  EXPECT_THROW((void)p.normals({0}), std::invalid_argument);
  p.addFrame(frameOf(typedCloud(FieldType::Float32, gridPoints(40, 0.3))));
  const std::vector<SampleId> first = p.outputSamples();
  ASSERT_GT(first.size(), 100u);
  EXPECT_EQ(p.makeCloud(first, false).size(), first.size());
  p.addFrame(frameOf(typedCloud(FieldType::Float32, gridPoints(5, 0.3))));  // scan mode: a new, smaller hierarchy
  try {
    (void)p.makeCloud(first, false);
    ADD_FAILURE() << "ids of the previous frame accepted";
  } catch (const std::invalid_argument &e) {
    EXPECT_NE(std::string(e.what()).find("is no sample of the hierarchy"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)p.makeCloud({1000000u}, false), std::invalid_argument);
  EXPECT_EQ(p.makeCloud(p.outputSamples(), false).size(), p.outputSamples().size());
}

TEST(HostilePipeline, NanInfInEveryFieldAndPose) {
  PointBuffer b = typedCloud(FieldType::Float64, gridPoints(6, 1.0));
  for (std::size_t i = 0; i < b.size(); ++i)
    for (const auto &f : b.layout().fields)
      writeFromDouble(b.record(i), f, (i % 2) ? NAN : -INFINITY);
  HpdsConfig c;
  c.normals.enabled = true;
  c.order.type = InsertionOrder::Sphericity;  // the feature orders see no invalid point either
  Pipeline p(c);
  const FrameResult r = p.addFrame(frameOf(b));
  EXPECT_EQ(r.counters.skipped_invalid, b.size());
  EXPECT_EQ(p.makeCloud(p.outputSamples(), false).size(), 0u);
  // A finite rigid pose that sends finite points to infinity: skipped as invalid, not inserted at inf.
  Frame huge = frameOf(typedCloud(FieldType::Float64, {{1e308, 0, 0}, {1, 1, 1}}));
  huge.sensor_to_fixed.translation() = Eigen::Vector3d(1.5e308, 0.0, 0.0);
  HpdsConfig m;
  m.mode = Mode::Map;
  Pipeline pm(m);
  const FrameResult rh = pm.addFrame(huge);
  EXPECT_EQ(rh.counters.skipped_invalid, 1u);  // 2.5e308 overflows to inf
  EXPECT_EQ(rh.counters.out_of_range, 1u);     // 1.5e308 m is beyond the exact keys of 1.4 cm cells
  EXPECT_EQ(rh.counters.accepted, 0u);
  for (SampleId id : pm.outputSamples()) EXPECT_TRUE(std::isfinite(pm.hierarchy().position(id)[0]));
}

// A pose must be rigid: a scaled, sheared, mirrored or projective matrix would put the points somewhere no sensor
// saw them (a scale of 0 collapsed a frame into one sample without a word).
TEST(HostilePipeline, PosesThatAreNotRigidAreRefused) {
  const PointBuffer cloud = typedCloud(FieldType::Float32, gridPoints(5, 0.5));
  for (const Mode mode : {Mode::Scan, Mode::Map}) {
    HpdsConfig c;
    c.mode = mode;
    Pipeline p(c);
    std::vector<std::pair<const char *, Eigen::Isometry3d>> bad;
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() *= 0.0;
    bad.emplace_back("scale 0", t);
    t = Eigen::Isometry3d::Identity();
    t.linear() *= 2.0;
    bad.emplace_back("scale 2", t);
    t = Eigen::Isometry3d::Identity();
    t.linear()(0, 0) = -1.0;
    bad.emplace_back("mirror", t);
    t = Eigen::Isometry3d::Identity();
    t.linear()(0, 1) = 0.01;
    bad.emplace_back("shear", t);
    t = Eigen::Isometry3d::Identity();
    t.matrix()(3, 0) = 0.5;
    bad.emplace_back("bottom row", t);
    t = Eigen::Isometry3d::Identity();
    t.matrix()(1, 3) = NAN;
    bad.emplace_back("NaN", t);
    for (const auto &[what, pose] : bad) {
      SCOPED_TRACE(what);
      Frame f = frameOf(cloud);
      f.sensor_to_fixed = pose;
      try {
        (void)p.addFrame(f);
        ADD_FAILURE() << "accepted";
      } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("sensor_to_fixed"), std::string::npos) << e.what();
      }
      EXPECT_EQ(p.framesProcessed(), 0u);
    }
    // A rotation as a tf or a pose file gives it (within 1e-3 of orthonormal) is accepted.
    Frame f = frameOf(cloud);
    f.sensor_to_fixed.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    f.sensor_to_fixed.linear()(0, 0) += 1e-6;
    f.sensor_to_fixed.translation() = Eigen::Vector3d(100.0, -20.0, 3.0);
    EXPECT_GT(p.addFrame(f).counters.accepted, 0u);
  }
}

// Map mode's layout is that of the first frame that gives a sample: an empty or NaN-only first frame (a driver's
// cloud before its first scan) leaves it to the next, whose fields then hold while the map keeps samples.
TEST(HostilePipeline, AFirstMapFrameWithoutSamplesLeavesTheLayoutToTheNext) {
  HpdsConfig c;
  c.mode = Mode::Map;
  for (const bool nan_only : {false, true}) {
    SCOPED_TRACE(nan_only ? "NaN-only first frame" : "empty first frame");
    Pipeline p(c);
    PointBuffer first = typedCloud(FieldType::Float32, nan_only ? std::vector<std::array<double, 3>>{{NAN, 0, 0}}
                                                               : std::vector<std::array<double, 3>>{});
    EXPECT_EQ(p.addFrame(frameOf(first)).counters.accepted, 0u);
    const PointBuffer other = typedCloud(FieldType::Float64, gridPoints(4, 1.0));
    ASSERT_NE(other.layout(), first.layout());
    EXPECT_GT(p.addFrame(frameOf(other)).counters.accepted, 0u);
    EXPECT_TRUE(p.hierarchy().recordLayout() == other.layout());
    // Now the map holds float64 records: float32 ones have no place in them.
    EXPECT_THROW((void)p.addFrame(frameOf(typedCloud(FieldType::Float32, gridPoints(4, 2.0)))), std::invalid_argument);
  }
}

// samplesHitByLastFrame against brute force over the last frame's points, at radii from far below the spacing
// (where its grid cannot key the whole frame) to infinity.
TEST(HostilePipeline, SamplesHitByLastFrameAtEveryRadius) {
  SyntheticLidarConfig lc;
  lc.beams = 16;
  lc.azimuth_steps = 600;
  lc.frames = 2;
  const SyntheticLidar lidar(lc);
  HpdsConfig c;
  c.mode = Mode::Map;
  c.normals.enabled = false;
  Pipeline p(c);
  for (int i = 0; i < 2; ++i) (void)p.addFrame(lidar.frame(i).frame);
  const std::vector<std::array<double, 3>> last = test::insertedPoints(c, {lidar.frame(1).frame});
  const int deepest = p.buildDepth();
  for (const double radius : {1e-6, 1e-5, 1e-3, 0.1, 1.0, double(INFINITY)}) {
    SCOPED_TRACE(radius);
    const std::vector<SampleId> got = p.samplesHitByLastFrame(0, deepest, radius);
    std::vector<SampleId> want;
    for (SampleId id = 0; id < p.hierarchy().idBound(); ++id) {
      if (!p.hierarchy().isLive(id)) continue;
      const double *s = p.hierarchy().position(id);
      for (const auto &q : last) {
        const double dx = s[0] - q[0], dy = s[1] - q[1], dz = s[2] - q[2];
        if (dx * dx + dy * dy + dz * dz < radius * radius) {
          want.push_back(id);
          break;
        }
      }
    }
    ASSERT_FALSE(want.empty());
    EXPECT_EQ(got, want);
  }
}

TEST(HostilePipeline, PointBufferSizesThatWrapAreRefused) {
  PointLayout l;
  l.append("x", FieldType::Float32);
  l.append("y", FieldType::Float32);
  l.append("z", FieldType::Float32);
  PointBuffer b(l, 3);
  EXPECT_THROW(b.resize(std::size_t(0x1555555555555556ull)), std::length_error);  // 12 * n wraps to 8
  EXPECT_THROW(b.resize(std::size_t(1) << 32), std::length_error);                // beyond a 32-bit width
  EXPECT_THROW(b.reserve(std::size_t(0x1555555555555556ull)), std::length_error);
  EXPECT_EQ(b.size(), 3u);  // unchanged
  EXPECT_EQ(std::size_t(b.width()) * b.height(), b.size());
  EXPECT_THROW(PointBuffer(l, std::size_t(0x1555555555555556ull)), std::length_error);
}

TEST(HostilePipeline, AllPointsAtOneSpotAndAtTheOrigin) {
  for (bool skip_zero : {true, false}) {
    HpdsConfig c;
    c.input.skip_zero_points = skip_zero;
    c.normals.enabled = true;
    c.order.type = InsertionOrder::SurfaceVariation;
    Pipeline p(c);
    const FrameResult r = p.addFrame(frameOf(typedCloud(FieldType::Float32, std::vector<std::array<double, 3>>(5000, {0, 0, 0}))));
    EXPECT_EQ(r.counters.accepted, skip_zero ? 0u : 1u);
    EXPECT_EQ(r.counters.skipped_zero, skip_zero ? 5000u : 0u);
    EXPECT_EQ(r.counters.dropped_depth, skip_zero ? 0u : 4999u);
    // Normals of a degenerate neighbourhood are invalid (NaN), not garbage.
    const PointBuffer out = p.makeCloud(p.outputSamples(), false);
    for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(std::isnan(readAsDouble(out.record(i), *out.layout().find("normal_x"))));
  }
  // Points exactly on one line: every neighbourhood is that line, which pins no normal (found: 702 of 861 samples got
  // an arbitrary one, with curvature 0).
  {
    HpdsConfig c;
    c.normals.enabled = true;
    Pipeline line(c);
    std::vector<std::array<double, 3>> pts;
    for (int i = 0; i < 2000; ++i) pts.push_back({0.01 * i, 2.0, 0.5});
    line.addFrame(frameOf(typedCloud(FieldType::Float64, pts)));
    const PointBuffer out = line.makeCloud(line.outputSamples(), false);
    ASSERT_GT(out.size(), 100u);
    for (std::size_t i = 0; i < out.size(); ++i)
      ASSERT_TRUE(std::isnan(readAsDouble(out.record(i), *out.layout().find("normal_x")))) << "sample " << i;
  }
  Pipeline p(HpdsConfig{});
  const FrameResult r = p.addFrame(frameOf(typedCloud(FieldType::Float32, std::vector<std::array<double, 3>>(5000, {3, -2, 1}))));
  EXPECT_EQ(r.counters.accepted, 1u);
  EXPECT_EQ(r.counters.dropped_depth, 4999u);
}

TEST(HostilePipeline, CoordinatesAt1e7MetresAreExactOrCounted) {
  // 4 m cells, every level down to 8 built: 1e7 m is well inside the exact key range; with 2^-21 m cells it is not.
  const std::vector<std::array<double, 3>> far = {{1e7, 0, 0}, {-1e7, 1e7, 5}, {1e7 + 2.0, 0, 0}, {0, 0, -1e7}};
  HpdsConfig depth8;
  depth8.hierarchy.cell_size = 4.0;
  depth8.hierarchy.max_depth = 8;
  depth8.output.level = 8;
  depth8.output.float64_xyz = true;  // float32 output would round 1e7 m by 0.6 m: verify could not check level 8
  for (FieldType t : {FieldType::Float32, FieldType::Float64}) {
    Pipeline p(depth8);
    const FrameResult r = p.addFrame(frameOf(typedCloud(t, far)));
    EXPECT_EQ(r.counters.accepted, 4u) << fieldTypeName(t);
    EXPECT_EQ(r.counters.out_of_range, 0u);
    const PointBuffer out = p.makeCloud(p.outputSamples(), false);
    EXPECT_EQ(verifySampling(out, 4.0, nullptr).total_violations(), 0u);
  }
  HpdsConfig fine;
  fine.hierarchy.cell_size = 1.0;
  fine.hierarchy.max_depth = 21;
  fine.output.level = 21;
  Pipeline p(fine);
  const FrameResult r = p.addFrame(frameOf(typedCloud(FieldType::Float64, far)));
  EXPECT_EQ(r.counters.out_of_range, 4u);
  EXPECT_EQ(r.counters.accepted, 0u);
  // Beyond any hierarchy: 1e30 m is counted as out of range even at the coarsest settings.
  HpdsConfig coarse;
  coarse.hierarchy.cell_size = 1e6;
  coarse.hierarchy.max_depth = 0;
  coarse.output.level = 0;
  Pipeline pc(coarse);
  EXPECT_EQ(pc.addFrame(frameOf(typedCloud(FieldType::Float64, {{1e30, 0, 0}}))).counters.out_of_range, 1u);
}

TEST(HostilePipeline, AFarOutlierReturnLeavesTheFramesNormalsAndMapOutput) {
  // A frame of two walls and a floor plus one glitched return 2 000 km away, below it on x: the normals' and the
  // map output's neighbour searches address 2^21 cells per axis, and counted from the outlier they held nothing
  // else (every normal invalid). Every sample but the outlier keeps a valid normal, in scan mode on 1 and 2 threads,
  // and in map mode the samples the frame hit are still found.
  std::vector<std::array<double, 3>> pts = wallsAndFloor(6000, 4);
  pts.push_back({-2e6, 1.0, 0.0});
  for (int threads : {1, 2}) {
    HpdsConfig c;
    c.threads = threads;
    Pipeline p(c);
    p.addFrame(frameOf(typedCloud(FieldType::Float32, pts)));
    const std::vector<SampleId> ids = p.outputSamples();
    const std::vector<SampleNormal> normals = p.normals(ids);
    std::size_t valid = 0;
    for (const SampleNormal &n : normals) valid += n.valid ? 1 : 0;
    EXPECT_GE(valid + 1, ids.size()) << threads << " threads: " << valid << " valid of " << ids.size();
    EXPECT_GT(ids.size(), 1000u);
  }
  HpdsConfig m;
  m.mode = Mode::Map;
  m.map.evict_distance = 0.0;
  Pipeline map(m);
  map.addFrame(frameOf(typedCloud(FieldType::Float32, pts)));
  // Every output sample was hit, the outlier too (it is its own candidate): the frame spans 2e6 m, more than the
  // frame grid can key at this radius, and the search goes through the hierarchy instead.
  const std::vector<SampleId> hit = map.samplesHitByLastFrame(0, map.outputLevel(), map.hierarchy().radius(map.outputLevel()));
  EXPECT_EQ(hit, map.outputSamples());
}

TEST(HostilePipeline, AReturnBeyondTheKeyRangeChangesNothingButItsCount) {
  // A glitched return at -1e30 (a no-return with a flipped byte) has no cell key: it is counted as out of range. As
  // the corner of the scan-mode centroid grids it put every real point beyond their reach, and no sample of the frame
  // got a normal. The frame with it must give what the frame without it gives, sample for sample, in both modes and
  // on 1 and 2 threads, wherever in the frame it stands and on whichever axis, whatever its sign.
  const std::vector<std::array<double, 3>> clean = wallsAndFloor(3000, 5);
  const auto run = [](const HpdsConfig &c, const std::vector<std::array<double, 3>> &pts, std::uint64_t &out_of_range) {
    Pipeline p(c);
    out_of_range = p.addFrame(frameOf(typedCloud(FieldType::Float32, pts))).counters.out_of_range;
    std::vector<std::array<float, 7>> got;  // position, normal, valid
    const std::vector<SampleId> ids = p.outputSamples();
    const std::vector<SampleNormal> normals = p.normals(ids);
    for (std::size_t k = 0; k < ids.size(); ++k) {
      const double *q = p.hierarchy().position(ids[k]);
      const SampleNormal &n = normals[k];
      got.push_back({float(q[0]), float(q[1]), float(q[2]), n.valid ? n.normal[0] : 0.0f, n.valid ? n.normal[1] : 0.0f,
                     n.valid ? n.normal[2] : 0.0f, n.valid ? 1.0f : 0.0f});
    }
    return got;
  };
  for (const Mode mode : {Mode::Scan, Mode::Map})
    for (int threads : {1, 2}) {
      HpdsConfig c;
      c.mode = mode;
      c.threads = threads;
      c.map.evict_distance = 0.0;
      std::uint64_t none = 0;
      const auto expected = run(c, clean, none);
      ASSERT_EQ(none, 0u);
      std::size_t valid = 0;
      for (const auto &e : expected) valid += e[6] > 0.0f ? 1 : 0;
      ASSERT_GT(valid, expected.size() * 9 / 10) << "the clean frame's normals";
      for (const std::size_t at : {std::size_t(0), std::size_t(1234), clean.size()})
        for (int axis = 0; axis < 3; ++axis)
          for (const double value : {-1e30, 1e30, -1.7e38f + 0.0}) {
            SCOPED_TRACE(testing::Message() << (mode == Mode::Scan ? "scan" : "map") << ", " << threads
                                            << " threads, outlier " << value << " on axis " << axis << " at " << at);
            std::vector<std::array<double, 3>> pts = clean;
            std::array<double, 3> bad{0.0, 0.0, 0.0};
            bad[std::size_t(axis)] = value;
            pts.insert(pts.begin() + std::ptrdiff_t(at), bad);
            std::uint64_t out_of_range = 0;
            EXPECT_EQ(run(c, pts, out_of_range), expected);
            EXPECT_EQ(out_of_range, 1u);
          }
    }
}

TEST(HostilePipeline, TenMillionPointFrameInBoundedTimeAndMemory) {
  // 10 M records of 16 bytes (160 MB) plus the pipeline's per-point scratch; max_depth 2 keeps the hierarchy tiny.
  constexpr std::size_t kPoints = 10'000'000;
  PointLayout l;
  for (const char *a : {"x", "y", "z", "intensity"}) l.append(a, FieldType::Float32);
  Frame f;
  f.points = PointBuffer(l, kPoints);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-50.0f, 50.0f);
  for (std::size_t i = 0; i < kPoints; ++i) {
    float rec[4] = {u(rng), u(rng), u(rng) * 0.1f, float(i % 100)};
    std::memcpy(f.points.record(i), rec, 16);
  }
  HpdsConfig c;
  c.hierarchy.cell_size = 4.0;
  c.hierarchy.max_depth = 2;
  c.output.level = 2;
  c.normals.enabled = false;
  const auto t0 = std::chrono::steady_clock::now();
  Pipeline p(c);
  const FrameResult r = p.addFrame(f);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.counters.input, kPoints);
  EXPECT_EQ(r.counters.accepted + r.counters.dropped_depth, kPoints);
  // 100 x 100 x 10 m at 1 m finest cells: about 10^5 cells, far fewer samples than points.
  EXPECT_LT(r.counters.accepted, 150000u);
  EXPECT_EQ(p.hierarchy().sampleCount(), r.counters.accepted);
  EXPECT_LT(seconds, 240.0);
  const PointBuffer out = p.makeCloud(p.outputSamples(), false);
  EXPECT_EQ(verifySampling(out, c.hierarchy.cell_size, nullptr).total_violations(), 0u);
}

TEST(HostilePipeline, StampsAreCarriedNotInterpreted) {
  const SyntheticLidar lidar([] {
    SyntheticLidarConfig c;
    c.beams = 8;
    c.azimuth_steps = 300;
    c.frames = 3;
    return c;
  }());
  const std::vector<std::vector<double>> stamp_sets = {
      {0.0, 0.1, 0.2}, {5.0, 5.0, 5.0}, {3.0, -1.0, 2.0}, {NAN, INFINITY, -0.0}, {1e300, 0.0, 1e300}};
  std::vector<std::uint8_t> reference;
  for (const auto &stamps : stamp_sets) {
    HpdsConfig c;
    c.mode = Mode::Map;
    c.order.seed = 9;
    Pipeline p(c);
    for (int i = 0; i < 3; ++i) {
      Frame f = lidar.frame(i).frame;
      f.stamp = stamps[i];
      p.addFrame(f);
    }
    const std::vector<std::uint8_t> bytes = p.makeCloud(p.outputSamples(), false).bytes();
    if (reference.empty()) reference = bytes;
    EXPECT_EQ(bytes, reference);
  }
}

TEST(HostilePipeline, InvalidConfigsAreRefusedByTheConstructor) {
  auto refused = [](auto &&edit, const std::string &key) {
    HpdsConfig c;
    edit(c);
    try {
      Pipeline p(c);
      ADD_FAILURE() << key << " accepted";
    } catch (const std::invalid_argument &e) {
      EXPECT_EQ(std::string(e.what()).rfind(key, 0), 0u) << e.what();
    }
  };
  // Enumerations out of range, only reachable by a cast: they ran as scan mode / input order.
  refused([](HpdsConfig &c) { c.mode = static_cast<Mode>(5); }, "mode");
  refused([](HpdsConfig &c) { c.order.type = static_cast<InsertionOrder>(7); }, "order.type");
  refused([](HpdsConfig &c) { c.hierarchy.cell_size = NAN; }, "hierarchy.cell_size");
  refused([](HpdsConfig &c) { c.hierarchy.cell_size = -INFINITY; }, "hierarchy.cell_size");
  refused([](HpdsConfig &c) { c.hierarchy.max_depth = 99; }, "hierarchy.max_depth");
  refused([](HpdsConfig &c) { c.output.spacing = NAN; }, "output.spacing");
  refused([](HpdsConfig &c) { c.order.feature_radius = INFINITY; }, "order.feature_radius");
  refused([](HpdsConfig &c) { c.normals.radius = -1.0; }, "normals.radius");
  refused([](HpdsConfig &c) { c.map.evict_distance = NAN; }, "map.evict_distance");
  refused([](HpdsConfig &c) { c.input.min_range = INFINITY; }, "input.min_range");
  refused([](HpdsConfig &c) { c.threads = 100000; }, "threads");
}

}  // namespace
}  // namespace hpds
