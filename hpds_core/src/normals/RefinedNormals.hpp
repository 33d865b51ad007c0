// Internal: the refined normal estimator behind NormalParams::neighborhood_level_offset / max_growth (contract in
// hpds/normals/NormalEstimator.hpp), called by estimateNormals, and the pieces both estimators share. Not public API.
#pragma once

#include <memory>
#include <vector>

#include "hpds/normals/LocalPca.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "sampling/BallGrid.hpp"

namespace hpds {

/// The search radii of the refined estimator on `hierarchy` with `params`: the base footprint, doubled until twice
/// the level-0 cell edge is reached.
[[nodiscard]] std::vector<double> refinedSearchRadii(const Hierarchy &hierarchy, const NormalParams &params);

/// The averaging points' side of the refined estimator's searches, one per search radius, all over one box that holds
/// every sample the normals will be asked for: built ahead of the normals (the pipeline builds the first ones while
/// a frame is inserted, on its second thread). A radius without a grid here is sorted over the same box when a
/// sweep needs it, so the normals are the same whichever were built ahead.
struct AveragingGrids {
  std::vector<double> radii;  ///< refinedSearchRadii
  double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {0.0, 0.0, 0.0};
  std::vector<std::unique_ptr<BallGridPoints>> by_radius;  ///< by index into radii; null: not built ahead
  [[nodiscard]] std::size_t memUsage() const;
};

/// `centroids`: when given, the averaging points of neighborhood_level_offset (3 doubles each, fixed frame: the
/// centroids of the points of the frame the samples came from per cell of level level + offset, see
/// CellCentroids.hpp) in place of the samples of levels level+1..level+offset, which then need not exist.
/// `neighbourhoods`: when given (sized as ids), each entry is set to the PCA of the neighbourhood the normal came from.
/// `grids`: with `centroids`, their search grids (see AveragingGrids); every queried sample must lie in their box.
[[nodiscard]] std::vector<SampleNormal> estimateNormalsRefined(const Hierarchy &hierarchy,
                                                               const std::vector<SampleId> &ids,
                                                               const NormalParams &params,
                                                               const std::vector<double> *centroids = nullptr,
                                                               std::vector<LocalPca> *neighbourhoods = nullptr,
                                                               const AveragingGrids *grids = nullptr);

/// NaN normal and curvature, valid = false.
[[nodiscard]] SampleNormal invalidNormal();
/// The PCA's normal (sign as solved) and curvature; invalidNormal() for an invalid PCA.
[[nodiscard]] SampleNormal unorientedNormal(const LocalPca &pca);
/// Turns every valid normals[i] toward the viewpoint of ids[i]'s frame. A separate pass in id order: the
/// neighbourhood searches visit samples in cell order, where each view direction would be a cache miss.
void orientTowardViewpoints(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                            std::vector<SampleNormal> &normals, int threads);

}  // namespace hpds
