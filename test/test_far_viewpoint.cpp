// nearestPointDistance / isFarViewpoint: the check behind the CLI's and Python's "viewpoint far from every point"
// warning, against a brute-force distance over random clouds with NaN/Inf points, in both storage forms.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "hpds/points/FarViewpoint.hpp"

namespace {

using hpds::FieldType;
using hpds::PointBuffer;
using hpds::PointLayout;

TEST(FarViewpoint, NearestDistanceMatchesBruteForceAndSkipsNonFinitePoints) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coord(-2000.0, 2000.0);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (int trial = 0; trial < 50; ++trial) {
    PointLayout layout;
    layout.append("intensity", FieldType::Float32);  // x y z not first: fields are found by name
    layout.append("x", FieldType::Float64);
    layout.append("y", FieldType::Float64);
    layout.append("z", FieldType::Float64);
    const std::size_t n = 1 + trial * 7;
    PointBuffer cloud(layout, n);
    std::vector<Eigen::Vector3d> as_doubles;
    std::vector<Eigen::Vector3f> as_floats;
    const Eigen::Vector3d viewpoint(coord(rng), coord(rng), coord(rng));
    double expected = inf;
    for (std::size_t i = 0; i < n; ++i) {
      Eigen::Vector3d p(coord(rng), coord(rng), coord(rng));
      if (i % 5 == 1) p.x() = nan;
      if (i % 7 == 3) p.z() = -inf;
      for (int a = 0; a < 3; ++a) hpds::writeFromDouble(cloud.record(i), *layout.find(std::string(1, char('x' + a))), p[a]);
      as_doubles.push_back(p);
      as_floats.push_back(p.cast<float>());
      if (p.allFinite()) expected = std::min(expected, (p - viewpoint).norm());
    }
    EXPECT_DOUBLE_EQ(hpds::nearestPointDistance(cloud, viewpoint), expected) << "trial " << trial;
    EXPECT_DOUBLE_EQ(hpds::nearestPointDistance(as_doubles, viewpoint), expected) << "trial " << trial;
    if (std::isfinite(expected))
      EXPECT_NEAR(hpds::nearestPointDistance(as_floats, viewpoint), expected, 1e-3) << "trial " << trial;
    else
      EXPECT_EQ(hpds::nearestPointDistance(as_floats, viewpoint), inf);
  }
}

TEST(FarViewpoint, FarMeansFiniteAndBeyondAKilometre) {
  EXPECT_FALSE(hpds::isFarViewpoint(0.0));
  EXPECT_FALSE(hpds::isFarViewpoint(hpds::kFarViewpoint));
  EXPECT_TRUE(hpds::isFarViewpoint(hpds::kFarViewpoint + 1.0));
  // No finite point, or no x y z at all: nothing to say about the viewpoint.
  EXPECT_FALSE(hpds::isFarViewpoint(std::numeric_limits<double>::infinity()));
  PointLayout no_xyz;
  no_xyz.append("intensity", FieldType::Float32);
  EXPECT_EQ(hpds::nearestPointDistance(PointBuffer(no_xyz, 3), Eigen::Vector3d::Zero()),
            std::numeric_limits<double>::infinity());
  EXPECT_EQ(hpds::nearestPointDistance(std::vector<Eigen::Vector3d>{}, Eigen::Vector3d::Zero()),
            std::numeric_limits<double>::infinity());
  // A survey in UTM coordinates with the viewpoint left at the origin.
  const std::vector<Eigen::Vector3d> utm = {{500000.0, 5400000.0, 300.0}, {500010.0, 5400003.0, 301.0}};
  EXPECT_TRUE(hpds::isFarViewpoint(hpds::nearestPointDistance(utm, Eigen::Vector3d::Zero())));
  EXPECT_FALSE(hpds::isFarViewpoint(hpds::nearestPointDistance(utm, Eigen::Vector3d(500005.0, 5400000.0, 302.0))));
}

}  // namespace
