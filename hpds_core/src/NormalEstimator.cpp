#include "hpds/NormalEstimator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "hpds/LocalPca.hpp"
#include "hpds/ParallelFor.hpp"

namespace hpds {

NormalParams normalParamsFor(const HpdsConfig &config, int level) {
  NormalParams p;
  p.level = level;
  p.k = config.normals.k;
  p.radius = config.normals.radius;
  if (p.radius <= 0.0 && p.k == 0) p.radius = 2.5 * poissonRadius(config.hierarchy.cell_size, level);
  p.min_neighbors = config.normals.min_neighbors;
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
  std::vector<SampleNormal> result(ids.size(), invalidNormal());
  const int level = std::min(params.level, h.maxDepth());
  const double max_radius = 2.0 * h.cellSize();
  parallelFor(ids.size(), params.threads, [&](std::size_t b, std::size_t e) {
    std::vector<std::pair<double, SampleId>> nb;
    for (std::size_t i = b; i < e; ++i) {
      const SampleId id = ids[i];
      const double *q = h.position(id);
      if (params.radius > 0.0) {
        gather(h, q, params.radius, level, nb);
      } else {
        for (double r = 2.0 * h.radius(level);; r *= 2.0) {
          gather(h, q, r, level, nb);
          if (static_cast<int>(nb.size()) >= params.k || r >= max_radius) break;
        }
      }
      if (params.k > 0 && nb.size() > static_cast<std::size_t>(params.k)) {
        // (distance, id) pairs: ties resolve by id, so the neighbourhood is deterministic.
        std::nth_element(nb.begin(), nb.begin() + params.k, nb.end());
        nb.resize(static_cast<std::size_t>(params.k));
      }
      if (static_cast<int>(nb.size()) < params.min_neighbors) continue;
      PcaAccumulator acc(q);
      for (const auto &n : nb) acc.add(h.position(n.second));
      const LocalPca pca = acc.solve(/*accurate=*/true);
      if (!pca.valid) continue;
      const float *v = h.toViewpoint(id);
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
