// GICP covariances from the hierarchy's normal neighbourhoods (SampleCovariance.hpp): the regularisation's
// properties, the covariance of every sample against a brute-force neighbourhood PCA (plain, finer-level and grown
// neighbourhoods), and the cov_* fields of the output cloud.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/normals/SampleCovariance.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "HierarchyTestSupport.hpp"
#include "hpds/sampling/Hierarchy.hpp"

namespace hpds {
namespace {

Eigen::Matrix3d full(const SampleCovariance &c) {
  Eigen::Matrix3d m;
  m << c.cov[0], c.cov[1], c.cov[2], c.cov[1], c.cov[3], c.cov[4], c.cov[2], c.cov[4], c.cov[5];
  return m;
}

SampleNormal invalidNormalForTest() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  return SampleNormal{{nan, nan, nan}, nan, false};
}

SampleNormal normalOf(const Eigen::Vector3d &n) {
  return SampleNormal{{static_cast<float>(n.x()), static_cast<float>(n.y()), static_cast<float>(n.z())}, 0.0f, true};
}

TEST(SampleCovariance, PlaneRegularisationIsSymmetricPositiveDefiniteWithTheNormalAsSmallAxis) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Eigen::Vector3d> normals = {Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(),
                                          Eigen::Vector3d(1.0, 1e-7, 0.0).normalized()};
  for (int i = 0; i < 200; ++i) normals.push_back(Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized());
  for (const double eps : {1e-4, 1e-3, 0.1, 1.0}) {
    for (const Eigen::Vector3d &n : normals) {
      const SampleCovariance c = planeCovariance(normalOf(n), eps);
      ASSERT_TRUE(c.valid);
      const Eigen::Matrix3d m = full(c);
      // Stored as the upper triangle, so symmetric by construction; what can fail is definiteness and the axes.
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(m);
      EXPECT_GT(es.eigenvalues()(0), 0.0) << "not positive definite, eps " << eps;
      EXPECT_NEAR(es.eigenvalues()(0), eps, 2e-6) << n.transpose();
      EXPECT_NEAR(es.eigenvalues()(1), 1.0, 2e-6);
      EXPECT_NEAR(es.eigenvalues()(2), 1.0, 2e-6);
      // The normal is an eigenvector of eps (for eps = 1 every direction is).
      EXPECT_LT((m * n - eps * n).norm(), 2e-6) << n.transpose();
      if (eps < 0.5) {
        EXPECT_GT(std::abs(es.eigenvectors().col(0).dot(n)), 1.0 - 1e-9);
      }
      // The sign of the normal plays no role.
      const SampleCovariance flipped = planeCovariance(normalOf(-n), eps);
      for (int k = 0; k < 6; ++k) EXPECT_EQ(c.cov[k], flipped.cov[k]);
    }
  }
}

TEST(SampleCovariance, InvalidOrNonFiniteNormalsGiveNaN) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const SampleNormal &n : {SampleNormal{{nan, nan, nan}, nan, false}, SampleNormal{{0.f, 0.f, 1.f}, 0.f, false},
                                SampleNormal{{0.f, 0.f, 0.f}, 0.f, true}, SampleNormal{{nan, 0.f, 1.f}, 0.f, true},
                                SampleNormal{{INFINITY, 0.f, 0.f}, 0.f, true}}) {
    const SampleCovariance c = planeCovariance(n, 1e-3);
    EXPECT_FALSE(c.valid);
    for (float v : c.cov) EXPECT_TRUE(std::isnan(v));
  }
  EXPECT_TRUE(planeCovariances({}, 1e-3).empty());
}

// ------------------------------------------------------------------------------------------------ brute force

Hierarchy build(const std::vector<double> &xyz, int max_depth, unsigned seed) {
  return test::buildShuffled(xyz, 1.0, max_depth, seed, {0.0, 0.0, 5.0});
}

struct BrutePca {
  Eigen::Vector3d values = Eigen::Vector3d::Zero();
  Eigen::Matrix3d vectors = Eigen::Matrix3d::Identity();
  std::size_t count = 0;
};

/// PCA (Eigen's iterative solver) of every sample of levels 0..finest strictly within rho of sample q.
BrutePca brutePca(const Hierarchy &h, SampleId q, int finest, double rho) {
  const Eigen::Vector3d c(h.position(q));
  std::vector<Eigen::Vector3d> nb;
  for (SampleId id : h.samplesUpTo(finest)) {
    const Eigen::Vector3d p(h.position(id));
    if ((p - c).squaredNorm() < rho * rho) nb.push_back(p - c);
  }
  BrutePca out;
  out.count = nb.size();
  if (nb.size() < 3) return out;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto &p : nb) mean += p;
  mean /= static_cast<double>(nb.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto &p : nb) cov += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov / static_cast<double>(nb.size()));
  out.values = es.eigenvalues().cwiseMax(0.0);
  out.vectors = es.eigenvectors();
  return out;
}

/// Where a line's grown ball is not flat: the plane through the line (principal axis of the ball of radius rho / 2)
/// at the angle about it that most points of the ball off the line fall within 10 degrees of (36 bins of the
/// diamond angle, the best two adjacent), refitted to the points within 4 % of rho of it; kept if 3 or more of those
/// lie off the line on each side and their PCA passes the growth's tests. Of windows tied on votes, the flattest
/// such plane (smallest l0). RefinedNormals.cpp's planeThroughLine, by brute force over the samples.
bool brutePlaneThroughLine(const Hierarchy &h, SampleId q, int finest, double rho, const NormalParams &p,
                           BrutePca &out) {
  const Eigen::Vector3d c(h.position(q));
  std::vector<Eigen::Vector3d> ball, inner;
  for (SampleId id : h.samplesUpTo(finest)) {
    const Eigen::Vector3d d = Eigen::Vector3d(h.position(id)) - c;
    if (d.squaredNorm() < rho * rho) ball.push_back(d);
    if (d.squaredNorm() < rho * rho / 4.0) inner.push_back(d);
  }
  if (inner.size() < 2) return false;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto &d : inner) mean += d / static_cast<double>(inner.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto &d : inner) cov += (d - mean) * (d - mean).transpose() / static_cast<double>(inner.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  const Eigen::Vector3d line = es.eigenvectors().col(2), u = line.unitOrthogonal(), w = line.cross(u);
  const double off = std::max(3.0 * std::sqrt(std::max(0.0, es.eigenvalues()(1))), 0.1 * rho);
  auto diamond = [](double a, double b) {  // the angle of (a, b) modulo pi, as 0..2
    if (b < 0.0 || (b == 0.0 && a < 0.0)) a = -a, b = -b;
    return a >= 0.0 ? b / (a + b) : 1.0 - a / (b - a);
  };
  std::array<int, 36> bins{};
  for (const auto &d : ball) {
    const Eigen::Vector3d e = d - mean;
    const double a = e.dot(u), b = e.dot(w);
    if (std::hypot(a, b) >= off) ++bins[std::min(35, static_cast<int>(diamond(a, b) * 18.0))];
  }
  auto window = [&](int k) { return bins[k] + bins[(k + 1) % 36]; };
  int most = 0;
  for (int k = 0; k < 36; ++k) most = std::max(most, window(k));
  if (most < 6) return false;
  bool found = false;
  for (int k = 0; k < 36; ++k) {
    if (window(k) != most) continue;
    const double pd = (k + 1) / 18.0;  // back from the diamond angle to a direction in u, w
    const Eigen::Vector3d along = ((1.0 - pd) * u + (pd <= 1.0 ? pd : 2.0 - pd) * w).normalized();
    const Eigen::Vector3d normal = line.cross(along).normalized();
    std::vector<Eigen::Vector3d> plane;
    int above = 0, below = 0;
    for (const auto &d : ball) {
      const Eigen::Vector3d e = d - mean;
      if (std::abs(e.dot(normal)) > 2.0 * p.max_plane_rms * rho) continue;
      plane.push_back(d);
      if (std::hypot(e.dot(u), e.dot(w)) >= off) (e.dot(along) > 0.0 ? above : below) += 1;
    }
    if (above < 3 || below < 3 || static_cast<int>(plane.size()) < p.min_neighbors) continue;
    Eigen::Vector3d pm = Eigen::Vector3d::Zero();
    for (const auto &d : plane) pm += d / static_cast<double>(plane.size());
    Eigen::Matrix3d pc = Eigen::Matrix3d::Zero();
    for (const auto &d : plane) pc += (d - pm) * (d - pm).transpose() / static_cast<double>(plane.size());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ps(pc);
    const Eigen::Vector3d l = ps.eigenvalues().cwiseMax(0.0);
    if (!(l(1) > 1e-9 * l.sum()) || l(0) > p.max_plane_rms * p.max_plane_rms * rho * rho ||
        l(1) < p.line_ratio * l(2))
      continue;
    if (found && !(l(0) < out.values(0))) continue;
    out.values = l;
    out.vectors = ps.eigenvectors();
    out.count = plane.size();
    found = true;
  }
  return found;
}

/// The neighbourhood NormalEstimator.hpp's contract picks for a fixed radius, brute force: levels 0..level+offset
/// inside the footprint, doubled while line-like or too small up to max_growth, a grown one kept only if flat and
/// no longer line-like. Returns false where no neighbourhood qualifies (invalid normal).
bool bruteNeighbourhood(const Hierarchy &h, SampleId q, const NormalParams &p, BrutePca &chosen) {
  const int finest = std::min(p.level + p.neighborhood_level_offset, h.maxDepth());
  const double limit = std::min(2.0 * h.cellSize(), p.radius * p.max_growth);
  bool have = false;
  for (double rho = p.radius;; rho *= 2.0) {
    const BrutePca pca = brutePca(h, q, finest, rho);
    bool settled = false;
    if (static_cast<int>(pca.count) >= p.min_neighbors) {
      const Eigen::Vector3d &l = pca.values;
      const bool valid = l(1) > 1e-9 * l.sum();
      const bool flat = l(0) <= p.max_plane_rms * p.max_plane_rms * rho * rho;
      const bool not_line = l(1) >= p.line_ratio * l(2);
      const bool had_line = have && chosen.values(1) < p.line_ratio * chosen.values(2);
      if (valid && (!have || (flat && not_line))) {
        chosen = pca;
        have = true;
        if (not_line) return true;
      }
      settled = have && !flat;
      if (settled && had_line && brutePlaneThroughLine(h, q, finest, rho, p, chosen)) return true;
    }
    if (settled || rho * 2.0 > limit * (1.0 + 1e-12)) return have;
  }
}

/// What the brute-force neighbourhoods give per sample.
struct Compared {
  std::size_t planes = 0, lines = 0;
};

/// sampleCovariances(estimateNormals(...)) of `ids` against the brute-force neighbourhoods: their PCA's eigenvalues,
/// and the covariance U diag(eps, 1, 1) U^T of a plane-like one or the identity of a line-like one.
Compared expectCovariancesMatchBruteForce(const Hierarchy &h, const std::vector<SampleId> &ids, const NormalParams &p,
                                          double eps, double ratio = HpdsConfig{}.normals.covariance_line_ratio) {
  std::vector<LocalPca> neighbourhoods;
  const std::vector<SampleNormal> normals = estimateNormals(h, ids, p, &neighbourhoods);
  const std::vector<SampleCovariance> covs = sampleCovariances(normals, neighbourhoods, eps, ratio);
  EXPECT_EQ(neighbourhoods.size(), ids.size());
  Compared compared;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    BrutePca pca;
    const bool have = bruteNeighbourhood(h, ids[i], p, pca);
    EXPECT_EQ(covs[i].valid, have) << "sample " << i;
    if (!covs[i].valid) {
      EXPECT_TRUE(full(covs[i]).isApprox(Eigen::Matrix3d::Identity())) << "sample " << i;
    }
    if (!have || !covs[i].valid) continue;
    const double trace = pca.values.sum();
    EXPECT_NEAR(neighbourhoods[i].l0, pca.values(0), 1e-9 * trace) << "sample " << i;
    EXPECT_NEAR(neighbourhoods[i].l1, pca.values(1), 1e-9 * trace) << "sample " << i;
    EXPECT_NEAR(neighbourhoods[i].l2, pca.values(2), 1e-9 * trace) << "sample " << i;
    Eigen::Matrix3d expected;
    if (pca.values(1) < ratio * pca.values(2)) {
      // A line's neighbourhood gets the identity (borderline cases, within round-off of the ratio, are skipped).
      if (std::abs(pca.values(1) - ratio * pca.values(2)) < 1e-9 * trace) continue;
      expected = Eigen::Matrix3d::Identity();
      ++compared.lines;
    } else {
      // Near-equal smallest eigenvalues leave the normal (and so the covariance) to round-off: not comparable.
      if (pca.values(1) - pca.values(0) < 1e-6 * trace) continue;
      expected = pca.vectors * Eigen::Vector3d(eps, 1.0, 1.0).asDiagonal() * pca.vectors.transpose();
      ++compared.planes;
    }
    EXPECT_LT((full(covs[i]) - expected).cwiseAbs().maxCoeff(), 1e-5) << "sample " << i << "\n" << expected;
  }
  return compared;
}

/// A gently curved noisy surface, with parallel scan lines 0.5 m apart on one half (line-like neighbourhoods).
std::vector<double> curvedSurfaceWithScanLines() {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0.0, 2.0);
  std::normal_distribution<double> noise(0.0, 0.004);
  auto z = [](double x, double y) { return 0.15 * std::sin(1.3 * x) + 0.1 * std::cos(0.9 * y); };
  std::vector<double> xyz;
  for (int i = 0; i < 1500; ++i) {
    const double x = u(rng), y = u(rng);
    xyz.insert(xyz.end(), {x, y, z(x, y) + noise(rng)});
  }
  for (int line = 0; line < 4; ++line)
    for (int i = 0; i < 300; ++i) {
      const double x = 2.2 + i * 0.005, y = 0.2 + 0.5 * line + noise(rng);
      xyz.insert(xyz.end(), {x, y, z(x, y) + noise(rng)});
    }
  return xyz;
}

TEST(SampleCovariance, MatchesBruteForceNeighbourhoodPca) {
  const Hierarchy h = build(curvedSurfaceWithScanLines(), 6, 3);
  const int level = 3;  // r_3 = 0.108 m
  const std::vector<SampleId> ids = h.samplesUpTo(level);
  ASSERT_GT(ids.size(), 100u);
  NormalParams p;
  p.level = level;
  p.radius = 2.5 * h.radius(level);
  p.min_neighbors = 5;
  // Plain estimator (levels 0..L), then finer levels inside the footprint: the scan lines stay line-like.
  for (const int offset : {0, 2}) {
    p.neighborhood_level_offset = offset;
    const Compared c = expectCovariancesMatchBruteForce(h, ids, p, 1e-3);
    EXPECT_GT(c.planes, ids.size() / 2) << "offset " << offset;
    EXPECT_GT(c.lines, 10u) << "offset " << offset;
  }
  // Ratio 0: every neighbourhood is a plane.
  EXPECT_EQ(expectCovariancesMatchBruteForce(h, ids, p, 1e-3, 0.0).lines, 0u);
  // Growth spans the scan lines: fewer line-like neighbourhoods remain.
  p.max_growth = 8.0;
  const Compared fixed = expectCovariancesMatchBruteForce(h, ids, [&] { NormalParams q = p; q.max_growth = 1.0; return q; }(), 0.01);
  const Compared grown = expectCovariancesMatchBruteForce(h, ids, p, 0.01);
  EXPECT_GT(grown.planes, ids.size() / 2);
  EXPECT_LT(grown.lines, fixed.lines);
}

TEST(SampleCovariance, LineLikeNeighbourhoodsGetTheIdentityAndSizesMustMatch) {
  const SampleNormal up = normalOf(Eigen::Vector3d::UnitZ());
  LocalPca plane, line;
  plane.l0 = 1e-6, plane.l1 = 0.2, plane.l2 = 0.3, plane.valid = true;
  line.l0 = 1e-6, line.l1 = 0.001, line.l2 = 0.3, line.valid = true;
  const auto covs = sampleCovariances({up, up, invalidNormalForTest()}, {plane, line, line}, 1e-3, 0.05);
  ASSERT_EQ(covs.size(), 3u);
  EXPECT_TRUE(covs[0].valid && covs[1].valid);
  EXPECT_NEAR(covs[0].cov[5], 1e-3, 1e-7);  // the plane: epsilon along the normal
  EXPECT_TRUE(full(covs[1]).isApprox(Eigen::Matrix3d::Identity()));
  // No normal: the identity, line or not (a NaN made PCL's GICP return a NaN transform said to have converged).
  EXPECT_FALSE(covs[2].valid);
  EXPECT_TRUE(full(covs[2]).isApprox(Eigen::Matrix3d::Identity()));
  EXPECT_THROW((void)sampleCovariances({up}, {}, 1e-3, 0.05), std::invalid_argument);
}

TEST(SampleCovariance, PlaneNormalsReplaceTheNormalOnlyWhereThereIsAPlane) {
  const SampleNormal up = normalOf(Eigen::Vector3d::UnitZ()), side = normalOf(Eigen::Vector3d::UnitX());
  LocalPca plane, line;
  plane.l0 = 1e-6, plane.l1 = 0.2, plane.l2 = 0.3, plane.valid = true;
  line.l0 = 1e-6, line.l1 = 0.001, line.l2 = 0.3, line.valid = true;
  const SampleNormal none = invalidNormalForTest();
  // plane + valid plane normal: its plane; plane + invalid plane normal: the normal's; line or no normal: identity.
  const auto covs = sampleCovariances({up, up, up, none}, {plane, plane, line, plane}, {side, none, side, side}, 1e-3,
                                      0.05);
  ASSERT_EQ(covs.size(), 4u);
  EXPECT_TRUE((full(covs[0]) * Eigen::Vector3d::UnitX() - 1e-3 * Eigen::Vector3d::UnitX()).norm() < 1e-6);
  EXPECT_TRUE((full(covs[1]) * Eigen::Vector3d::UnitZ() - 1e-3 * Eigen::Vector3d::UnitZ()).norm() < 1e-6);
  EXPECT_TRUE(full(covs[2]).isApprox(Eigen::Matrix3d::Identity()));
  EXPECT_FALSE(covs[3].valid);
  EXPECT_TRUE(full(covs[3]).isApprox(Eigen::Matrix3d::Identity()));
  EXPECT_THROW((void)sampleCovariances({up}, {plane}, {}, 1e-3, 0.05), std::invalid_argument);
}

// ------------------------------------------------------------------------------------------------ output cloud

TEST(SampleCovariance, OutputCloudCarriesCovFieldsOnlyWhenAsked) {
  SyntheticLidarConfig lc;
  lc.beams = 16;
  lc.azimuth_steps = 600;
  lc.frames = 1;
  const SyntheticLidar lidar(lc);
  HpdsConfig c;
  c.output.level = 4;
  c.normals.enabled = true;
  c.normals.covariances = true;
  c.normals.covariance_epsilon = 0.002;
  const char *names[6] = {"cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"};
  // covariance_k 0: the plane is the written normal's. The default: the PCA normal of the covariance_k nearest
  // output samples (the oracle: estimateNormals with covarianceNormalParams), on the same samples, and the same
  // samples get the identity (the output normal's neighbourhood decides that).
  std::vector<bool> identity_at_k0;
  for (const int covariance_k : {0, HpdsConfig{}.normals.covariance_k}) {
    SCOPED_TRACE("covariance_k " + std::to_string(covariance_k));
    c.normals.covariance_k = covariance_k;
    Pipeline p(c);
    p.addFrame(lidar.frame(0).frame);
    const std::vector<SampleId> ids = p.outputSamples();
    const PointBuffer cloud = p.makeCloud(ids, false);
    std::vector<SampleNormal> planes;
    if (covariance_k > 0) planes = estimateNormals(p.hierarchy(), ids, covarianceNormalParams(c, p.outputLevel()));
    const PointLayout &l = cloud.layout();
    const PointField *f[6];
    for (int k = 0; k < 6; ++k) {
      f[k] = l.find(names[k]);
      ASSERT_NE(f[k], nullptr) << names[k];
      EXPECT_EQ(f[k]->type, FieldType::Float32);
    }
    const PointField *nx = l.find("normal_x"), *ny = l.find("normal_y"), *nz = l.find("normal_z");
    ASSERT_TRUE(nx && ny && nz);
    ASSERT_EQ(cloud.size(), ids.size());
    std::size_t valid = 0, invalid = 0, lines = 0, apart = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const std::uint8_t *r = cloud.record(i);
      const Eigen::Vector3d n(readAsDouble(r, *nx), readAsDouble(r, *ny), readAsDouble(r, *nz));
      Eigen::Matrix3d m;
      m << readAsDouble(r, *f[0]), readAsDouble(r, *f[1]), readAsDouble(r, *f[2]), readAsDouble(r, *f[1]),
          readAsDouble(r, *f[3]), readAsDouble(r, *f[4]), readAsDouble(r, *f[2]), readAsDouble(r, *f[4]),
          readAsDouble(r, *f[5]);
      const bool identity = n.allFinite() && m.isApprox(Eigen::Matrix3d::Identity());
      if (covariance_k == 0) {
        identity_at_k0.push_back(identity);
      } else {
        EXPECT_EQ(identity, identity_at_k0.at(i)) << "sample " << i;
      }
      if (!n.allFinite()) {
        ++invalid;
        EXPECT_TRUE(m.isApprox(Eigen::Matrix3d::Identity())) << "sample " << i;  // never NaN: GICP takes it
        continue;
      }
      ++valid;
      if (identity) {
        ++lines;  // a neighbourhood on one scan line
        continue;
      }
      Eigen::Vector3d axis = n;  // the plane's normal: the covariance's small axis
      if (covariance_k > 0 && planes[i].valid) {
        axis = Eigen::Vector3d(planes[i].normal[0], planes[i].normal[1], planes[i].normal[2]);
        apart += std::abs(axis.normalized().dot(n.normalized())) < std::cos(1.0 * M_PI / 180.0) ? 1 : 0;
      }
      EXPECT_LT((m * axis - 0.002 * axis).norm(), 1e-5) << "sample " << i;
      EXPECT_NEAR(m.trace(), 2.002, 1e-5);
    }
    EXPECT_GT(valid - lines, 100u);
    EXPECT_LT(lines, valid / 2);
    EXPECT_EQ(invalid + valid, cloud.size());
    if (covariance_k > 0) {
      EXPECT_GT(apart, 20u);  // the two neighbourhoods do give different planes
    }
  }

  c.normals.covariances = false;
  Pipeline plain(c);
  plain.addFrame(lidar.frame(0).frame);
  const PointBuffer without = plain.makeCloud(plain.outputSamples(), false);
  for (const char *name : names) EXPECT_EQ(without.layout().find(name), nullptr) << name;
  ASSERT_GT(without.size(), 0u);
}

}  // namespace
}  // namespace hpds
