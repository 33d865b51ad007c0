// Building blocks of the registration benchmark (bench/registration): pose errors, their summaries, perturbed starts,
// and the equal-count bisection that sizes the grid baselines.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "hpds/eval/EqualCount.hpp"
#include "hpds/eval/GridSubsampling.hpp"
#include "hpds/eval/PoseError.hpp"

namespace hpds {
namespace {

constexpr double kDeg = 0.017453292519943295;

Eigen::Isometry3d pose(double tx, double ty, double tz, const Eigen::Vector3d &axis, double deg) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  p.linear() = Eigen::AngleAxisd(deg * kDeg, axis.normalized()).toRotationMatrix();
  p.translation() = Eigen::Vector3d(tx, ty, tz);
  return p;
}

TEST(PoseError, ResidualMotionInTheSourceFrame) {
  const Eigen::Isometry3d truth = pose(0.5, 0.1, -0.01, Eigen::Vector3d(0.1, 0.2, 1.0), 0.6);
  EXPECT_NEAR(poseError(truth, truth).translation, 0.0, 1e-12);
  EXPECT_NEAR(poseError(truth, truth).rotation_deg, 0.0, 1e-9);
  // estimate = truth * delta: the error is delta's, whatever truth is.
  for (const double deg : {1e-5, 0.3, 1.0, 45.0, 179.0, 179.9999}) {
    const Eigen::Isometry3d delta = pose(0.03, -0.04, 0.0, Eigen::Vector3d(1.0, -2.0, 0.5), deg);
    const PoseError e = poseError(truth * delta, truth);
    EXPECT_NEAR(e.translation, 0.05, 1e-12) << deg;
    EXPECT_NEAR(e.rotation_deg, deg, 1e-9 * std::max(1.0, deg)) << deg;
  }
  // A pure rotation of the estimate about the target origin moves the source origin too: the translation error is
  // that of truth^-1 * estimate, not of the translations alone.
  const Eigen::Isometry3d turned = pose(0, 0, 0, Eigen::Vector3d::UnitZ(), 90.0) * truth;
  EXPECT_NEAR(poseError(turned, truth).rotation_deg, 90.0, 1e-9);
  EXPECT_NEAR(poseError(turned, truth).translation,
              (truth.inverse() * turned).translation().norm(), 1e-12);
  EXPECT_GT(poseError(turned, truth).translation, 0.1);
}

TEST(PoseError, FailureLimitsAndNonFiniteEstimates) {
  EXPECT_FALSE(isFailure({0.2, 1.0}));  // the limits themselves pass
  EXPECT_TRUE(isFailure({0.2001, 0.0}));
  EXPECT_TRUE(isFailure({0.0, 1.0001}));
  EXPECT_TRUE(isFailure({NAN, 0.0}));
  EXPECT_FALSE(isFailure({0.5, 3.0}, FailureLimits{1.0, 5.0}));
  Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
  bad.translation().x() = std::numeric_limits<double>::quiet_NaN();
  const PoseError e = poseError(bad, Eigen::Isometry3d::Identity());
  EXPECT_TRUE(std::isinf(e.translation));
  EXPECT_TRUE(isFailure(e));
}

TEST(PoseError, SummaryMatchesSortedStatistics) {
  std::mt19937_64 rng(4);
  std::exponential_distribution<double> t(10.0), r(2.0);
  for (const std::size_t n : {1u, 2u, 7u, 100u, 101u}) {
    std::vector<PoseError> errors;
    for (std::size_t i = 0; i < n; ++i) errors.push_back({t(rng), r(rng)});
    const ErrorSummary s = summarizeErrors(errors);
    std::vector<double> ts, rs;
    double st = 0, sr = 0;
    std::size_t fails = 0;
    for (const auto &e : errors) {
      ts.push_back(e.translation), rs.push_back(e.rotation_deg);
      st += e.translation, sr += e.rotation_deg;
      fails += (e.translation > 0.2 || e.rotation_deg > 1.0) ? 1 : 0;
    }
    std::sort(ts.begin(), ts.end());
    std::sort(rs.begin(), rs.end());
    auto med = [](const std::vector<double> &v) {
      return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
    };
    EXPECT_EQ(s.count, n);
    EXPECT_DOUBLE_EQ(s.median_translation, med(ts)) << n;
    EXPECT_DOUBLE_EQ(s.median_rotation_deg, med(rs)) << n;
    EXPECT_NEAR(s.mean_translation, st / n, 1e-12);
    EXPECT_NEAR(s.mean_rotation_deg, sr / n, 1e-12);
    EXPECT_DOUBLE_EQ(s.failure_rate, static_cast<double>(fails) / n);
  }
  const ErrorSummary empty = summarizeErrors({});
  EXPECT_EQ(empty.count, 0u);
  EXPECT_TRUE(std::isnan(empty.median_translation) && std::isnan(empty.failure_rate));
  // A failed (non-finite) registration is never hidden by the statistics.
  EXPECT_TRUE(std::isinf(summarizeErrors({{0.01, 0.1}, {INFINITY, INFINITY}}).mean_translation));
}

TEST(PoseError, PerturbedStartsAreAtTheGivenDistanceAndDeterministic) {
  const Eigen::Isometry3d truth = pose(1.0, 0.2, 0.0, Eigen::Vector3d::UnitZ(), 2.0);
  std::vector<Eigen::Vector3d> shifts;
  for (std::uint64_t seed = 0; seed < 50; ++seed) {
    const Eigen::Isometry3d start = perturbedPose(truth, 0.5, 5.0, seed);
    const PoseError e = poseError(start, truth);
    EXPECT_NEAR(e.translation, 0.5, 1e-12);
    EXPECT_NEAR(e.rotation_deg, 5.0, 1e-9);
    EXPECT_TRUE(perturbedPose(truth, 0.5, 5.0, seed).isApprox(start, 0.0));
    shifts.push_back((truth.inverse() * start).translation());
  }
  // Directions spread over the sphere: their mean is far shorter than one.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto &s : shifts) mean += s / 0.5;
  EXPECT_LT((mean / 50.0).norm(), 0.4);
  EXPECT_FALSE(perturbedPose(truth, 0.5, 5.0, 1).isApprox(perturbedPose(truth, 0.5, 5.0, 2)));
}

TEST(EqualCount, BisectionReachesTheToleranceOnAVoxelGrid) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  std::normal_distribution<double> g(0.0, 0.02);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 40000; ++i) pts.emplace_back(u(rng), u(rng), 0.1 * std::sin(u(rng)) + g(rng));
  auto count = [&](double cell) { return voxelCentroids(pts, cell).size(); };
  for (const std::size_t target : {300u, 2000u, 9000u}) {
    const CountMatch m = matchCellToCount(count, target, 0.03, 1e-3, 10.0);
    ASSERT_TRUE(m.within) << target << " got " << m.count;
    EXPECT_EQ(m.count, count(m.cell));
    EXPECT_LE(std::abs(double(m.count) - double(target)), 0.03 * target);
    EXPECT_LE(m.probes, 40);
  }
}

TEST(EqualCount, UnreachableTargetsReturnTheBestProbeMarkedMissed) {
  // A count that jumps from 100 to 200 at cell 1: 150 +- 3 % cannot be met; the best probe is one of the two sides.
  auto step = [](double cell) -> std::size_t { return cell < 1.0 ? 200 : 100; };
  const CountMatch m = matchCellToCount(step, 150, 0.03, 0.01, 100.0, 20);
  EXPECT_FALSE(m.within);
  EXPECT_EQ(m.probes, 20);
  EXPECT_TRUE(m.count == 100 || m.count == 200);
  // A smooth count: n(c) = 1e6 / c^3 is matched exactly enough in a few probes, and tolerance 0 keeps probing.
  auto cube = [](double cell) { return static_cast<std::size_t>(1e6 / (cell * cell * cell)); };
  const CountMatch c = matchCellToCount(cube, 5000, 0.03, 0.1, 100.0);
  EXPECT_TRUE(c.within);
  EXPECT_LT(c.probes, 15);
  EXPECT_NEAR(c.cell, std::cbrt(1e6 / 5000.0), 0.05 * std::cbrt(1e6 / 5000.0));
  EXPECT_THROW((void)matchCellToCount(cube, 10, 0.03, 0.0, 1.0), std::invalid_argument);
  EXPECT_THROW((void)matchCellToCount(cube, 10, 0.03, 2.0, 1.0), std::invalid_argument);
  EXPECT_THROW((void)matchCellToCount(cube, 10, -0.1, 0.1, 1.0), std::invalid_argument);
  EXPECT_THROW((void)matchCellToCount(cube, 10, 0.03, 0.1, 1.0, 0), std::invalid_argument);
}

}  // namespace
}  // namespace hpds
