#include "QualityIo.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <stdexcept>

#include "CliOptions.hpp"
#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/InputFolders.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"

namespace hpds::cli {

int SamplingCloud::maxLevel() const { return level.empty() ? -1 : *std::max_element(level.begin(), level.end()); }

SamplingCloud loadSampling(const std::string &path) {
  const PointBuffer buf = readPointCloud(path);
  const PointLayout &l = buf.layout();
  const PointField *fx = l.find("x"), *fy = l.find("y"), *fz = l.find("z");
  const PointField *fl = l.find("level"), *fc = l.find("curvature"), *ff = l.find("frame");
  const PointField *nx = l.find("normal_x"), *ny = l.find("normal_y"), *nz = l.find("normal_z");
  SamplingCloud c;
  c.has_level = fl != nullptr;
  c.has_frame = ff != nullptr;
  c.xyz.resize(buf.size());
  if (fl) c.level.resize(buf.size());
  if (nx && ny && nz) c.normal.resize(buf.size());
  if (fc) c.curvature.resize(buf.size());
  if (ff) c.frame.resize(buf.size());
  for (std::size_t i = 0; i < buf.size(); ++i) {
    const std::uint8_t *r = buf.record(i);
    c.xyz[i] = {readAsDouble(r, *fx), readAsDouble(r, *fy), readAsDouble(r, *fz)};
    if (fl) {
      const double v = readAsDouble(r, *fl);
      if (!(v >= 0.0 && v <= 21.0 && v == std::floor(v)))
        throw std::invalid_argument(path + ": level value " + std::to_string(v) + " is not an integer in 0..21");
      c.level[i] = static_cast<int>(v);
    }
    if (!c.normal.empty()) c.normal[i] = {readAsDouble(r, *nx), readAsDouble(r, *ny), readAsDouble(r, *nz)};
    if (fc) c.curvature[i] = static_cast<float>(readAsDouble(r, *fc));
    if (ff) c.frame[i] = static_cast<std::uint32_t>(readAsDouble(r, *ff));
  }
  return c;
}

SamplingCloud keepFrame(const SamplingCloud &c, std::uint32_t frame) {
  if (c.frame.empty()) return c;
  SamplingCloud out;
  for (std::size_t i = 0; i < c.xyz.size(); ++i) {
    if (c.frame[i] != frame) continue;
    out.xyz.push_back(c.xyz[i]);
    if (!c.level.empty()) out.level.push_back(c.level[i]);
    if (!c.normal.empty()) out.normal.push_back(c.normal[i]);
    if (!c.curvature.empty()) out.curvature.push_back(c.curvature[i]);
    out.frame.push_back(frame);
  }
  return out;
}

std::vector<Eigen::Vector3d> loadInputs(const std::vector<std::string> &inputs, const std::string &poses_file) {
  std::vector<Eigen::Isometry3d> poses;
  if (!poses_file.empty()) {
    poses = readPosesOption(poses_file);
    if (const std::string w = checkPosesMatchInputs(poses_file, poses.size(), inputs); !w.empty())
      std::cerr << "hpds: warning: " << w << "\n";
  }
  std::vector<Eigen::Vector3d> out;
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const PointBuffer buf = readPointCloud(inputs[i]);
    const PointField *fx = buf.layout().find("x"), *fy = buf.layout().find("y"), *fz = buf.layout().find("z");
    const Eigen::Isometry3d T = poses.empty() ? Eigen::Isometry3d::Identity() : poses[i];
    for (std::size_t k = 0; k < buf.size(); ++k) {
      const Eigen::Vector3d p(readAsDouble(buf.record(k), *fx), readAsDouble(buf.record(k), *fy),
                              readAsDouble(buf.record(k), *fz));
      if (!p.allFinite() || (p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0)) continue;
      out.push_back(T * p);
    }
  }
  return out;
}

void TextFile::close() { writeFileAtomically(path_, out_.str()); }

std::string jsonQuoted(const std::string &text) {
  std::string out = "\"";
  for (const char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(static_cast<unsigned char>(c)));
      out += buf;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::string num(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

}  // namespace hpds::cli
