// Helpers of the pipeline tests (test_pipeline_*.cpp, test_insertion_order.cpp): a frame made from a list of points,
// the small synthetic lidar most of them drive the pipeline with, and the promised orientation of normals.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/points/Frame.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds::test {

/// x, y, z of type `t`, then a uint8 intensity and a float64 t: the layout of makeFrame's frames.
inline PointLayout frameLayout(FieldType t = FieldType::Float32) {
  PointLayout l;
  l.append("x", t);
  l.append("y", t);
  l.append("z", t);
  l.append("intensity", FieldType::UInt8);
  l.append("t", FieldType::Float64);
  return l;
}

/// A frame of `pts` (identity pose); intensity and t count up with the point index.
inline Frame makeFrame(const std::vector<std::array<double, 3>> &pts, FieldType t = FieldType::Float32) {
  Frame f;
  f.points = PointBuffer(frameLayout(t), pts.size());
  const auto &l = f.points.layout();
  for (std::size_t i = 0; i < pts.size(); ++i) {
    for (int a = 0; a < 3; ++a) writeFromDouble(f.points.record(i), l.fields[a], pts[i][a]);
    writeFromDouble(f.points.record(i), *l.find("intensity"), static_cast<double>(i % 251));
    writeFromDouble(f.points.record(i), *l.find("t"), 1e-3 * static_cast<double>(i));
  }
  return f;
}

/// A 16-beam lidar of 720 azimuth steps (11 520 rays a frame): small enough for brute-force oracles.
inline SyntheticLidarConfig smallLidar(SceneKind scene = SceneKind::Urban, int frames = 3) {
  SyntheticLidarConfig c;
  c.beams = 16;
  c.azimuth_steps = 720;
  c.frames = frames;
  c.scene = scene;
  return c;
}

/// The orientation NormalEstimator.hpp promises, written from its contract: a normal n of a sample whose unit
/// direction to its viewpoint is v faces the viewpoint (n.v >= 0), except that one within 11.5 degrees of
/// perpendicular to v (|n.v| < 0.2) and within 60 degrees of `up` (|n.up| >= 0.5) of a sample below the sensor
/// (v.up >= 1e-3) faces up (n.up >= 0).
inline bool orientedAsPromised(const Eigen::Vector3d &n, const Eigen::Vector3d &v,
                               const Eigen::Vector3d &up = Eigen::Vector3d::UnitZ()) {
  if (std::abs(n.dot(v)) < 0.2 && std::abs(n.dot(up)) >= 0.5 && v.dot(up) >= 1e-3) return n.dot(up) >= 0.0;
  return n.dot(v) >= 0.0;
}

}  // namespace hpds::test
