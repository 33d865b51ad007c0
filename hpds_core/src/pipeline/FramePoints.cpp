#include "hpds/pipeline/FramePoints.hpp"

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace hpds {

void poseFramePoints(const Frame &frame, const InputConfig &input, std::vector<double> &xyz,
                     std::vector<std::uint32_t> &candidates, SkippedPoints &skipped) {
  const PointBuffer &pts = frame.points;
  const PointLayout &layout = pts.layout();
  const PointField *fx = layout.find("x"), *fy = layout.find("y"), *fz = layout.find("z");
  if (!fx || !fy || !fz) throw std::invalid_argument("frame has no x/y/z fields");
  const std::size_t n = pts.size();
  xyz.resize(3 * n);
  candidates.clear();
  candidates.reserve(n);
  const Eigen::Matrix3d R = frame.sensor_to_fixed.linear();
  const Eigen::Vector3d t = frame.sensor_to_fixed.translation();
  const Eigen::Vector3d v = frame.viewpoint;
  const double min_r2 = input.min_range * input.min_range;
  const double max_r2 = input.max_range > 0.0 ? input.max_range * input.max_range : INFINITY;
  // Drivers almost always send float32 x/y/z: read those directly instead of through the per-type switch.
  const bool f32 = fx->type == FieldType::Float32 && fy->type == FieldType::Float32 && fz->type == FieldType::Float32;
  const auto loadF32 = [](const std::uint8_t *p) {
    float value;
    std::memcpy(&value, p, sizeof value);
    return static_cast<double>(value);
  };
  // The skip rules, in the points' own frame: true, and counted, for a point left out.
  const auto skip = [&](double x, double y, double z) {
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      ++skipped.invalid;
      return true;
    }
    if (input.skip_zero_points && x == 0.0 && y == 0.0 && z == 0.0) {
      ++skipped.zero;
      return true;
    }
    const double dx = x - v.x(), dy = y - v.y(), dz = z - v.z();
    const double r2 = dx * dx + dy * dy + dz * dz;
    if (r2 < min_r2 || r2 > max_r2) {
      ++skipped.range;
      return true;
    }
    return false;
  };
  // Scan mode in the sensor's own frame (the node's default) has the identity pose: a finite point is then its own
  // position, and x + 0.0 gives the bits the product would (1 x + 0 y + 0 z + 0, a -0.0 included).
  const bool identity = R == Eigen::Matrix3d::Identity() && t == Eigen::Vector3d::Zero();
  if (identity && f32) {
    const std::size_t ox = fx->offset, oy = fy->offset, oz = fz->offset;
    candidates.resize(n);
    std::size_t kept = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint8_t *rec = pts.record(i);
      const double x = loadF32(rec + ox), y = loadF32(rec + oy), z = loadF32(rec + oz);
      if (skip(x, y, z)) continue;
      double *o = &xyz[3 * i];
      o[0] = x + 0.0, o[1] = y + 0.0, o[2] = z + 0.0;
      candidates[kept++] = static_cast<std::uint32_t>(i);
    }
    candidates.resize(kept);
    return;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t *rec = pts.record(i);
    const double x = f32 ? loadF32(rec + fx->offset) : readAsDouble(rec, *fx);
    const double y = f32 ? loadF32(rec + fy->offset) : readAsDouble(rec, *fy);
    const double z = f32 ? loadF32(rec + fz->offset) : readAsDouble(rec, *fz);
    if (skip(x, y, z)) continue;
    const double wx = R(0, 0) * x + R(0, 1) * y + R(0, 2) * z + t.x();
    const double wy = R(1, 0) * x + R(1, 1) * y + R(1, 2) * z + t.y();
    const double wz = R(2, 0) * x + R(2, 1) * y + R(2, 2) * z + t.z();
    if (!std::isfinite(wx) || !std::isfinite(wy) || !std::isfinite(wz)) {  // a finite point can overflow through a huge pose
      ++skipped.invalid;
      continue;
    }
    xyz[3 * i] = wx;
    xyz[3 * i + 1] = wy;
    xyz[3 * i + 2] = wz;
    candidates.push_back(static_cast<std::uint32_t>(i));
  }
}

}  // namespace hpds
