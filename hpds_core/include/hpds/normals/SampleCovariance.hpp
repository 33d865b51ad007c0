// Per-sample covariances for generalized ICP (GICP), from the normal estimator's neighbourhoods.
//
// Contract
// - GICP (Segal, Haehnel and Thrun 2009) models every point as drawn from a locally planar surface and regularises
//   the PCA of its neighbourhood to eigenvalues (epsilon, 1, 1), the smallest along the normal: the "plane"
//   regularisation PCL's GeneralizedIterativeClosestPoint applies to its own k-NN covariances. Eigenvalues
//   (epsilon, 1, 1) keep only the neighbourhood's smallest-eigenvalue axis, so the covariance is the normal's:
//   C = I - (1 - epsilon) n n^T. What sets it apart from a k-NN covariance is the neighbourhood the normal came from
//   (NormalEstimator.hpp: finer levels inside the footprint, grown past single scan lines).
// - Dimensionless (unit variance in the plane), as GICP expects; the scale of all covariances of a registration
//   drops out of its minimiser. Symmetric, positive definite for epsilon in (0, 1], eigenvalues (epsilon, 1, 1) with
//   the unit normal as the eigenvector of epsilon; the normal's sign plays no role.
// - A neighbourhood that is line-like (l1 < line_ratio * l2: one scan line that growth could not widen, or a strip
//   narrow against its range noise) does not pin a normal: across a line any direction fits, and the plane through
//   one scan line and its range noise contains the ray, so it can stand anywhere up to 90 degrees off the surface.
//   Such a sample gets the identity (unit variance in every direction: a weak point-to-point term next to the
//   planes' 1 / epsilon) instead of a confident plane in a wrong direction, which traps GICP in false minima
//   (docs/quality.md, Registration).
// - By default (normals.covariance_k = 30) the plane's normal is not the output normal but the PCA normal of the
//   30 nearest output samples, where the output normal's own neighbourhood is not line-like (estimateCovariances).
// - Every sample gets a covariance GICP can take: where the normal could not be estimated (too few neighbours) no
//   plane is known either, and the sample gets the identity, as on a scan line, with `valid` false. A NaN there
//   (as PCL marks a missing normal) made PCL's GICP return a NaN transform that said it converged, or abort in its
//   k-d tree (found in a user trial; 80 of 19 282 samples on the HDL-32 pair at the defaults).
// - Stored as the six upper-triangle entries xx xy xz yy yz zz (the output fields cov_xx ... cov_zz).
#pragma once

#include <vector>

#include "hpds/normals/LocalPca.hpp"
#include "hpds/normals/NormalEstimator.hpp"

namespace hpds {

struct SampleCovariance {
  float cov[6];  ///< xx xy xz yy yz zz, dimensionless
  bool valid;    ///< false: from no normal (sampleCovariances: the identity; planeCovariance: NaN)
};

/// The plane-regularised covariance of a sample with this normal (see contract); epsilon in (0, 1]. NaN in all six
/// entries, `valid` false, for an invalid normal: a building block; sampleCovariances gives those the identity.
[[nodiscard]] SampleCovariance planeCovariance(const SampleNormal &normal, double epsilon);

/// planeCovariance of every normal, same order.
[[nodiscard]] std::vector<SampleCovariance> planeCovariances(const std::vector<SampleNormal> &normals, double epsilon);

/// The covariance of every sample from its normal and the neighbourhood it came from (estimateNormals'
/// `neighbourhoods`, same order): the identity where the normal is invalid or its neighbourhood line-like, else
/// planeCovariance.
/// std::invalid_argument when the sizes differ.
[[nodiscard]] std::vector<SampleCovariance> sampleCovariances(const std::vector<SampleNormal> &normals,
                                                              const std::vector<LocalPca> &neighbourhoods,
                                                              double epsilon, double line_ratio);
/// The same with the config's normals.covariance_epsilon and normals.covariance_line_ratio.
[[nodiscard]] std::vector<SampleCovariance> sampleCovariances(const std::vector<SampleNormal> &normals,
                                                              const std::vector<LocalPca> &neighbourhoods,
                                                              const NormalConfig &config);
/// As sampleCovariances, but a plane takes its normal from `plane_normals` (same order) where that one is valid,
/// else from `normals`; whether a sample gets a plane at all is still its `neighbourhoods` entry's to decide.
[[nodiscard]] std::vector<SampleCovariance> sampleCovariances(const std::vector<SampleNormal> &normals,
                                                              const std::vector<LocalPca> &neighbourhoods,
                                                              const std::vector<SampleNormal> &plane_normals,
                                                              double epsilon, double line_ratio);

/// The covariances the library outputs for samples `ids` of output level `level` (levels 0..level of `hierarchy`),
/// given their normals and the neighbourhoods those came from (estimateNormals or Pipeline::normals). With
/// normals.covariance_k > 0 a plane's normal is the PCA normal of the covariance_k nearest samples of levels
/// 0..level (covarianceNormalParams): the refined neighbourhood finds where a scan line pins no plane, while a
/// neighbourhood of a fixed number of samples, alike in every frame, gives the plane GICP matches best (at equal
/// point count: GICP rotation error 0.054 -> 0.009 deg at level 4 of the synthetic drive; docs/quality.md).
/// Thread count from config.threads; const on the hierarchy.
[[nodiscard]] std::vector<SampleCovariance> estimateCovariances(const Hierarchy &hierarchy,
                                                                const std::vector<SampleId> &ids, int level,
                                                                const std::vector<SampleNormal> &normals,
                                                                const std::vector<LocalPca> &neighbourhoods,
                                                                const HpdsConfig &config);

}  // namespace hpds
