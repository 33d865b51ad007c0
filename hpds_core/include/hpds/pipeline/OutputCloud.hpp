// OutputCloud: hierarchy samples as a point cloud with the layout every consumer (PLY, PointCloud2) shares.
//
// Layout: float32 x y z (fixed frame), uint8 level, [float32 normal_x normal_y normal_z curvature],
// [uint32 frame], then every input field except x/y/z and names taken above, same name, type and bytes.
#pragma once

#include <vector>

#include "hpds/sampling/Hierarchy.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds {

[[nodiscard]] PointLayout outputLayout(const PointLayout &input, bool with_normals, bool with_frame);

/// `normals`: null, or one entry per id. Samples are written in the order of `ids`.
[[nodiscard]] PointBuffer buildOutputCloud(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                                           const std::vector<SampleNormal> *normals, bool with_frame);

}  // namespace hpds
