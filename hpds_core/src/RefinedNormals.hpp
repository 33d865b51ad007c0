// Internal: the refined normal estimator behind NormalParams::neighborhood_level_offset / max_growth (contract in
// hpds/NormalEstimator.hpp). Called by estimateNormals; not part of the public API.
#pragma once

#include <vector>

#include "hpds/NormalEstimator.hpp"

namespace hpds {

[[nodiscard]] std::vector<SampleNormal> estimateNormalsRefined(const Hierarchy &hierarchy,
                                                               const std::vector<SampleId> &ids,
                                                               const NormalParams &params);

}  // namespace hpds
