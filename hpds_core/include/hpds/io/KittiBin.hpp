// KITTI velodyne .bin files: a headerless sequence of little-endian float32 records (x, y, z, intensity).
//
// Contract
// - Units are whatever the file holds (KITTI: metres, intensity in [0, 1]); nothing is rescaled.
// - readKittiBin returns a PointBuffer with fields x y z intensity (float32, offsets 0/4/8/12, point_step 16),
//   organisation N x 1. A file whose size is 0 or not a multiple of 16 bytes is rejected: the format has no header,
//   so the size is the only integrity check there is, and an empty file is far more often a failed write than a
//   real sweep. So is a file of float64 records (what numpy's tofile writes by default): more than 10 % of its
//   float32 points have a coordinate beyond 100 km or subnormal while, read as float64, at most 1 % are implausible.
// - writeKittiBin takes x, y, z and intensity (0 when the field is absent) from fields of any numeric type,
//   converting to float32; other fields and the organisation are dropped, as the format cannot hold them.
// - Errors: std::runtime_error whose message starts with the path (missing/unreadable file, bad size, missing x/y/z,
//   I/O failure). A failed write removes the partial file.
// - Thread-safety: reentrant; concurrent calls on different paths are safe.
#pragma once

#include <string>

#include "hpds/points/PointBuffer.hpp"

namespace hpds {

[[nodiscard]] PointBuffer readKittiBin(const std::string &path);

void writeKittiBin(const std::string &path, const PointBuffer &cloud);

}  // namespace hpds
