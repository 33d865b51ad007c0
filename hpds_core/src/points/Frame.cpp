#include "hpds/points/Frame.hpp"

#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace hpds {

namespace {

template <typename Scalar>
Frame framed(const std::vector<Eigen::Matrix<Scalar, 3, 1>> &points, const Eigen::Isometry3d &sensor_to_fixed,
             double stamp) {
  if (points.size() > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument(std::to_string(points.size()) + " points: at most 2^32 - 1 fit the sample index");
  constexpr FieldType kXyz = sizeof(Scalar) == 8 ? FieldType::Float64 : FieldType::Float32;
  PointLayout layout;
  layout.append("x", kXyz);
  layout.append("y", kXyz);
  layout.append("z", kXyz);
  layout.append("index", FieldType::UInt32);
  const std::uint32_t index_offset = layout.find("index")->offset;
  Frame frame;
  frame.points = PointBuffer(layout, points.size());
  frame.sensor_to_fixed = sensor_to_fixed;
  frame.stamp = stamp;
  for (std::size_t i = 0; i < points.size(); ++i) {
    std::uint8_t *rec = frame.points.record(i);
    std::memcpy(rec, points[i].data(), 3 * sizeof(Scalar));
    const auto index = static_cast<std::uint32_t>(i);
    std::memcpy(rec + index_offset, &index, sizeof index);
  }
  return frame;
}

}  // namespace

Frame frameFromPoints(const std::vector<Eigen::Vector3f> &points, const Eigen::Isometry3d &sensor_to_fixed,
                      double stamp) {
  return framed(points, sensor_to_fixed, stamp);
}

Frame frameFromPoints(const std::vector<Eigen::Vector3d> &points, const Eigen::Isometry3d &sensor_to_fixed,
                      double stamp) {
  return framed(points, sensor_to_fixed, stamp);
}

}  // namespace hpds
