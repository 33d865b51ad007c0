// Tests of the synthetic lidar: determinism, layout, ground truth that actually matches the scene, and the sensor
// effects (no-returns, rings, times) that downstream code relies on.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "hpds/eval/SyntheticLidar.hpp"

namespace hpds {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct PointView {
  Eigen::Vector3d p;
  double intensity;
  int ring;
  double time;
};

PointView readPoint(const PointBuffer &buf, std::size_t i) {
  const PointLayout &l = buf.layout();
  const std::uint8_t *rec = buf.record(i);
  return {Eigen::Vector3d(readAsDouble(rec, *l.find("x")), readAsDouble(rec, *l.find("y")),
                          readAsDouble(rec, *l.find("z"))),
          readAsDouble(rec, *l.find("intensity")), static_cast<int>(readAsDouble(rec, *l.find("ring"))),
          readAsDouble(rec, *l.find("time"))};
}

bool isNoReturn(const PointView &v) { return v.p.x() == 0.0 && v.p.y() == 0.0 && v.p.z() == 0.0; }

// Smaller than the default sweep so the surface checks stay quick; geometry is otherwise the default.
SyntheticLidarConfig smallConfig(SceneKind scene = SceneKind::Urban) {
  SyntheticLidarConfig c;
  c.azimuth_steps = 720;
  c.frames = 3;
  c.scene = scene;
  return c;
}

std::array<std::size_t, kObjectKindCount> countKinds(const std::vector<SyntheticFrame> &frames) {
  std::array<std::size_t, kObjectKindCount> counts{};
  for (const auto &f : frames)
    for (const ObjectKind k : f.kinds) ++counts[static_cast<int>(k)];
  return counts;
}

void expectSameFrame(const SyntheticFrame &a, const SyntheticFrame &b) {
  EXPECT_EQ(a.frame.points.layout(), b.frame.points.layout());
  EXPECT_EQ(a.frame.points.width(), b.frame.points.width());
  EXPECT_EQ(a.frame.points.height(), b.frame.points.height());
  EXPECT_TRUE(a.frame.points.bytes() == b.frame.points.bytes());
  EXPECT_EQ(a.frame.stamp, b.frame.stamp);
  EXPECT_TRUE(a.frame.sensor_to_fixed.matrix() == b.frame.sensor_to_fixed.matrix());
  EXPECT_TRUE(a.normals == b.normals);
  EXPECT_TRUE(a.kinds == b.kinds);
}

TEST(SyntheticLidar, SameSeedGivesByteIdenticalFrames) {
  const SyntheticLidar a(smallConfig()), b(smallConfig());
  const auto sa = a.stream(), sb = b.stream();
  ASSERT_EQ(sa.size(), 3u);
  ASSERT_EQ(sb.size(), 3u);
  for (std::size_t i = 0; i < sa.size(); ++i) expectSameFrame(sa[i], sb[i]);
  // A frame does not depend on which frames were generated before it.
  expectSameFrame(a.frame(2), sa[2]);
}

TEST(SyntheticLidar, FrameDoesNotDependOnStreamLength) {
  SyntheticLidarConfig longer = smallConfig();
  longer.frames = 8;
  expectSameFrame(SyntheticLidar(smallConfig()).frame(1), SyntheticLidar(longer).frame(1));
}

TEST(SyntheticLidar, DifferentSeedGivesDifferentFrames) {
  SyntheticLidarConfig other = smallConfig();
  other.seed = 2;
  const auto a = SyntheticLidar(smallConfig()).frame(0), b = SyntheticLidar(other).frame(0);
  EXPECT_FALSE(a.frame.points.bytes() == b.frame.points.bytes());
  // The scene itself changes, not only the noise.
  other.range_noise = 0.0;
  SyntheticLidarConfig base = smallConfig();
  base.range_noise = 0.0;
  EXPECT_FALSE(SyntheticLidar(base).frame(0).kinds == SyntheticLidar(other).frame(0).kinds);
}

TEST(SyntheticLidar, LayoutAndOrganisation) {
  const SyntheticLidarConfig c;  // the full default sweep
  const SyntheticFrame f = SyntheticLidar(c).frame(0);
  const PointLayout &l = f.frame.points.layout();
  l.validate();
  const std::array<const char *, 6> names = {"x", "y", "z", "intensity", "ring", "time"};
  ASSERT_EQ(l.fields.size(), names.size());
  for (std::size_t i = 0; i < names.size(); ++i) EXPECT_EQ(l.fields[i].name, names[i]);
  EXPECT_EQ(l.find("ring")->type, FieldType::UInt16);
  EXPECT_EQ(l.find("time")->type, FieldType::Float32);
  EXPECT_EQ(l.find("time")->offset % 4, 0u);
  EXPECT_EQ(f.frame.points.width(), 1800u);
  EXPECT_EQ(f.frame.points.height(), 32u);
  EXPECT_EQ(f.frame.points.size(), 1800u * 32u);
  EXPECT_EQ(f.normals.size(), f.frame.points.size());
  EXPECT_EQ(f.kinds.size(), f.frame.points.size());

  // Organised cell (row, column) is ring `row` fired at column `column`.
  const PointBuffer &pts = f.frame.points;
  for (std::size_t i = 0; i < pts.size(); i += 97) {
    const PointView v = readPoint(pts, i);
    EXPECT_EQ(v.ring, static_cast<int>(i / 1800));
    EXPECT_NEAR(v.time, static_cast<double>(i % 1800) / 1800 * c.frame_period, 1e-7);
  }
}

TEST(SyntheticLidar, RingsTimesAndIntensityInRange) {
  const SyntheticLidarConfig c = smallConfig();
  for (const auto &f : SyntheticLidar(c).stream()) {
    for (std::size_t i = 0; i < f.frame.points.size(); ++i) {
      const PointView v = readPoint(f.frame.points, i);
      ASSERT_GE(v.ring, 0);
      ASSERT_LT(v.ring, c.beams);
      ASSERT_GE(v.time, 0.0);
      ASSERT_LT(v.time, c.frame_period);
      ASSERT_GE(v.intensity, 0.0);
      ASSERT_LE(v.intensity, 255.0);
    }
  }
}

TEST(SyntheticLidar, NoReturnsAreZeroPointsOrAbsent) {
  SyntheticLidarConfig c = smallConfig();
  const SyntheticFrame with = SyntheticLidar(c).frame(0);
  std::size_t zeros = 0;
  for (std::size_t i = 0; i < with.frame.points.size(); ++i) {
    const bool none = with.kinds[i] == ObjectKind::None;
    EXPECT_EQ(isNoReturn(readPoint(with.frame.points, i)), none);
    if (none) {
      ++zeros;
      EXPECT_EQ(with.normals[i], Eigen::Vector3f::Zero());
      EXPECT_EQ(readPoint(with.frame.points, i).intensity, 0.0);
    }
  }
  EXPECT_GT(zeros, 0u);  // upper beams see the sky
  EXPECT_LT(zeros, with.frame.points.size() / 2);

  c.emit_no_returns = false;
  const SyntheticFrame without = SyntheticLidar(c).frame(0);
  EXPECT_EQ(without.frame.points.height(), 1u);
  EXPECT_EQ(without.frame.points.size(), with.frame.points.size() - zeros);
  for (std::size_t i = 0; i < without.frame.points.size(); ++i) {
    ASSERT_FALSE(isNoReturn(readPoint(without.frame.points, i)));
    ASSERT_NE(without.kinds[i], ObjectKind::None);
  }

  // Unorganised with no-returns: same points in firing order (column-major).
  c.emit_no_returns = true;
  c.organized = false;
  const SyntheticFrame firing = SyntheticLidar(c).frame(0);
  EXPECT_EQ(firing.frame.points.height(), 1u);
  ASSERT_EQ(firing.frame.points.size(), with.frame.points.size());
  const std::size_t cols = static_cast<std::size_t>(c.azimuth_steps), rings = static_cast<std::size_t>(c.beams);
  for (std::size_t i = 0; i < firing.frame.points.size(); i += 13) {
    const std::size_t organised = (i % rings) * cols + i / rings;
    EXPECT_EQ(std::memcmp(firing.frame.points.record(i), with.frame.points.record(organised),
                          with.frame.points.layout().point_step),
              0);
  }
}

// Every return, taken back to the world, lies on the scene surface; normals match the surface there.
void checkOnSurface(SyntheticLidarConfig c) {
  const SyntheticLidar lidar(c);
  const double tolerance = 5.0 * c.range_noise + 1e-4;
  std::size_t returns = 0, normal_agree = 0, fd_checked = 0, fd_agree = 0;
  for (const auto &f : lidar.stream()) {
    for (std::size_t i = 0; i < f.frame.points.size(); ++i) {
      if (f.kinds[i] == ObjectKind::None) continue;
      ++returns;
      const PointView v = readPoint(f.frame.points, i);
      const Eigen::Vector3d world = f.frame.sensor_to_fixed * v.p;
      const SceneQuery q = lidar.queryScene(world);
      ASSERT_LE(std::abs(q.signed_distance), tolerance)
          << toString(c.scene) << " " << toString(f.kinds[i]) << " at " << world.transpose();
      const Eigen::Vector3d n = f.normals[i].cast<double>();
      ASSERT_NEAR(n.norm(), 1.0, 1e-5);
      ASSERT_GT(n.dot(-v.p), 0.0) << "normal faces away from the sensor";
      const Eigen::Vector3d n_world = f.frame.sensor_to_fixed.linear() * n;
      if (n_world.dot(q.normal) > 0.99) ++normal_agree;
      // Independent check of the sculpture's analytic gradient: finite differences of the distance field.
      if (f.kinds[i] == ObjectKind::Sculpture && c.range_noise == 0.0) {
        const double h = 1e-5;
        Eigen::Vector3d g;
        for (int a = 0; a < 3; ++a) {
          Eigen::Vector3d e = Eigen::Vector3d::Zero();
          e[a] = h;
          g[a] = (lidar.queryScene(world + e).signed_distance - lidar.queryScene(world - e).signed_distance) / (2 * h);
        }
        ++fd_checked;
        if (g.normalized().dot(n_world) > 0.995) ++fd_agree;
      }
    }
  }
  ASSERT_GT(returns, 1000u);
  // Disagreement only where the nearest surface is another object (edges, creases, overlapping solids).
  EXPECT_GT(static_cast<double>(normal_agree), 0.98 * returns) << toString(c.scene);
  if (fd_checked > 0) {
    EXPECT_GT(static_cast<double>(fd_agree), 0.95 * fd_checked);
  }
}

TEST(SyntheticLidar, ReturnsLieOnTheSceneWithNoise) {
  for (const SceneKind scene : {SceneKind::Urban, SceneKind::PlanarUrban, SceneKind::CurvedObjects})
    checkOnSurface(smallConfig(scene));
}

TEST(SyntheticLidar, ReturnsLieOnTheSceneWithoutNoise) {
  for (const SceneKind scene : {SceneKind::Urban, SceneKind::CurvedObjects}) {
    SyntheticLidarConfig c = smallConfig(scene);
    c.range_noise = 0.0;
    checkOnSurface(c);
  }
}

TEST(SyntheticLidar, NoiseIsAlongTheRayWithTheRequestedSigma) {
  SyntheticLidarConfig exact = smallConfig(), noisy = smallConfig();
  exact.range_noise = 0.0;
  noisy.range_noise = 0.05;
  const SyntheticFrame a = SyntheticLidar(exact).frame(0), b = SyntheticLidar(noisy).frame(0);
  ASSERT_EQ(a.frame.points.size(), b.frame.points.size());
  double sum = 0.0, sum2 = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.frame.points.size(); ++i) {
    if (a.kinds[i] == ObjectKind::None || b.kinds[i] == ObjectKind::None) continue;
    const Eigen::Vector3d pa = readPoint(a.frame.points, i).p, pb = readPoint(b.frame.points, i).p;
    ASSERT_LT(pa.normalized().cross(pb.normalized()).norm(), 1e-5);  // same ray
    const double e = pb.norm() - pa.norm();
    ASSERT_LE(std::abs(e), 4.0 * noisy.range_noise + 1e-4);
    sum += e;
    sum2 += e * e;
    ++n;
  }
  ASSERT_GT(n, 10000u);
  const double mean = sum / n, sigma = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.002);
  EXPECT_NEAR(sigma, noisy.range_noise, 0.002);
}

TEST(SyntheticLidar, EveryObjectKindIsHit) {
  const auto urban = countKinds(SyntheticLidar(smallConfig(SceneKind::Urban)).stream());
  for (const ObjectKind k : {ObjectKind::Ground, ObjectKind::Wall, ObjectKind::Box, ObjectKind::Cylinder,
                             ObjectKind::Sphere, ObjectKind::Sculpture})
    EXPECT_GT(urban[static_cast<int>(k)], 20u) << "urban: " << toString(k);
  EXPECT_GT(urban[static_cast<int>(ObjectKind::Sculpture)], 300u);  // close enough to resolve its ripples

  const auto planar = countKinds(SyntheticLidar(smallConfig(SceneKind::PlanarUrban)).stream());
  for (const ObjectKind k : {ObjectKind::Ground, ObjectKind::Wall, ObjectKind::Box})
    EXPECT_GT(planar[static_cast<int>(k)], 20u) << "planar: " << toString(k);
  for (const ObjectKind k : {ObjectKind::Cylinder, ObjectKind::Sphere, ObjectKind::Sculpture})
    EXPECT_EQ(planar[static_cast<int>(k)], 0u) << "planar: " << toString(k);

  const auto curved = countKinds(SyntheticLidar(smallConfig(SceneKind::CurvedObjects)).stream());
  for (const ObjectKind k : {ObjectKind::Cylinder, ObjectKind::Sphere, ObjectKind::Sculpture})
    EXPECT_GT(curved[static_cast<int>(k)], 100u) << "curved: " << toString(k);
  EXPECT_EQ(curved[static_cast<int>(ObjectKind::Wall)], 0u);
  EXPECT_EQ(curved[static_cast<int>(ObjectKind::Box)], 0u);
}

TEST(SyntheticLidar, GroundRingsFollowBeamElevations) {
  SyntheticLidarConfig c = smallConfig();
  c.range_noise = 0.0;
  const SyntheticFrame f = SyntheticLidar(c).frame(0);
  const double step = (c.max_elevation_deg - c.min_elevation_deg) / (c.beams - 1);
  std::size_t checked = 0;
  for (std::size_t i = 0; i < f.frame.points.size(); ++i) {
    if (f.kinds[i] != ObjectKind::Ground) continue;
    const PointView v = readPoint(f.frame.points, i);
    const double el = (c.min_elevation_deg + v.ring * step) * kPi / 180.0;
    ASSERT_LT(el, 0.0);
    // Dense circles of radius h / tan(-elevation), sparse between them: the scan-line pattern.
    EXPECT_NEAR(v.p.head<2>().norm(), c.sensor_height / std::tan(-el), 1e-3);
    EXPECT_NEAR(v.p.z(), -c.sensor_height, 1e-4);
    ++checked;
  }
  EXPECT_GT(checked, 5000u);
}

TEST(SyntheticLidar, ConsecutiveFramesAgreeInTheWorld) {
  SyntheticLidarConfig c = smallConfig();
  c.range_noise = 0.0;
  const SyntheticLidar lidar(c);
  const auto frames = lidar.stream();
  for (std::size_t i = 0; i + 1 < frames.size(); ++i) {
    const Eigen::Isometry3d rel = frames[i].frame.sensor_to_fixed.inverse() * frames[i + 1].frame.sensor_to_fixed;
    // Arc of curvature yaw_rate / speed: the chord is just under `speed`, heading changes by yaw_rate.
    EXPECT_NEAR(rel.translation().norm(), c.speed, 1e-3);
    EXPECT_NEAR(std::atan2(rel.linear()(1, 0), rel.linear()(0, 0)), c.yaw_rate, 1e-12);
    EXPECT_NEAR(rel.translation().z(), 0.0, 1e-12);
    EXPECT_DOUBLE_EQ(frames[i].frame.stamp, i * c.frame_period);

    // What frame i+1 saw is what frame i sees along the same world line of sight, unless something occludes it.
    const Eigen::Vector3d origin = frames[i].frame.sensor_to_fixed.translation();
    std::size_t tried = 0, agreed = 0;
    const SyntheticFrame &next = frames[i + 1];
    for (std::size_t k = 0; k < next.frame.points.size(); k += 3) {
      if (next.kinds[k] == ObjectKind::None) continue;
      const Eigen::Vector3d world = next.frame.sensor_to_fixed * readPoint(next.frame.points, k).p;
      const Eigen::Vector3d ray = world - origin;
      const double dist = ray.norm();
      if (dist > c.max_range - 1.0) continue;
      ++tried;
      const auto hit = lidar.castRay(origin, ray / dist, c.max_range);
      if (hit && std::abs(hit->t - dist) < 1e-3 && hit->kind == next.kinds[k]) ++agreed;
    }
    ASSERT_GT(tried, 1000u);
    EXPECT_GT(static_cast<double>(agreed), 0.9 * tried);
  }
}

TEST(SyntheticLidar, StraightPathAndStaticSensor) {
  SyntheticLidarConfig c = smallConfig();
  c.yaw_rate = 0.0;
  const SyntheticLidar straight(c);
  EXPECT_TRUE(straight.pose(2).translation().isApprox(Eigen::Vector3d(2.0 * c.speed, 0.0, c.sensor_height)));
  c.speed = 0.0;
  c.yaw_rate = 0.1;
  const SyntheticLidar spinning(c);
  EXPECT_TRUE(spinning.pose(2).translation().isApprox(Eigen::Vector3d(0.0, 0.0, c.sensor_height)));
  EXPECT_NO_THROW((void)spinning.frame(2));
}

TEST(SyntheticLidar, RejectsBadConfigAndIndices) {
  const auto bad = [](auto mutate) {
    SyntheticLidarConfig c;
    mutate(c);
    return c;
  };
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.beams = 0; })), std::invalid_argument);
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.azimuth_steps = 0; })), std::invalid_argument);
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.max_elevation_deg = -30.0; })), std::invalid_argument);
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.range_noise = -1.0; })), std::invalid_argument);
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.max_range = NAN; })), std::invalid_argument);
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.frame_period = 0.0; })), std::invalid_argument);
  EXPECT_THROW(SyntheticLidar(bad([](auto &c) { c.yaw_rate = 0.1; })), std::invalid_argument);  // 10 m radius
  const SyntheticLidar lidar(smallConfig());
  EXPECT_THROW((void)lidar.frame(-1), std::out_of_range);
  EXPECT_THROW((void)lidar.frame(3), std::out_of_range);
}

}  // namespace
}  // namespace hpds
