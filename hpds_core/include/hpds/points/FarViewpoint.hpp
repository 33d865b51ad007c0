// FarViewpoint: whether a cloud's viewpoint can be its sensor's position.
//
// Contract
// - A sensor is never a kilometre from every point it measured. Where the viewpoint is, the input is not in its
//   sensor's frame (world coordinates given without the sensor's pose), and normals would face a point far off,
//   about half of them the wrong way, while range limits measure from it. The CLI and the Python API warn alike.
// - Distances in metres, in the points' own frame; NaN/Inf points are left out. Stateless, thread-safe.
#pragma once

#include "hpds/points/PointBuffer.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace hpds {

/// [m] Farther than this from every point, a viewpoint is no sensor's position (a lidar's nearest return is metres
/// away).
inline constexpr double kFarViewpoint = 1000.0;

/// [m] The distance from `viewpoint` to the nearest finite point of `points` (infinity when there is none, or no x y z).
[[nodiscard]] double nearestPointDistance(const PointBuffer &points, const Eigen::Vector3d &viewpoint);

/// The same for positions held as Eigen vectors (float or double).
template <typename Scalar>
[[nodiscard]] double nearestPointDistance(const std::vector<Eigen::Matrix<Scalar, 3, 1>> &points,
                                          const Eigen::Vector3d &viewpoint) {
  double nearest = std::numeric_limits<double>::infinity();
  for (const auto &p : points) {
    const Eigen::Vector3d q = p.template cast<double>();
    if (q.allFinite()) nearest = std::min(nearest, (q - viewpoint).squaredNorm());
  }
  return std::sqrt(nearest);
}

/// Whether `nearest` (from nearestPointDistance) puts the viewpoint too far from every point to be the sensor's.
[[nodiscard]] inline bool isFarViewpoint(double nearest) { return std::isfinite(nearest) && nearest > kFarViewpoint; }

/// The start of the warning for input `input` whose nearest point is `nearest` metres from `viewpoint`, ending in ": "
/// for the caller's advice (which option gives the sensor's position depends on the tool).
[[nodiscard]] std::string farViewpointWarning(const std::string &input, double nearest,
                                              const Eigen::Vector3d &viewpoint);

}  // namespace hpds
