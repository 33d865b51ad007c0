// Helpers of the hostile-input tests (test_hostile_*.cpp, test_fuzz_regressions.cpp): clouds of any xyz field
// type, a grid of points, a frame around a cloud, and writing a file's bytes.
#pragma once

#include <array>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "hpds/points/Frame.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds::test {

inline void writeText(const std::filesystem::path &p, const std::string &s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

// A cloud with x y z of `type` and a float32 intensity; values are cast through writeFromDouble.
inline PointBuffer typedCloud(FieldType type, const std::vector<std::array<double, 3>> &pts) {
  PointLayout l;
  for (const char *a : {"x", "y", "z"}) l.append(a, type);
  l.append("intensity", FieldType::Float32);
  PointBuffer b(l, pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    for (int a = 0; a < 3; ++a) writeFromDouble(b.record(i), l.fields[a], pts[i][a]);
    writeFromDouble(b.record(i), l.fields[3], double(i));
  }
  return b;
}

inline std::vector<std::array<double, 3>> gridPoints(int n, double step, double offset = 0.0) {
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) pts.push_back({offset + i * step, offset + j * step, 1.0 + (i + j) % 3});
  return pts;
}

inline Frame frameOf(PointBuffer b) {
  Frame f;
  f.points = std::move(b);
  return f;
}

}  // namespace hpds::test
