// The pipeline on the real lidar frames of ../shared/data/lidar: the VLP-16 frame's fields survive sampling, and the
// HDL-32 pair with its relative pose builds one map. Skipped when the data is absent.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <vector>

#include "TestData.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {
namespace {

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
