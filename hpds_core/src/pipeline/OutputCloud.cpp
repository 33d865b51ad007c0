#include "hpds/pipeline/OutputCloud.hpp"

#include <cstring>
#include <stdexcept>

namespace hpds {

namespace {
bool isOwnName(const std::string &n) {
  return n == "x" || n == "y" || n == "z" || n == "level" || n == "normal_x" || n == "normal_y" || n == "normal_z" ||
         n == "curvature" || n == "frame";
}
}  // namespace

PointLayout outputLayout(const PointLayout &input, bool with_normals, bool with_frame) {
  PointLayout out;
  out.append("x", FieldType::Float32);
  out.append("y", FieldType::Float32);
  out.append("z", FieldType::Float32);
  out.append("level", FieldType::UInt8);
  if (with_normals) {
    out.append("normal_x", FieldType::Float32);
    out.append("normal_y", FieldType::Float32);
    out.append("normal_z", FieldType::Float32);
    out.append("curvature", FieldType::Float32);
  }
  if (with_frame) out.append("frame", FieldType::UInt32);
  for (const auto &f : input.fields)
    if (!isOwnName(f.name)) out.append(f.name, f.type, f.count);
  return out;
}

PointBuffer buildOutputCloud(const Hierarchy &h, const std::vector<SampleId> &ids,
                             const std::vector<SampleNormal> *normals, bool with_frame) {
  if (normals && normals->size() != ids.size()) throw std::invalid_argument("buildOutputCloud: one normal per id");
  const PointLayout &in = h.recordLayout();
  PointBuffer cloud(outputLayout(in, normals != nullptr, with_frame), ids.size());
  const PointLayout &out = cloud.layout();
  // Field pairs resolved once, so the per-sample loop only copies bytes.
  std::vector<std::pair<const PointField *, const PointField *>> carried;
  for (const auto &f : in.fields)
    if (!isOwnName(f.name)) carried.emplace_back(out.find(f.name), &f);
  const PointField *fx = out.find("x"), *fy = out.find("y"), *fz = out.find("z"), *fl = out.find("level");
  const PointField *fnx = out.find("normal_x"), *fny = out.find("normal_y"), *fnz = out.find("normal_z"),
                   *fc = out.find("curvature"), *ff = out.find("frame");
  for (std::size_t i = 0; i < ids.size(); ++i) {
    std::uint8_t *rec = cloud.record(i);
    const SampleId id = ids[i];
    const double *p = h.position(id);
    const float xyz[3] = {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
    std::memcpy(rec + fx->offset, &xyz[0], 4);
    std::memcpy(rec + fy->offset, &xyz[1], 4);
    std::memcpy(rec + fz->offset, &xyz[2], 4);
    rec[fl->offset] = static_cast<std::uint8_t>(h.level(id));
    if (normals) {
      const SampleNormal &n = (*normals)[i];
      std::memcpy(rec + fnx->offset, &n.normal[0], 4);
      std::memcpy(rec + fny->offset, &n.normal[1], 4);
      std::memcpy(rec + fnz->offset, &n.normal[2], 4);
      std::memcpy(rec + fc->offset, &n.curvature, 4);
    }
    if (ff) {
      const std::uint32_t frame = h.frameIndex(id);
      std::memcpy(rec + ff->offset, &frame, 4);
    }
    if (const std::uint8_t *src = h.record(id))
      for (const auto &[dst_field, src_field] : carried) copyFieldBytes(rec, *dst_field, src, *src_field);
  }
  return cloud;
}

}  // namespace hpds
