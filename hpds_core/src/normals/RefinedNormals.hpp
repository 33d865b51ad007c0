// Internal: the refined normal estimator behind NormalParams::neighborhood_level_offset / max_growth (contract in
// hpds/normals/NormalEstimator.hpp), called by estimateNormals, and the pieces both estimators share. Not public API.
#pragma once

#include <cstddef>
#include <cstdint>
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
  /// The grid of radii[g] over `points` (the averaging points these grids serve): the first sorted, the others
  /// grouped from it (BallGridPoints' nesting constructor; from by_radius[0], else from `first` when given, else from
  /// a first grid made for the purpose), so a grid is the same whoever builds it and when. Does not store it.
  [[nodiscard]] std::unique_ptr<BallGridPoints> make(std::size_t g, const PointSet &points,
                                                     const BallGridPoints *first = nullptr) const;
};

/// Neighbourhoods already chosen for some of the queries (by refinedNeighbourhoodsOverCentroids), parallel to ids.
struct KnownNeighbourhoods {
  enum State : std::uint8_t { kUnknown = 0, kChosen = 1, kNone = 2 };
  const std::uint8_t *state = nullptr;  ///< per id: kUnknown (estimate it), kChosen (chosen[i]), kNone (no normal)
  const LocalPca *chosen = nullptr;
};

/// `centroids`: when given, the averaging points of neighborhood_level_offset (3 doubles each, fixed frame: the
/// centroids of the points of the frame the samples came from per cell of level level + offset, see
/// CellCentroids.hpp) in place of the samples of levels level+1..level+offset, which then need not exist.
/// `neighbourhoods`: when given (sized as ids), each entry is set to the PCA of the neighbourhood the normal came from.
/// `grids`: with `centroids`, their search grids (see AveragingGrids); every queried sample must lie in their box.
/// `known`: with `centroids` and a fixed footprint (params.k 0), the neighbourhoods of the ids not marked kUnknown,
/// taken as given; std::invalid_argument otherwise.
[[nodiscard]] std::vector<SampleNormal> estimateNormalsRefined(const Hierarchy &hierarchy,
                                                               const std::vector<SampleId> &ids,
                                                               const NormalParams &params,
                                                               const std::vector<double> *centroids = nullptr,
                                                               std::vector<LocalPca> *neighbourhoods = nullptr,
                                                               const AveragingGrids *grids = nullptr,
                                                               const KnownNeighbourhoods *known = nullptr);

/// The neighbourhood estimateNormalsRefined chooses, over `centroids` with `grids` (their radii those of
/// refinedSearchRadii for a hierarchy of `cell_size` and these params), for queries at positions base + 3 * index[i],
/// i < count, without a hierarchy: chosen[i] and have[i] = 1, or have[i] = 0 where no normal can be estimated. The
/// same bits as estimateNormalsRefined for a sample at that position, whatever else is queried or known (a query's
/// neighbourhoods depend on its position only). Needs params.k 0 and params.radius > 0 (std::invalid_argument
/// otherwise). Runs on the calling thread; grids it sorts are kept in `grids`, which only this call may touch
/// meanwhile. The pipeline runs it on the samples a frame's insertion has accepted so far, beside the insertion.
void refinedNeighbourhoodsOverCentroids(const double *base, const std::uint32_t *index, std::size_t count,
                                        const NormalParams &params, double cell_size,
                                        const std::vector<double> &centroids, AveragingGrids &grids,
                                        LocalPca *chosen, std::uint8_t *have);

/// NaN normal and curvature, valid = false.
[[nodiscard]] SampleNormal invalidNormal();
/// The PCA's normal (sign as solved) and curvature; invalidNormal() for an invalid PCA.
[[nodiscard]] SampleNormal unorientedNormal(const LocalPca &pca);
/// Turns every valid normals[i] toward the viewpoint of ids[i]'s frame; one nearly perpendicular to the view of a
/// sample below the viewpoint up along `up` (unit; NormalParams::up; the rule and why: NormalEstimator.cpp). A
/// separate pass in id order: the neighbourhood searches visit samples in cell order, where each view direction
/// would be a cache miss.
void orientTowardViewpoints(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                            std::vector<SampleNormal> &normals, const std::array<double, 3> &up, int threads);

}  // namespace hpds
