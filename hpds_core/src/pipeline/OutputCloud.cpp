#include "hpds/pipeline/OutputCloud.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace hpds {

namespace {
constexpr const char *kCovarianceNames[6] = {"cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"};

/// Whether an output with these parts keeps the name n for a field of its own. An input's own normals
/// (PointXYZINormal, a PLY from another estimator) and covariances are data like any other field when hpds writes
/// none; level and frame stay reserved, since `hpds verify` and the quality tools read them as hpds's.
bool isOwnName(const std::string &n, bool with_normals, bool with_covariances) {
  if (with_covariances)
    for (const char *c : kCovarianceNames)
      if (n == c) return true;
  if (with_normals && (n == "normal_x" || n == "normal_y" || n == "normal_z" || n == "curvature")) return true;
  return n == "x" || n == "y" || n == "z" || n == "level" || n == "frame";
}
}  // namespace

std::vector<std::string> fieldsNotCarried(const PointLayout &input, bool with_normals, bool with_covariances) {
  std::vector<std::string> names;
  for (const auto &f : input.fields)
    if (isOwnName(f.name, with_normals, with_covariances) && f.name != "x" && f.name != "y" && f.name != "z")
      names.push_back(f.name);
  return names;
}

std::string fieldNotCarriedReason(const std::string &name) {
  if (name == "level") return "'level' is reserved for the level of hpds's samples";
  if (name == "frame")
    return "'frame' is reserved for hpds's frame index (hpds verify and the quality tools read it as that), even "
           "where the output has none";
  return "hpds writes its own '" + name + "'";
}

XyzType outputXyzType(const OutputConfig &output) {
  if (output.float64_xyz) return XyzType::Float64;
  return output.float32_xyz ? XyzType::Float32 : XyzType::AsInput;
}

PointLayout outputLayout(const PointLayout &input, bool with_normals, bool with_frame, bool with_covariances,
                         XyzType xyz) {
  // x y z first, then the other fields by decreasing element size (stable: listed order within a size), each at the
  // next offset that is a multiple of its element size: readers may then load any field as an aligned value, and
  // the size order leaves at most one gap (before the first 8-byte field).
  std::vector<PointField> rest;
  auto want = [&rest](const std::string &name, FieldType type, std::uint32_t count = 1) {
    rest.push_back(PointField{name, 0, type, count});
  };
  if (with_normals) {
    for (const char *name : {"normal_x", "normal_y", "normal_z", "curvature"}) want(name, FieldType::Float32);
  }
  if (with_covariances)
    for (const char *name : kCovarianceNames) want(name, FieldType::Float32);
  if (with_frame) want("frame", FieldType::UInt32);
  want("level", FieldType::UInt8);
  for (const auto &f : input.fields)
    if (!isOwnName(f.name, with_normals, with_covariances)) want(f.name, f.type, f.count);
  std::stable_sort(rest.begin(), rest.end(), [](const PointField &a, const PointField &b) {
    return fieldTypeSize(a.type) > fieldTypeSize(b.type);
  });

  PointLayout out;
  std::uint32_t alignment = 4;  // point_step a multiple of 4 at least, as PCL's point types are
  auto place = [&](const PointField &f) {
    const auto size = static_cast<std::uint32_t>(fieldTypeSize(f.type));
    alignment = std::max(alignment, size);
    out.point_step = (out.point_step + size - 1) / size * size;
    out.append(f.name, f.type, f.count);
  };
  bool input_float64 = true;
  for (const char *axis : {"x", "y", "z"}) {
    const PointField *f = input.find(axis);
    input_float64 &= f != nullptr && f->type == FieldType::Float64;
  }
  const bool doubles = xyz == XyzType::Float64 || (xyz == XyzType::AsInput && input_float64);
  const FieldType xyz_type = doubles ? FieldType::Float64 : FieldType::Float32;
  for (const char *axis : {"x", "y", "z"}) place(PointField{axis, 0, xyz_type, 1});
  for (const PointField &f : rest) place(f);
  out.point_step = (out.point_step + alignment - 1) / alignment * alignment;
  return out;
}

PointBuffer buildOutputCloud(const Hierarchy &h, const std::vector<SampleId> &ids,
                             const std::vector<SampleNormal> *normals, bool with_frame,
                             const std::vector<SampleCovariance> *covariances, XyzType xyz) {
  if (normals && normals->size() != ids.size()) throw std::invalid_argument("buildOutputCloud: one normal per id");
  if (covariances && covariances->size() != ids.size())
    throw std::invalid_argument("buildOutputCloud: one covariance per id");
  const PointLayout &in = h.recordLayout();
  PointBuffer cloud(outputLayout(in, normals != nullptr, with_frame, covariances != nullptr, xyz),
                    ids.size());
  const PointLayout &out = cloud.layout();
  // Field pairs resolved once, so the per-sample loop only copies bytes.
  std::vector<std::pair<const PointField *, const PointField *>> carried;
  for (const auto &f : in.fields)
    if (!isOwnName(f.name, normals != nullptr, covariances != nullptr))
      carried.emplace_back(out.find(f.name), &f);
  const PointField *fx = out.find("x"), *fy = out.find("y"), *fz = out.find("z"), *fl = out.find("level");
  const bool doubles = fx->type == FieldType::Float64;
  const PointField *fnx = out.find("normal_x"), *fny = out.find("normal_y"), *fnz = out.find("normal_z"),
                   *fc = out.find("curvature"), *ff = out.find("frame");
  const PointField *fcov[6] = {};
  for (int c = 0; c < 6; ++c) fcov[c] = out.find(kCovarianceNames[c]);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    std::uint8_t *rec = cloud.record(i);
    const SampleId id = ids[i];
    const double *p = h.position(id);
    if (doubles) {
      std::memcpy(rec + fx->offset, &p[0], 8);
      std::memcpy(rec + fy->offset, &p[1], 8);
      std::memcpy(rec + fz->offset, &p[2], 8);
    } else {
      const float single[3] = {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
      std::memcpy(rec + fx->offset, &single[0], 4);
      std::memcpy(rec + fy->offset, &single[1], 4);
      std::memcpy(rec + fz->offset, &single[2], 4);
    }
    rec[fl->offset] = static_cast<std::uint8_t>(h.level(id));
    if (normals) {
      const SampleNormal &n = (*normals)[i];
      std::memcpy(rec + fnx->offset, &n.normal[0], 4);
      std::memcpy(rec + fny->offset, &n.normal[1], 4);
      std::memcpy(rec + fnz->offset, &n.normal[2], 4);
      std::memcpy(rec + fc->offset, &n.curvature, 4);
    }
    if (covariances)
      for (int c = 0; c < 6; ++c) std::memcpy(rec + fcov[c]->offset, &(*covariances)[i].cov[c], 4);
    if (ff) {
      const std::uint32_t frame = h.frameIndex(id);
      std::memcpy(rec + ff->offset, &frame, 4);
    }
    if (const std::uint8_t *src = h.record(id))
      for (const auto &[dst_field, src_field] : carried) copyFieldBytes(rec, *dst_field, src, *src_field);
  }
  return cloud;
}

double positionRounding(const PointBuffer &cloud) {
  const PointLayout &l = cloud.layout();
  const PointField *f[3] = {l.find("x"), l.find("y"), l.find("z")};
  double largest = 0.0;
  for (const PointField *axis : f) {
    if (!axis || axis->type != FieldType::Float32) continue;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      float v;
      std::memcpy(&v, cloud.record(i) + axis->offset, 4);
      if (std::isfinite(v)) largest = std::max(largest, static_cast<double>(std::fabs(v)));
    }
  }
  return std::ldexp(largest, -24);
}

double largestCoordinate(const PointBuffer &cloud) {
  double largest = 0.0;
  for (const char *name : {"x", "y", "z"}) {
    const PointField *axis = cloud.layout().find(name);
    if (!axis) continue;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const double v = readAsDouble(cloud.record(i), *axis);
      if (std::isfinite(v)) largest = std::max(largest, std::fabs(v));
    }
  }
  return largest;
}

bool roundingMatters(double rounding, double output_radius) { return rounding > 0.01 * output_radius; }

std::string positionRoundingWarning(double rounding, double output_radius, const std::string &key,
                                    double input_rounding) {
  std::ostringstream out;
  if (roundingMatters(input_rounding, output_radius)) {
    // The samples are the input's positions as written, so the sampling itself holds; what is lost is the digits
    // the input never had, which advising float64 output would send the user after in vain.
    out << "the input's own float32 x y z round positions by up to " << input_rounding << " m (coordinates up to "
        << std::ldexp(input_rounding, 24) << " m), more than 1 % of the output radius " << output_radius
        << " m: the input holds no finer positions, and float64 output cannot restore them; write the input in a "
           "local frame (coordinates minus an origin near the data, kept aside), or as float64 from a source that "
           "has the digits";
    return out.str();
  }
  if (!roundingMatters(rounding, output_radius)) return {};
  out << "the output's float32 x y z round positions by up to " << rounding << " m (coordinates up to "
      << std::ldexp(rounding, 24) << " m), more than 1 % of the output radius " << output_radius
      << " m: samples may come out closer than it; set " << key << " (or work in a local frame)";
  return out.str();
}

std::string widenXyzForPoses(HpdsConfig &config, double largest_translation, const std::string &float32_key) {
  if (outputXyzType(config.output) != XyzType::AsInput || !std::isfinite(largest_translation)) return {};
  const double radius = resolveOutput(config).radius;
  const double rounding = std::ldexp(std::fabs(largest_translation), -24);
  if (!roundingMatters(rounding, radius)) return {};
  config.output.float64_xyz = true;
  std::ostringstream out;
  out << "x y z are written as float64: the poses' coordinates reach " << std::fabs(largest_translation)
      << " m, where float32 would round positions by up to " << rounding
      << " m, more than 1 % of the output radius " << radius << " m; set " << float32_key
      << " for a reader that takes float32 only (PCL's typed point clouds)";
  return out.str();
}

}  // namespace hpds
