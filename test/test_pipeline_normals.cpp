// The pipeline's normals: against a brute-force PCA and oriented toward the sensor, and against the ground truth
// of a planar synthetic scene.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <vector>

#include "PipelineTestSupport.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {
namespace {

using test::smallLidar;

double angleDeg(const Eigen::Vector3d &a, const Eigen::Vector3d &b) {
  return std::acos(std::clamp(std::abs(a.normalized().dot(b.normalized())), 0.0, 1.0)) * 180.0 / M_PI;
}

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

}  // namespace
}  // namespace hpds
