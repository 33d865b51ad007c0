// Normals and curvature of hierarchy samples by local PCA, with neighbourhoods taken from the hierarchy itself.
//
// Contract
// - Neighbours of a sample are the samples of levels 0..`level` within `radius`, and with k > 0 the k nearest of
//   those; with radius = 0 the radius doubles from 2 r_level until k are found (or it reaches twice the level-0 cell
//   edge). Every radius is searched for all ids at once (BallGrid: samples and queries sorted by cell once, the
//   queries of a cell sharing one search; with radius 0, one such search per doubling over the ids still short of
//   k). A search spans at most 2^21 cells of its radius per axis from the queries' bounding box (56 km at 2.7 cm):
//   samples beyond have no neighbours (invalid normal).
// - PCA by LocalPca's solveNormal (eigenvalues and normal agree with an iterative eigensolver to ~1e-15).
// - The normal is oriented toward the viewpoint of the frame that contributed the sample. Where it is nearly
//   perpendicular to the view (a neighbourhood on one scan line: its plane holds the ray, so the view cannot tell its
//   sides apart: |cos(normal, view)| < 0.2) and the sample lies below the viewpoint, a normal near `up` (the frame's
//   z; |cos| >= 0.5) faces up: a surface below the sensor with such a normal is seen from above (ground, roofs).
//   Above the sensor the view decides, as ceilings face down and rising ground up; so does a sample level with the
//   sensor (its view within 1e-3 rad of horizontal, the view direction's own error), whose normal is then nearly
//   perpendicular to the view and may face either way. See orientTowardViewpoints.
// - Fewer than `min_neighbors` neighbours (the sample included) or a degenerate neighbourhood gives valid = false
//   and NaN normal/curvature (PCL's convention for "not estimated"); never a garbage direction marked valid.
// - curvature = l0 / (l0 + l1 + l2). Results are per id, independent of the thread count.
// - Refinements (both off in this estimator's own parameters; config/hpds.yaml turns both on: offset 2, growth 8;
//   see RefinedNormals.cpp):
//   - neighborhood_level_offset o > 0: the footprint is chosen as above at `level` (the radius, or the distance of
//     the k-th nearest sample of levels 0..level), then every sample of levels 0..level+o inside it is used. Finer
//     levels average the range noise, which a single Poisson-disk level cannot.
//   - max_growth g > 1: a neighbourhood that is line-like (l1 < line_ratio * l2: one scan line) or has fewer than
//     min_neighbors samples doubles its footprint, up to g times the first one (and twice the level-0 cell edge).
//     A grown neighbourhood is used only if it is no longer line-like and flat (RMS distance to its plane <=
//     max_plane_rms * its radius); the first non-flat one stops the growth, and if none qualifies the first
//     neighbourhood is kept. The line test needs a footprint long against the range noise (~20 sigma), as at the
//     usual output levels.
//   Measured gains and costs: docs/quality.md.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/normals/LocalPca.hpp"
#include "hpds/sampling/Hierarchy.hpp"

namespace hpds {

struct NormalParams {
  int level = 0;            ///< neighbourhoods from levels 0..level
  double radius = 0.0;      ///< [m]; 0 with k > 0: adaptive
  int k = 0;                ///< 0: every neighbour within radius
  int min_neighbors = 5;
  int threads = 1;
  int neighborhood_level_offset = 0;  ///< also take neighbours from levels level+1..level+offset (0 = off)
  double max_growth = 1.0;            ///< grow line-like/too small neighbourhoods up to this factor (1 = off)
  double line_ratio = 0.05;           ///< l1 / l2 below this counts as line-like
  double max_plane_rms = 0.02;        ///< a grown neighbourhood must fit its plane within this * its radius (RMS)
  /// Unit, in the hierarchy's frame: which way is up, for normals perpendicular to the view (see above). The z
  /// axis, as ROS's REP 103 has it for sensor, body and map frames alike.
  std::array<double, 3> up = {0.0, 0.0, 1.0};
};

struct SampleNormal {
  float normal[3];
  float curvature;
  bool valid;
};

/// Resolves the config's defaults (radius 0 and k 0 -> 2.5 r_level) for output level `level`.
[[nodiscard]] NormalParams normalParamsFor(const HpdsConfig &config, int level);
/// The search behind a covariance's plane (normals.covariance_k > 0): the normals.covariance_k nearest samples of
/// levels 0..level, no refinement (SampleCovariance.hpp).
[[nodiscard]] NormalParams covarianceNormalParams(const HpdsConfig &config, int level);

/// An upper bound [m] on the distance from a sample to any sample its normal reads, for a hierarchy of level-0
/// cell edge `cell_size` and radius `level_radius` of params.level: samples farther than this from every queried id
/// cannot change estimateNormals' results (the tiled map build reads its neighbours' samples this far). Kept beside
/// estimateNormals because it mirrors its search limits: fixed radius (plain), growth capped at twice the level-0
/// edge (refined), k-NN searches doubling up to that cap.
[[nodiscard]] double neighborhoodReach(const NormalParams &params, double cell_size, double level_radius);

/// One result per id in `ids` (same order). `neighbourhoods`: when given, resized to ids.size() and set to the PCA of
/// the neighbourhood each normal came from (eigenvalues, unoriented normal; a default LocalPca where none was
/// solved), e.g. for covariances (SampleCovariance.hpp).
[[nodiscard]] std::vector<SampleNormal> estimateNormals(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                                                        const NormalParams &params,
                                                        std::vector<LocalPca> *neighbourhoods = nullptr);

}  // namespace hpds
