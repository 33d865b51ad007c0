#include "normals/MapNormals.hpp"

#include <cmath>
#include <cstring>

namespace hpds {

void MapNormals::resetSlots(const std::vector<SampleId> &fresh, std::size_t id_bound) {
  if (entries_.size() < id_bound) entries_.resize(id_bound);
  for (SampleId id : fresh) entries_[id].state = kEmpty;
}

std::vector<SampleId> MapNormals::improvable(const Hierarchy &hierarchy, const std::vector<SampleId> &hit,
                                             const double viewpoint[3], double line_ratio,
                                             std::vector<float> &ranges) const {
  std::vector<SampleId> out;
  ranges.clear();
  for (SampleId id : hit) {
    const double *p = hierarchy.position(id);
    const double dx = p[0] - viewpoint[0], dy = p[1] - viewpoint[1], dz = p[2] - viewpoint[2];
    const float range = static_cast<float>(std::sqrt(dx * dx + dy * dy + dz * dz));
    const Entry *e = id < entries_.size() ? &entries_[id] : nullptr;
    if (!e || e->state != kValid || range < e->range || lineLike(e->eigen[1], e->eigen[2], line_ratio)) {
      out.push_back(id);
      ranges.push_back(range);
    }
  }
  return out;
}

void MapNormals::offer(SampleId id, const SampleNormal &normal, const LocalPca &neighbourhood, float range,
                       double line_ratio) {
  Entry &e = slot(id);
  bool take = e.state == kEmpty || (normal.valid && (e.state == kInvalid || range < e.range));
  if (normal.valid && e.state == kValid) {
    const bool was_line = lineLike(e.eigen[1], e.eigen[2], line_ratio);
    const bool is_line =
        lineLike(static_cast<float>(neighbourhood.l1), static_cast<float>(neighbourhood.l2), line_ratio);
    if (was_line != is_line) take = was_line;
  }
  if (!take) return;
  for (int a = 0; a < 3; ++a) e.normal[a] = normal.normal[a];
  e.curvature = normal.curvature;
  e.eigen[0] = static_cast<float>(neighbourhood.l0);
  e.eigen[1] = static_cast<float>(neighbourhood.l1);
  e.eigen[2] = static_cast<float>(neighbourhood.l2);
  e.range = range;
  e.state = normal.valid ? kValid : kInvalid;
}

bool MapNormals::lookup(SampleId id, SampleNormal &normal, LocalPca *neighbourhood) const {
  if (id >= entries_.size() || entries_[id].state != kValid) return false;
  const Entry &e = entries_[id];
  for (int a = 0; a < 3; ++a) normal.normal[a] = e.normal[a];
  normal.curvature = e.curvature;
  normal.valid = true;
  if (neighbourhood) {
    for (int a = 0; a < 3; ++a) neighbourhood->normal[a] = e.normal[a];
    neighbourhood->l0 = e.eigen[0];
    neighbourhood->l1 = e.eigen[1];
    neighbourhood->l2 = e.eigen[2];
    neighbourhood->valid = true;
  }
  return true;
}

void MapNormals::save(SampleId id, std::uint8_t *out) const {
  const Entry e = id < entries_.size() ? entries_[id] : Entry{};
  std::memcpy(out, e.normal, 12);
  std::memcpy(out + 12, &e.curvature, 4);
  std::memcpy(out + 16, e.eigen, 12);
  std::memcpy(out + 28, &e.range, 4);
  out[32] = e.state;
}

bool MapNormals::restore(SampleId id, const std::uint8_t *in) {
  Entry e;
  std::memcpy(e.normal, in, 12);
  std::memcpy(&e.curvature, in + 12, 4);
  std::memcpy(e.eigen, in + 16, 12);
  std::memcpy(&e.range, in + 28, 4);
  e.state = in[32];
  if (e.state > kValid) return false;
  // A kept entry was seen from a finite range, and a valid one is a unit normal; anything else would reach the
  // outputs as garbage.
  if (e.state != kEmpty && !(e.range >= 0.f && std::isfinite(e.range))) return false;
  if (e.state == kValid) {
    const double n2 = double(e.normal[0]) * e.normal[0] + double(e.normal[1]) * e.normal[1] +
                      double(e.normal[2]) * e.normal[2];
    if (!(std::fabs(n2 - 1.0) < 1e-3) || !std::isfinite(e.curvature) || !std::isfinite(e.eigen[0]) ||
        !std::isfinite(e.eigen[1]) || !std::isfinite(e.eigen[2]))
      return false;
  }
  slot(id) = e;
  return true;
}

}  // namespace hpds
