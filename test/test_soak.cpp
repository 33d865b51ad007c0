// Soak: a long synthetic drive in map mode with eviction. Once eviction has started, memory and sample count stay
// flat however far the sensor drives, nothing inside the eviction radius is lost, and the local map around the
// sensor remains a valid Poisson-disk sampling that covers the latest sweep.
// Bounded to about a minute in Release; sanitizer builds drive a quarter of the distance.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/eval/SamplingVerifier.hpp"
#include "hpds/eval/SyntheticLidar.hpp"

#if defined(__SANITIZE_ADDRESS__)
#define HPDS_SOAK_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HPDS_SOAK_SANITIZED 1
#endif
#endif

namespace hpds {
namespace {

#ifdef HPDS_SOAK_SANITIZED
constexpr int kFrames = 600;
#else
constexpr int kFrames = 2400;
#endif
constexpr double kEvict = 40.0;
constexpr double kSpeed = 1.5;  // m per frame: 3.6 km in Release

// The latest sweep in the fixed frame, without no-returns and beyond the sensor's range filter.
PointBuffer sweepInFixedFrame(const Frame &f) {
  PointLayout l;
  for (const char *a : {"x", "y", "z"}) l.append(a, FieldType::Float64);
  PointBuffer out(l, 0);
  const PointLayout &in = f.points.layout();
  for (std::size_t i = 0; i < f.points.size(); ++i) {
    const Eigen::Vector3d p(readAsDouble(f.points.record(i), *in.find("x")),
                            readAsDouble(f.points.record(i), *in.find("y")),
                            readAsDouble(f.points.record(i), *in.find("z")));
    if (p.isZero(0.0)) continue;
    const Eigen::Vector3d w = f.sensor_to_fixed * p;
    std::uint8_t rec[24];
    std::memcpy(rec, w.data(), 24);
    out.pushBack(rec);
  }
  return out;
}

TEST(Soak, LongDriveInMapModeKeepsMemoryFlatAndTheLocalMapCorrect) {
  const auto t0 = std::chrono::steady_clock::now();
  SyntheticLidarConfig lc;
  lc.beams = 8;
  lc.azimuth_steps = 240;
  lc.frames = kFrames;
  lc.speed = kSpeed;
  lc.yaw_rate = 0.0;  // a straight street: a curved one would wrap into a circle and revisit old ground
  lc.max_range = 35.0;
  lc.seed = 11;
  const SyntheticLidar lidar(lc);

  HpdsConfig c;
  c.mode = Mode::Map;
  c.hierarchy.cell_size = 4.0;
  c.hierarchy.max_depth = 6;
  c.output.level = 5;
  c.map.evict_distance = kEvict;
  c.map.max_samples = 0;      // eviction alone bounds the map here
  c.map.keep_depth = 6;       // every level stored, as the memory figures below assume
  c.normals.enabled = false;  // the map, not the normals, is under test
  c.order.seed = 3;
  Pipeline p(c);

  // Eviction starts once the sensor is kEvict past the first samples; measure from twice that on.
  const int warmup = static_cast<int>(2.0 * (kEvict + lc.max_range) / kSpeed);
  ASSERT_LT(warmup * 3, kFrames);
  std::size_t first_bytes = 0, first_count = 0, max_bytes = 0, max_count = 0, min_count = SIZE_MAX;
  std::uint64_t offered = 0;
  int checks = 0;
  for (int i = 0; i < kFrames; ++i) {
    const SyntheticFrame sf = lidar.frame(i);
    const FrameResult r = p.addFrame(sf.frame);
    offered += r.counters.input;
    const Hierarchy &h = p.hierarchy();
    if (i == warmup) {
      first_bytes = h.memUsage();
      first_count = h.sampleCount();
    }
    if (i >= warmup) {
      max_bytes = std::max(max_bytes, h.memUsage());
      max_count = std::max(max_count, h.sampleCount());
      min_count = std::min(min_count, h.sampleCount());
    }
    // Six times along the drive: the whole stored map obeys the eviction radius (samples kept from before this frame)
    // and the map around the sensor is a valid sampling that covers the latest sweep.
    if (i >= warmup && (i % (kFrames / 6) == 0 || i == kFrames - 1)) {
      ++checks;
      const Eigen::Vector3d s = sf.frame.sensor_to_fixed.translation();
      for (SampleId id = 0; id < h.idBound(); ++id) {
        if (!h.isLive(id) || h.frameIndex(id) == static_cast<std::uint32_t>(i)) continue;
        const double *q = h.position(id);
        ASSERT_LE((Eigen::Vector3d(q[0], q[1], q[2]) - s).norm(), kEvict + 1e-9) << "frame " << i;
      }
      const double center[3] = {s.x(), s.y(), s.z()};
      // Wider than kEvict: this frame's own samples reach max_range, and coverage is checked up to 2 r_0 beyond.
      const PointBuffer local = p.makeCloud(p.outputSamplesNear(center, kEvict + 10.0), false);
      ASSERT_GT(local.size(), 500u);
      const PointBuffer sweep = sweepInFixedFrame(sf.frame);
      const VerifyReport rep = verifySampling(local, c.hierarchy.cell_size, &sweep);
      ASSERT_EQ(rep.total_violations(), 0u) << "frame " << i << "\n" << formatReport(rep);
    }
  }
  EXPECT_GE(checks, 3);
  EXPECT_GT(p.totals().evicted, p.totals().accepted / 2);  // most of what was ever sampled has been driven past
  // Flat: after warm-up the map neither grows with the distance driven nor leaks storage.
  EXPECT_LE(max_count, first_count * 13 / 10) << "samples grew from " << first_count << " to " << max_count;
  EXPECT_GE(min_count, first_count * 7 / 10);
  EXPECT_LE(max_bytes, first_bytes * 3 / 2) << "memUsage grew from " << first_bytes << " to " << max_bytes;
  EXPECT_EQ(p.framesProcessed(), static_cast<std::uint32_t>(kFrames));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  RecordProperty("frames", kFrames);
  RecordProperty("points", static_cast<int>(offered));
  std::printf("soak: %d frames, %llu points, %.1f km, %.1f s, map %zu..%zu samples, %zu bytes peak\n", kFrames,
              static_cast<unsigned long long>(offered), kFrames * kSpeed / 1000.0, seconds, min_count, max_count,
              max_bytes);
}

}  // namespace
}  // namespace hpds
