// The registration benchmark's registrations: PCL's point-to-plane ICP and GeneralizedIterativeClosestPoint, with one
// set of settings for every data set, level and method.
//
// Contract
// - register*(source, target, start) returns the transform mapping source into target found from `start`, and the
//   seconds spent in PCL's align() (for GICP with k-NN covariances that includes computing them).
// - Point-to-plane ICP needs target normals: given ones (hpds) or PCL NormalEstimation of the k nearest points of the
//   target cloud (settings.knn). Target points without a normal are left out of the target, for every method; so
//   are hpds samples whose neighbourhood pins no normal (plane_like 0: the identity covariance).
// - GICP takes given covariances (hpds) or computes PCL's own from the k nearest points (settings.knn, PCL's
//   default 20, regularised by PCL to (1, 1, 0.001)). A sample without a given covariance gets the identity
//   (no surface known: a weak point-to-point term) and is counted in `fallback`.
#pragma once

#include <Eigen/Geometry>
#include <vector>

#include "RegistrationSamplers.hpp"

namespace hpds::bench {

struct RegistrationSettings {
  double max_correspondence = 1.0;  ///< [m] pairs farther apart are ignored
  int max_iterations = 50;
  double transformation_epsilon = 1e-6;  ///< ICP: stop when the squared translation step is below this [m^2]
  int knn = 20;                          ///< neighbours of the k-NN normals and covariances
};

struct RegistrationResult {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  double seconds = 0.0;
  std::size_t fallback = 0;  ///< GICP: samples that had no given covariance
};

enum class CovarianceSource { Given, Knn };

[[nodiscard]] RegistrationResult registerPointToPlane(const SampledCloud &source, const SampledCloud &target,
                                                      const Eigen::Isometry3d &start,
                                                      const RegistrationSettings &settings);

[[nodiscard]] RegistrationResult registerGicp(const SampledCloud &source, const SampledCloud &target,
                                              const Eigen::Isometry3d &start, CovarianceSource covariances,
                                              const RegistrationSettings &settings);

}  // namespace hpds::bench
