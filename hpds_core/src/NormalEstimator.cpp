#include "hpds/NormalEstimator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <utility>

#include "hpds/FrameGridIndex.hpp"
#include "hpds/LocalPca.hpp"
#include "hpds/ParallelFor.hpp"
#include "RefinedNormals.hpp"

namespace hpds {

NormalParams normalParamsFor(const HpdsConfig &config, int level) {
  NormalParams p;
  p.level = level;
  p.k = config.normals.k;
  p.radius = config.normals.radius;
  if (p.radius <= 0.0 && p.k == 0) p.radius = 2.5 * poissonRadius(config.hierarchy.cell_size, level);
  p.min_neighbors = config.normals.min_neighbors;
  p.neighborhood_level_offset = config.normals.neighborhood_level_offset;
  p.max_growth = config.normals.max_growth;
  p.threads = config.threads;
  return p;
}

namespace {
SampleNormal invalidNormal() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  return SampleNormal{{nan, nan, nan}, nan, false};
}

void gather(const Hierarchy &h, const double *q, double radius, int level,
            std::vector<std::pair<double, SampleId>> &out) {
  out.clear();
  h.forEachInBall(q, radius, level, [&](SampleId id, double d2) { out.emplace_back(d2, id); });
}
}  // namespace

std::vector<SampleNormal> estimateNormals(const Hierarchy &h, const std::vector<SampleId> &ids,
                                          const NormalParams &params) {
  if (params.neighborhood_level_offset > 0 || params.max_growth > 1.0) return estimateNormalsRefined(h, ids, params);
  std::vector<SampleNormal> result(ids.size(), invalidNormal());
  if (ids.empty()) return result;
  const int level = std::min(params.level, h.maxDepth());
  const double max_radius = 2.0 * h.cellSize();

  // Fixed radius: the union samples of levels 0..level near the queried ids are bucketed once into cells of edge
  // `radius` (a grid neighbourhood over the hierarchy's samples, contiguous in memory), so a query reads 27
  // buckets instead of walking every level's cells through the hash.
  std::vector<double> xyz;
  std::vector<std::uint32_t> self;  // index of ids[i] in xyz
  std::unique_ptr<FrameGridIndex> index;
  if (params.radius > 0.0) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (SampleId id : ids)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], h.position(id)[a] - params.radius);
        hi[a] = std::max(hi[a], h.position(id)[a] + params.radius);
      }
    std::vector<SampleId> inside;
    for (SampleId id : h.samplesUpTo(level)) {
      const double *p = h.position(id);
      if (p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1] && p[2] >= lo[2] && p[2] <= hi[2])
        inside.push_back(id);
    }
    // Centres: a queried sample of the union is found in `inside` (ascending ids); one of a finer level is not a
    // neighbour of anything, so it gets a centre slot after the indexed points.
    self.resize(ids.size());
    std::size_t extra = 0;
    for (std::size_t i = 0; i < ids.size(); ++i) {
      const auto it = std::lower_bound(inside.begin(), inside.end(), ids[i]);
      self[i] = (it != inside.end() && *it == ids[i]) ? static_cast<std::uint32_t>(it - inside.begin())
                                                      : static_cast<std::uint32_t>(inside.size() + extra++);
    }
    xyz.reserve(3 * (inside.size() + extra));
    for (SampleId id : inside) xyz.insert(xyz.end(), h.position(id), h.position(id) + 3);
    for (std::size_t i = 0; i < ids.size(); ++i)
      if (self[i] >= inside.size()) xyz.insert(xyz.end(), h.position(ids[i]), h.position(ids[i]) + 3);
    std::vector<std::uint32_t> all(inside.size());
    std::iota(all.begin(), all.end(), 0u);
    index = std::make_unique<FrameGridIndex>(xyz.data(), all, params.radius);
  }

  parallelFor(ids.size(), params.threads, [&](std::size_t b, std::size_t e) {
    std::vector<std::pair<double, SampleId>> nb;
    for (std::size_t i = b; i < e; ++i) {
      const SampleId id = ids[i];
      const double *q = h.position(id);
      nb.clear();
      if (index) {
        index->forEachNeighbor(self[i], [&](std::uint32_t j) {
          const double *p = &xyz[3 * std::size_t(j)];
          const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
          nb.emplace_back(dx * dx + dy * dy + dz * dz, static_cast<SampleId>(j));
        });
      } else {
        for (double r = 2.0 * h.radius(level);; r *= 2.0) {
          gather(h, q, r, level, nb);
          if (static_cast<int>(nb.size()) >= params.k || r >= max_radius) break;
        }
      }
      if (params.k > 0 && nb.size() > static_cast<std::size_t>(params.k)) {
        // (distance, index) pairs: ties resolve by index, so the neighbourhood is deterministic.
        std::nth_element(nb.begin(), nb.begin() + params.k, nb.end());
        nb.resize(static_cast<std::size_t>(params.k));
      }
      if (static_cast<int>(nb.size()) < params.min_neighbors) continue;
      PcaAccumulator acc(q);
      for (const auto &n : nb) acc.add(index ? &xyz[3 * std::size_t(n.second)] : h.position(n.second));
      const LocalPca pca = acc.solve(/*accurate=*/false);
      if (!pca.valid) continue;
      const std::array<float, 3> v = h.toViewpoint(id);
      const double dot = pca.normal[0] * v[0] + pca.normal[1] * v[1] + pca.normal[2] * v[2];
      const double s = dot < 0.0 ? -1.0 : 1.0;
      result[i] = SampleNormal{{static_cast<float>(s * pca.normal[0]), static_cast<float>(s * pca.normal[1]),
                                static_cast<float>(s * pca.normal[2])},
                               static_cast<float>(pca.surfaceVariation()), true};
    }
  });
  return result;
}

}  // namespace hpds
