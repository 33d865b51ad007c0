#include "hpds/points/FarViewpoint.hpp"

#include <sstream>

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

std::string farViewpointWarning(const std::string &input, double nearest, const Eigen::Vector3d &viewpoint) {
  std::ostringstream w;
  w.precision(12);
  w << "the nearest point of '" << input << "' is " << nearest << " m from its viewpoint (" << viewpoint.x() << ", "
    << viewpoint.y() << ", " << viewpoint.z() << "), where normals are made to face and input.min_range/max_range "
    << "measure from: ";
  return w.str();
}

}  // namespace hpds
