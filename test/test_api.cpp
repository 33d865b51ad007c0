// The one-call API (hpds/hpds.hpp): the streaming pipeline's samples, Poisson-disk and covering by brute force,
// skipped points, normals, determinism, config errors. Core only: runs in a build without PCL.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <stdexcept>
#include <thread>

#include "TestData.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/hpds.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {
namespace {

SyntheticFrame syntheticFrame() {
  SyntheticLidarConfig c;
  c.beams = 16;
  c.azimuth_steps = 720;
  c.frames = 1;
  return SyntheticLidar(c).frame(0);
}

std::vector<Eigen::Vector3f> xyzOf(const PointBuffer &cloud) {
  const PointLayout &l = cloud.layout();
  std::vector<Eigen::Vector3f> out(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i)
    for (int a = 0; a < 3; ++a)
      out[i][a] = static_cast<float>(readAsDouble(cloud.record(i), *l.find(a == 0 ? "x" : a == 1 ? "y" : "z")));
  return out;
}

HpdsConfig withNormals() {
  HpdsConfig c;
  c.output.level = -1;
  c.output.spacing = 0.15;
  c.normals.enabled = true;
  return c;
}

TEST(Downsample, GivesThePipelinesSamplesInItsOrderWithItsNormals) {
  const SyntheticFrame f = syntheticFrame();
  const std::vector<Eigen::Vector3f> points = xyzOf(f.frame.points);
  const HpdsConfig config = withNormals();

  Pipeline pipeline(config);
  Frame frame = f.frame;
  frame.sensor_to_fixed = Eigen::Isometry3d::Identity();
  pipeline.addFrame(frame);
  const std::vector<SampleId> ids = pipeline.outputSamples();
  const PointBuffer cloud = pipeline.makeCloud(ids, false);
  const PointLayout &l = cloud.layout();

  const Samples s = downsample(points, config);
  ASSERT_EQ(s.size(), ids.size());
  ASSERT_GT(s.size(), 100u);
  ASSERT_EQ(s.level.size(), s.size());
  ASSERT_EQ(s.normal.size(), s.size());
  ASSERT_EQ(s.curvature.size(), s.size());
  for (std::size_t i = 0; i < s.size(); ++i) {
    ASSERT_LT(s.index[i], points.size());
    const double *p = pipeline.hierarchy().position(ids[i]);
    for (int a = 0; a < 3; ++a) ASSERT_EQ(static_cast<double>(points[s.index[i]][a]), p[a]) << i;
    ASSERT_EQ(s.level[i], pipeline.hierarchy().level(ids[i]));
    const char *nf[3] = {"normal_x", "normal_y", "normal_z"};
    for (int a = 0; a < 3; ++a) {
      const double expected = readAsDouble(cloud.record(i), *l.find(nf[a]));
      if (std::isnan(expected)) {
        EXPECT_TRUE(std::isnan(s.normal[i][a]));
      } else {
        EXPECT_EQ(s.normal[i][a], static_cast<float>(expected));
      }
    }
  }
}

TEST(Downsample, CovariancesAreThePipelinesCovFields) {
  const SyntheticFrame f = syntheticFrame();
  const std::vector<Eigen::Vector3f> points = xyzOf(f.frame.points);
  HpdsConfig config = withNormals();
  config.normals.covariances = true;
  Pipeline pipeline(config);
  Frame frame = f.frame;
  frame.sensor_to_fixed = Eigen::Isometry3d::Identity();
  pipeline.addFrame(frame);
  const PointBuffer cloud = pipeline.makeCloud(pipeline.outputSamples(), false);
  const PointLayout &l = cloud.layout();
  const Samples s = downsample(points, config);
  ASSERT_EQ(s.covariance.size(), s.size());
  ASSERT_EQ(cloud.size(), s.size());
  const char *names[3][3] = {{"cov_xx", "cov_xy", "cov_xz"}, {"cov_xy", "cov_yy", "cov_yz"}, {"cov_xz", "cov_yz", "cov_zz"}};
  std::size_t finite = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    finite += s.covariance[i].allFinite() ? 1 : 0;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        const double expected = readAsDouble(cloud.record(i), *l.find(names[r][c]));
        if (std::isnan(expected)) {
          EXPECT_TRUE(std::isnan(s.covariance[i](r, c)));
        } else {
          EXPECT_EQ(s.covariance[i](r, c), static_cast<float>(expected));
        }
      }
  }
  EXPECT_GT(finite, s.size() / 2);
  config.normals.covariances = false;
  EXPECT_TRUE(downsample(points, config).covariance.empty());
}

TEST(Downsample, SamplesAreRealPointsSpacedAndCoveringByBruteForce) {
  std::vector<Eigen::Vector3f> points;
  std::uint64_t state = 7;
  auto uniform = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<float>((state >> 40) * 0x1.0p-24);
  };
  for (int i = 0; i < 3000; ++i) points.emplace_back(4.0f * uniform(), 4.0f * uniform(), 0.5f * uniform());
  HpdsConfig config;
  config.hierarchy.cell_size = 2.0;
  config.hierarchy.max_depth = 4;
  config.output.level = 3;
  config.output.spacing = 0.0;
  config.normals.enabled = false;
  const Samples s = downsample(points, config);
  ASSERT_GT(s.size(), 10u);
  EXPECT_TRUE(s.normal.empty());
  EXPECT_TRUE(s.curvature.empty());
  const double r = poissonRadius(config.hierarchy.cell_size, 3);
  std::set<std::uint32_t> unique(s.index.begin(), s.index.end());
  EXPECT_EQ(unique.size(), s.size());
  for (std::size_t i = 0; i < s.size(); ++i) {
    ASSERT_LE(s.level[i], 3);
    for (std::size_t j = i + 1; j < s.size(); ++j)
      ASSERT_GE((points[s.index[i]].cast<double>() - points[s.index[j]].cast<double>()).norm(), r) << i << " " << j;
  }
  for (const Eigen::Vector3f &p : points) {
    double best = std::numeric_limits<double>::infinity();
    for (std::uint32_t k : s.index) best = std::min(best, (p.cast<double>() - points[k].cast<double>()).norm());
    ASSERT_LE(best, 2.0 * r);
  }
}

// Found by a SLAM integrator: the one-call API takes no pose, and feeding a Pipeline meant building a PointLayout
// and PointBuffer by hand; nor did Samples say the radius it ran at. frameFromPoints gives a posed frame whose
// samples name their input point; a map built from it is Poisson-disk in the fixed frame (brute force) and each
// sample sits at pose * points[index].
TEST(Downsample, FrameFromPointsFeedsAMapWithPosesAndNamesEachInputPoint) {
  std::uint64_t state = 11;
  auto uniform = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<float>((state >> 40) * 0x1.0p-24);
  };
  HpdsConfig config;
  config.mode = Mode::Map;
  config.hierarchy.cell_size = 2.0;
  config.hierarchy.max_depth = 4;
  config.output.level = 3;
  config.output.spacing = 0.0;
  config.normals.enabled = false;
  Pipeline pipeline(config);
  std::vector<std::vector<Eigen::Vector3f>> frames(3);
  std::vector<Eigen::Isometry3d> poses(3);
  for (int k = 0; k < 3; ++k) {
    for (int i = 0; i < 1500; ++i) frames[k].emplace_back(4.0f * uniform(), 4.0f * uniform(), 0.5f * uniform());
    poses[k] = Eigen::Translation3d(1.5 * k, 0.5 * k, 0.0) * Eigen::AngleAxisd(0.3 * k, Eigen::Vector3d::UnitZ());
    const Frame frame = frameFromPoints(frames[k], poses[k], 10.0 + k);
    EXPECT_EQ(frame.stamp, 10.0 + k);
    (void)pipeline.addFrame(frame);
  }
  const Hierarchy &h = pipeline.hierarchy();
  const PointField *index = h.recordLayout().find("index");
  ASSERT_NE(index, nullptr);
  const std::vector<SampleId> ids = pipeline.outputSamples();
  ASSERT_GT(ids.size(), 10u);
  const double r = poissonRadius(config.hierarchy.cell_size, 3);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const Eigen::Map<const Eigen::Vector3d> p(h.position(ids[i]));
    // Which frame: the one whose posed point at that index is this sample.
    const auto k = static_cast<std::size_t>(readAsDouble(h.record(ids[i]), *index));
    bool found = false;
    for (int f = 0; f < 3 && !found; ++f)
      found = k < frames[f].size() && (poses[f] * frames[f][k].cast<double>() - p).norm() < 1e-9;
    EXPECT_TRUE(found) << "sample " << i << " is no posed input point of index " << k;
    for (std::size_t j = i + 1; j < ids.size(); ++j)
      ASSERT_GE((p - Eigen::Map<const Eigen::Vector3d>(h.position(ids[j]))).norm(), r) << i << " " << j;
  }
  // The one-call API says the resolution it ran at.
  const Samples s = downsample(frames[0], withNormals());
  const OutputResolution want = resolveOutput(withNormals());
  EXPECT_EQ(s.output_level, want.level);
  EXPECT_EQ(s.radius, want.radius);
  EXPECT_EQ(s.cell_size, want.cell_size);
  EXPECT_EQ(frameFromPoints(std::vector<Eigen::Vector3d>{{1.0, 2.0, 3.0}}).points.layout().find("x")->type,
            FieldType::Float64);
}

TEST(Downsample, NanInfAndNoReturnPointsNeverComeOut) {
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  std::vector<Eigen::Vector3f> points = {{nan, 0, 0}, {0, 0, 0}, {1, inf, 0}, {1, 1, 1}, {5, 5, 5}};
  const Samples s = downsample(points, HpdsConfig{});
  std::set<std::uint32_t> got(s.index.begin(), s.index.end());
  EXPECT_EQ(got, (std::set<std::uint32_t>{3, 4}));
  EXPECT_EQ(s.skipped_invalid, 2u);
  EXPECT_EQ(s.skipped_zero, 1u);
  EXPECT_EQ(s.skipped_range + s.out_of_range, 0u);
  EXPECT_TRUE(downsample({}, HpdsConfig{}).index.empty());
}

// Found: points beyond the exact key range (2e7 m: georeferenced coordinates given as they are) left the result
// without a word. They are counted, as are the other points left out.
TEST(Downsample, PointsLeftOutAreCountedByReason) {
  HpdsConfig config;
  config.normals.enabled = false;
  config.input.min_range = 0.5;
  const std::vector<Eigen::Vector3d> points = {{1, 2, 3}, {2e7, 0, 0}, {0, -2e7, 1}, {0.1, 0, 0}, {3, 2, 1}};
  const Samples s = downsampleDoubles(points, config);
  EXPECT_EQ(s.out_of_range, 2u);
  EXPECT_EQ(s.skipped_range, 1u);
  EXPECT_EQ(s.skipped_invalid + s.skipped_zero, 0u);
  const std::set<std::uint32_t> got(s.index.begin(), s.index.end());
  EXPECT_EQ(got, (std::set<std::uint32_t>{0, 4}));
}

// Found in a user trial: a map-mode call over more points than map.max_samples keeps returned the capped map without a
// word (the CLI counts and warns). The samples given up are counted; the rest is what the cap leaves.
TEST(Downsample, SamplesAMapModeCapGivesUpAreCounted) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) points.emplace_back(0.5f * float(i) + 1.f, 0.5f * float(j) - 10.f, -1.f);
  HpdsConfig config;
  config.normals.enabled = false;
  config.mode = Mode::Map;
  const Samples all = downsample(points, config);
  EXPECT_EQ(all.evicted, 0u);
  ASSERT_GT(all.size(), 200u);
  config.map.max_samples = 100;
  const Samples capped = downsample(points, config);
  EXPECT_EQ(capped.size(), 100u);
  EXPECT_EQ(capped.evicted, all.size() - 100u);
  // The farthest from the sensor went: every kept sample is at most as far as every one given up.
  auto range = [&](std::uint32_t k) { return points[k].norm(); };
  const std::set<std::uint32_t> kept(capped.index.begin(), capped.index.end());
  float kept_max = 0.f, dropped_min = 1e9f;
  for (std::uint32_t k : all.index) {
    if (kept.count(k))
      kept_max = std::max(kept_max, range(k));
    else
      dropped_min = std::min(dropped_min, range(k));
  }
  for (std::uint32_t k : capped.index) EXPECT_EQ(std::count(all.index.begin(), all.index.end(), k), 1) << k;
  EXPECT_LE(kept_max, dropped_min);
}

// Found in a user trial: Ctrl-C could not stop a Python call of seconds (the binding sets the flag on a signal).
TEST(Downsample, AnInterruptStopsTheCallAndAClearFlagChangesNothing) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 1000; ++i)
    for (int j = 0; j < 1000; ++j)
      points.emplace_back(0.05f * float(i) - 25.f, 0.05f * float(j) - 25.f, -1.5f + 0.001f * float((i * 7 + j) % 13));
  HpdsConfig config;
  config.normals.covariances = true;
  const Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  // A flag that stays clear: the same samples, normals and covariances as without one.
  std::atomic<bool> clear{false};
  const Samples plain = downsample(points, config, origin);
  const Samples watched = downsample(points, config, origin, clear);
  EXPECT_EQ(watched.index, plain.index);
  EXPECT_EQ(watched.level, plain.level);
  ASSERT_EQ(watched.normal.size(), plain.normal.size());
  for (std::size_t i = 0; i < plain.size(); ++i)
    EXPECT_TRUE(watched.normal[i].cwiseEqual(plain.normal[i]).all() || !plain.normal[i].allFinite()) << i;
  // Set before the call, for both point types: nothing is done.
  std::atomic<bool> set{true};
  EXPECT_THROW((void)downsample(points, config, origin, set), Interrupted);
  const std::vector<Eigen::Vector3d> doubles(1, Eigen::Vector3d(1, 2, 3));
  EXPECT_THROW((void)downsampleDoubles(doubles, config, origin, set), Interrupted);
  // Set by another thread as the call starts: it stops (a million points take about a second here; the flag is read
  // before the frame's stages and every 2^18 points of an insertion pass).
  for (int threads : {1, 2}) {
    config.threads = threads;
    std::atomic<bool> flag{false};
    std::thread stopper([&] { flag = true; });
    try {
      (void)downsample(points, config, origin, flag);
      ADD_FAILURE() << "not interrupted, threads " << threads;
    } catch (const Interrupted &e) {
      EXPECT_NE(std::string(e.what()).find("interrupted ("), std::string::npos) << e.what();
    }
    stopper.join();
  }
}

// The pipeline: addFrame and normals() stop at once when the flag is set.
TEST(Downsample, APipelineStopsWhenItsInterruptIsSet) {
  SyntheticLidarConfig lc;
  lc.beams = 16;
  lc.azimuth_steps = 360;
  lc.frames = 2;
  const SyntheticLidar lidar(lc);
  HpdsConfig config;
  Pipeline pipeline(config);
  std::atomic<bool> flag{false};
  pipeline.setInterrupt(&flag);
  (void)pipeline.addFrame(lidar.frame(0).frame);
  const std::vector<SampleId> ids = pipeline.outputSamples();
  ASSERT_FALSE(ids.empty());
  flag = true;
  EXPECT_THROW((void)pipeline.normals(ids), Interrupted);
  EXPECT_THROW((void)pipeline.addFrame(lidar.frame(1).frame), Interrupted);
  EXPECT_EQ(pipeline.framesProcessed(), 1u);
  pipeline.setInterrupt(nullptr);
  EXPECT_EQ(pipeline.normals(ids).size(), ids.size());
}

TEST(Downsample, NormalsFaceTheOriginAndAreNanWhereNotEstimable) {
  // A flat patch 10 m in front of the sensor, plus one isolated point.
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 60; ++j) points.emplace_back(10.0f, -1.5f + 0.05f * float(i), -1.5f + 0.05f * float(j));
  points.emplace_back(-40.0f, 30.0f, 2.0f);
  HpdsConfig config = withNormals();
  const Samples s = downsample(points, config);
  ASSERT_EQ(s.normal.size(), s.size());
  std::size_t valid = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s.index[i] == points.size() - 1) {
      EXPECT_TRUE(std::isnan(s.normal[i].x()) && std::isnan(s.curvature[i]));
      continue;
    }
    if (std::isnan(s.normal[i].x())) continue;
    ++valid;
    EXPECT_LT(s.normal[i].x(), -0.99f) << i;  // faces the sensor at the origin: -x
    EXPECT_NEAR(s.normal[i].norm(), 1.0f, 1e-5f);
  }
  EXPECT_GT(valid, s.size() / 2);
}

// A cloud kept in another frame: the sensor was at `viewpoint` there, and normals face it (PCL's sensor_origin_).
TEST(Downsample, NormalsFaceAViewpointGivenAndRangesAreMeasuredFromIt) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 60; ++j) points.emplace_back(10.0f, -1.5f + 0.05f * float(i), -1.5f + 0.05f * float(j));
  HpdsConfig config = withNormals();
  const Samples at_origin = downsample(points, config);
  const Samples behind = downsample(points, config, Eigen::Vector3d(20.0, 0.0, 0.0));
  ASSERT_EQ(behind.index, at_origin.index);  // where the sensor was changes no sample
  std::size_t valid = 0;
  for (std::size_t i = 0; i < behind.size(); ++i) {
    if (std::isnan(behind.normal[i].x())) continue;
    ++valid;
    EXPECT_GT(behind.normal[i].x(), 0.99f) << i;  // the sensor at x = 20 sees the patch's +x side
    EXPECT_EQ(behind.normal[i], -at_origin.normal[i]);
  }
  EXPECT_GT(valid, behind.size() / 2);
  // input.max_range 5 m: every point is 10 m from the origin but within 5 m of a viewpoint at x = 8.
  config.input.max_range = 5.0;
  EXPECT_EQ(downsample(points, config).size(), 0u);
  EXPECT_EQ(downsample(points, config, Eigen::Vector3d(8.0, 0.0, 0.0)).size(), at_origin.size());
  EXPECT_THROW((void)downsample(points, config, Eigen::Vector3d(NAN, 0.0, 0.0)), std::invalid_argument);
}

TEST(Downsample, SameInputAndSeedSameSamplesWhateverTheThreads) {
  const std::vector<Eigen::Vector3f> points = xyzOf(syntheticFrame().frame.points);
  HpdsConfig one = withNormals(), many = withNormals(), other = withNormals();
  many.threads = 4;
  other.order.seed = 99;
  const Samples a = downsample(points, one), b = downsample(points, many), c = downsample(points, other);
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.level, b.level);
  for (std::size_t i = 0; i < a.size(); ++i)
    for (int k = 0; k < 3; ++k)
      EXPECT_TRUE(a.normal[i][k] == b.normal[i][k] || (std::isnan(a.normal[i][k]) && std::isnan(b.normal[i][k])));
  EXPECT_NE(a.index, c.index);
}

// The header's contract: concurrent calls are safe (no state shared between calls). Several callers at once, each
// with two threads of its own, get the samples of one call alone (`make test-tsan` watches them for races).
TEST(Downsample, CallsFromSeveralThreadsAtOnceGiveTheSameSamples) {
  const std::vector<Eigen::Vector3f> points = xyzOf(syntheticFrame().frame.points);
  HpdsConfig config = withNormals();
  config.threads = 2;
  const Samples expected = downsample(points, config);
  std::vector<Samples> got(4);
  std::vector<std::thread> callers;
  for (Samples &s : got) callers.emplace_back([&] { s = downsample(points, config); });
  for (std::thread &t : callers) t.join();
  for (const Samples &s : got) {
    EXPECT_EQ(s.index, expected.index);
    EXPECT_EQ(s.level, expected.level);
    ASSERT_EQ(s.normal.size(), expected.normal.size());
    for (std::size_t i = 0; i < s.size(); ++i)
      for (int k = 0; k < 3; ++k)
        EXPECT_TRUE(s.normal[i][k] == expected.normal[i][k] ||
                    (std::isnan(s.normal[i][k]) && std::isnan(expected.normal[i][k])));
  }
}

// Georeferenced points (a UTM northing of 4e6 m, where float32 keeps 0.25 m) through the double-precision call: the
// guarantees hold on the float64 positions by brute force (spacing and coverage), a leading no-return (0,0,0) changes
// nothing, and the sampling is that of the same cloud at the origin (the offset is a whole number of level-0 cells),
// up to near-ties that double rounding at 4e6 m decides otherwise.
TEST(Downsample, DoublesKeepTheGuaranteesAtGeoreferencedCoordinates) {
  const std::vector<Eigen::Vector3f> local32 = xyzOf(syntheticFrame().frame.points);
  HpdsConfig config;
  config.normals.enabled = false;
  const HpdsConfig resolved = resolvedConfig(config);
  const double cell = resolved.hierarchy.cell_size, r = poissonRadius(cell, resolved.output.level);
  const Eigen::Vector3d offset = (Eigen::Vector3d(5.0e5, 4.0e6, 30.0) / cell).array().round() * cell;
  std::vector<Eigen::Vector3d> local, geo;
  for (const Eigen::Vector3f &p : local32) {
    if (!p.allFinite() || p.isZero(0.0)) continue;
    local.push_back(p.cast<double>());
    geo.push_back(p.cast<double>() + offset);
  }
  const Samples at_origin = downsampleDoubles(local, config);
  const Samples far = downsampleDoubles(geo, config);
  EXPECT_NEAR(double(far.size()), double(at_origin.size()), 0.01 * double(at_origin.size()));
  for (std::size_t i = 0; i < far.size(); ++i)
    for (std::size_t j = i + 1; j < far.size(); ++j)
      ASSERT_GE((geo[far.index[i]] - geo[far.index[j]]).norm(), r * (1 - 1e-9)) << i << " " << j;
  for (const Eigen::Vector3d &p : geo) {
    double nearest = INFINITY;
    for (std::uint32_t k : far.index) nearest = std::min(nearest, (geo[k] - p).norm());
    ASSERT_LE(nearest, 2 * r * (1 + 1e-9));
  }
  std::vector<Eigen::Vector3d> with_zero = geo;
  with_zero.insert(with_zero.begin(), Eigen::Vector3d::Zero());
  const Samples led = downsampleDoubles(with_zero, config);
  ASSERT_EQ(led.size(), far.size());
  for (std::size_t i = 0; i < led.size(); ++i) EXPECT_EQ(led.index[i], far.index[i] + 1);
  // The float32 call on the same cloud cannot keep them: it is what the double call is for.
  std::vector<Eigen::Vector3f> geo32;
  for (const Eigen::Vector3d &p : geo) geo32.push_back(p.cast<float>());
  const Samples rounded = downsample(geo32, config);
  double closest = INFINITY;
  for (std::size_t i = 0; i < rounded.size(); ++i)
    for (std::size_t j = i + 1; j < rounded.size(); ++j)
      closest = std::min(closest, (geo[rounded.index[i]] - geo[rounded.index[j]]).norm());
  EXPECT_LT(closest, r);
}

TEST(Downsample, BadConfigIsAnErrorNamingTheKey) {
  HpdsConfig c;
  c.hierarchy.max_depth = 40;
  try {
    (void)downsample({{1, 2, 3}}, c);
    FAIL() << "no error";
  } catch (const std::invalid_argument &e) {
    EXPECT_EQ(std::string(e.what()).rfind("hierarchy.max_depth", 0), 0u) << e.what();
  }
}

TEST(LoadConfig, TheShippedFileIsTheDefaultsAndErrorsNameTheKey) {
  const HpdsConfig shipped = loadConfig(std::string(HPDS_SOURCE_DIR) + "/config/hpds.yaml");
  EXPECT_EQ(dumpConfigYaml(shipped), dumpConfigYaml(HpdsConfig{}));
  const auto dir = test::scratchDir("load_config");
  const std::string bad = (dir / "bad.yaml").string();
  std::ofstream(bad) << "normals:\n  k: -3\n";
  try {
    (void)loadConfig(bad);
    FAIL() << "no error";
  } catch (const std::invalid_argument &e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("normals.k", 0), 0u) << what;
    EXPECT_NE(what.find(bad), std::string::npos) << what;
  }
  EXPECT_THROW((void)loadConfig((dir / "missing.yaml").string()), std::invalid_argument);
}

}  // namespace
}  // namespace hpds
