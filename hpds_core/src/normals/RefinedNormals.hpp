// Internal: the refined normal estimator behind NormalParams::neighborhood_level_offset / max_growth (contract in
// hpds/normals/NormalEstimator.hpp), called by estimateNormals, and the pieces both estimators share. Not public API.
#pragma once

#include <vector>

#include "hpds/normals/LocalPca.hpp"
#include "hpds/normals/NormalEstimator.hpp"

namespace hpds {

/// `centroids`: when given, the averaging points of neighborhood_level_offset (3 doubles each, fixed frame: the
/// centroids of the points of the frame the samples came from per cell of level level + offset, see
/// CellCentroids.hpp) in place of the samples of levels level+1..level+offset, which then need not exist.
/// `neighbourhoods`: when given (sized as ids), each entry is set to the PCA of the neighbourhood the normal came from.
[[nodiscard]] std::vector<SampleNormal> estimateNormalsRefined(const Hierarchy &hierarchy,
                                                               const std::vector<SampleId> &ids,
                                                               const NormalParams &params,
                                                               const std::vector<double> *centroids = nullptr,
                                                               std::vector<LocalPca> *neighbourhoods = nullptr);

/// NaN normal and curvature, valid = false.
[[nodiscard]] SampleNormal invalidNormal();
/// The PCA's normal (sign as solved) and curvature; invalidNormal() for an invalid PCA.
[[nodiscard]] SampleNormal unorientedNormal(const LocalPca &pca);
/// Turns every valid normals[i] toward the viewpoint of ids[i]'s frame. A separate pass in id order: the
/// neighbourhood searches visit samples in cell order, where each view direction would be a cache miss.
void orientTowardViewpoints(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                            std::vector<SampleNormal> &normals, int threads);

}  // namespace hpds
