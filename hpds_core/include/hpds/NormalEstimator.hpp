// Normals and curvature of hierarchy samples by local PCA, with neighbourhoods taken from the hierarchy itself.
//
// Contract
// - Neighbours of a sample are the samples of levels 0..`level` within `radius` (the level grids are walked
//   directly), and with k > 0 the k nearest of those; with radius = 0 the radius grows from 2 r_level until k are
//   found (or it reaches twice the level-0 cell edge).
// - The normal is oriented toward the viewpoint of the frame that contributed the sample.
// - Fewer than `min_neighbors` neighbours (the sample included) or a degenerate neighbourhood gives valid = false
//   and NaN normal/curvature (PCL's convention for "not estimated"); never a garbage direction marked valid.
// - curvature = l0 / (l0 + l1 + l2). Results are per id, independent of the thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "hpds/Config.hpp"
#include "hpds/Hierarchy.hpp"

namespace hpds {

struct NormalParams {
  int level = 0;            ///< neighbourhoods from levels 0..level
  double radius = 0.0;      ///< [m]; 0 with k > 0: adaptive
  int k = 0;                ///< 0: every neighbour within radius
  int min_neighbors = 5;
  int threads = 1;
};

struct SampleNormal {
  float normal[3];
  float curvature;
  bool valid;
};

/// Resolves the config's defaults (radius 0 and k 0 -> 2.5 r_level) for output level `level`.
[[nodiscard]] NormalParams normalParamsFor(const HpdsConfig &config, int level);

/// One result per id in `ids` (same order).
[[nodiscard]] std::vector<SampleNormal> estimateNormals(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                                                        const NormalParams &params);

}  // namespace hpds
