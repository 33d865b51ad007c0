#include "hpds/points/FarViewpoint.hpp"

namespace hpds {

double nearestPointDistance(const PointBuffer &points, const Eigen::Vector3d &viewpoint) {
  const PointField *f[3] = {points.layout().find("x"), points.layout().find("y"), points.layout().find("z")};
  if (!f[0] || !f[1] || !f[2]) return std::numeric_limits<double>::infinity();
  double nearest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint8_t *r = points.record(i);
    const Eigen::Vector3d p(readAsDouble(r, *f[0]), readAsDouble(r, *f[1]), readAsDouble(r, *f[2]));
    if (p.allFinite()) nearest = std::min(nearest, (p - viewpoint).squaredNorm());
  }
  return std::sqrt(nearest);
}

}  // namespace hpds
