// Helpers shared by the sampling-quality benchmarks (normal_accuracy, feature_sensitivity): both feed the sampler
// the object returns of synthetic sweeps with a `gt` field that carries each point's index into their truth arrays
// through the pipeline, and both print tables of fixed-precision numbers.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "hpds/points/Frame.hpp"
#include "hpds/points/PointBuffer.hpp"
#include "hpds/eval/SyntheticLidar.hpp"

namespace hpds::bench {

/// `v` with `prec` decimals; "-" for NaN or infinity (a table cell without a value).
inline std::string fmt(double v, int prec = 2) {
  if (!std::isfinite(v)) return "-";
  char b[32];
  std::snprintf(b, sizeof b, "%.*f", prec, v);
  return b;
}

/// The returns of `sf` that hit an object (kind != None) as a frame of x, y, z (float32) and gt (uint32), gt numbering
/// them from `first_index` in order; pose and stamp are left to the caller. For every kept return `visit(i, p)` is
/// called with its index in `sf` and its sensor-frame position as the sampler sees it (rounded to float32), so that
/// the caller's truth arrays are indexed by the same point.
template <typename Visit>
Frame objectReturnsFrame(const SyntheticFrame &sf, std::uint32_t first_index, Visit &&visit) {
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  layout.append("gt", FieldType::UInt32);
  Frame out;
  out.points = PointBuffer(layout, 0);
  const PointBuffer &pts = sf.frame.points;
  const PointField *fx = pts.layout().find("x"), *fy = pts.layout().find("y"), *fz = pts.layout().find("z");
  std::vector<std::uint8_t> rec(layout.point_step);
  std::uint32_t index = first_index;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (sf.kinds[i] == ObjectKind::None) continue;
    const Eigen::Vector3d p(readAsDouble(pts.record(i), *fx), readAsDouble(pts.record(i), *fy),
                            readAsDouble(pts.record(i), *fz));
    for (int a = 0; a < 3; ++a) writeFromDouble(rec.data(), layout.fields[static_cast<std::size_t>(a)], p[a]);
    writeFromDouble(rec.data(), layout.fields[3], index++);
    out.points.pushBack(rec.data());
    visit(i, Eigen::Vector3d(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())));
  }
  return out;
}

}  // namespace hpds::bench
