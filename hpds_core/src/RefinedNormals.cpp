// Why this variant exists (measured by bench/normal_accuracy against exact normals):
// - One Poisson-disk level keeps one raw point per r_D, so PCA over it sees the full range noise, where a voxel
//   centroid has averaged it away. The finer levels of the same hierarchy hold the averaging points; the footprint
//   stays the output level's, so the neighbourhood keeps the level's isotropic extent.
// - Where the input is sparser than r_D (far ground, few beams) a level holds whole scan lines and a neighbourhood
//   may lie on one of them: its smallest-eigenvalue direction is then arbitrary about the line. Doubling the
//   footprint until it spans two lines is what choosing a coarser level locally amounts to.
#include "RefinedNormals.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <utility>

#include "hpds/FrameGridIndex.hpp"
#include "hpds/LocalPca.hpp"
#include "hpds/ParallelFor.hpp"

namespace hpds {

std::vector<SampleNormal> estimateNormalsRefined(const Hierarchy &h, const std::vector<SampleId> &ids,
                                                 const NormalParams &params) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<SampleNormal> result(ids.size(), SampleNormal{{nan, nan, nan}, nan, false});
  if (ids.empty()) return result;
  const int level = std::min(params.level, h.maxDepth());
  const int finest = std::min(level + std::max(0, params.neighborhood_level_offset), h.maxDepth());
  const double max_radius = 2.0 * h.cellSize();
  const double growth = std::max(1.0, params.max_growth);
  const double base = params.radius > 0.0 ? params.radius : 2.5 * h.radius(level);

  // Points: samples of levels 0..finest near the queried ids (a map may hold far more than a query needs), then the
  // queried ids themselves as centre slots, as in estimateNormals.
  const double margin = std::min(max_radius, base * growth * 4.0);
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (SampleId id : ids)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], h.position(id)[a] - margin);
      hi[a] = std::max(hi[a], h.position(id)[a] + margin);
    }
  std::vector<double> xyz;
  std::vector<std::uint32_t> indexed, indexed_coarse;  // levels 0..finest, and 0..level for k-NN footprints
  for (SampleId id : h.samplesUpTo(finest)) {
    const double *p = h.position(id);
    if (p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] || p[2] < lo[2] || p[2] > hi[2]) continue;
    const auto j = static_cast<std::uint32_t>(xyz.size() / 3);
    indexed.push_back(j);
    if (h.level(id) <= level) indexed_coarse.push_back(j);
    xyz.insert(xyz.end(), p, p + 3);
  }
  const std::size_t centres = xyz.size() / 3;
  for (SampleId id : ids) xyz.insert(xyz.end(), h.position(id), h.position(id) + 3);

  // One bucket grid per doubling of the base radius, so a grown query still reads only 27 buckets; the coarse ones
  // find k-NN footprints without walking the level grids cell by cell (slow where samples are sparse).
  std::vector<std::unique_ptr<FrameGridIndex>> grids, coarse_grids;
  for (double r = base;; r *= 2.0) {
    grids.push_back(std::make_unique<FrameGridIndex>(xyz.data(), indexed, r));
    if (params.k > 0) coarse_grids.push_back(std::make_unique<FrameGridIndex>(xyz.data(), indexed_coarse, r));
    if (r >= max_radius) break;
  }
  auto gridFor = [&](double rho) {
    std::size_t g = 0;
    double r = base;
    while (r < rho && g + 1 < grids.size()) r *= 2.0, ++g;
    return g;
  };

  parallelFor(ids.size(), params.threads, [&](std::size_t b, std::size_t e) {
    std::vector<double> dist_scratch;
    for (std::size_t i = b; i < e; ++i) {
      const SampleId id = ids[i];
      const double *q = h.position(id);
      const auto centre = static_cast<std::uint32_t>(centres + i);
      // 1. Footprint at the output level: the radius, or the k-th nearest sample of levels 0..level within it.
      double rho = params.radius > 0.0 ? params.radius : max_radius;
      if (params.k > 0) {
        std::vector<double> &d2s = dist_scratch;
        double r = base;
        for (std::size_t g = 0; g < coarse_grids.size(); ++g, r *= 2.0) {
          d2s.clear();
          coarse_grids[g]->forEachNeighbor(centre, [&](std::uint32_t j) {
            const double *p = &xyz[3 * std::size_t(j)];
            const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
            d2s.push_back(dx * dx + dy * dy + dz * dz);
          });
          if (static_cast<int>(d2s.size()) >= params.k || (params.radius > 0.0 && r >= params.radius)) break;
        }
        if (d2s.size() >= static_cast<std::size_t>(params.k)) {
          std::nth_element(d2s.begin(), d2s.begin() + (params.k - 1), d2s.end());
          // Just past the k-th distance, so that neighbour itself is inside the strict ball.
          rho = std::min(rho, std::sqrt(d2s[static_cast<std::size_t>(params.k - 1)]) * (1.0 + 1e-9) + 1e-12);
        } else {
          rho = std::min(rho, r);
        }
      }
      const double limit = std::min(max_radius, rho * growth);
      // 2. Every sample of levels 0..finest inside the footprint. A line-like result grows the footprint; a grown
      //    neighbourhood is only taken if it resolves the line and is flat (RMS distance to its plane <=
      //    max_plane_rms * radius): a ball reaching from a scan line on the ground into a wall would average two
      //    surfaces, and a longer piece of the same line is no better than the first.
      LocalPca chosen;
      bool have = false;
      for (;;) {
        const FrameGridIndex &grid = *grids[gridFor(rho)];
        const double r2 = rho * rho;
        PcaAccumulator acc(q);
        grid.forEachNeighbor(centre, [&](std::uint32_t j) {
          const double *p = &xyz[3 * std::size_t(j)];
          const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
          if (dx * dx + dy * dy + dz * dz < r2) acc.add(p);
        });
        const LocalPca pca = acc.solve(/*accurate=*/false);
        const bool enough = static_cast<int>(acc.count()) >= params.min_neighbors && pca.valid;
        const bool flat = pca.l0 <= params.max_plane_rms * params.max_plane_rms * r2;
        const bool not_line = pca.l1 >= params.line_ratio * pca.l2;
        if (enough && (!have || (flat && not_line))) {
          chosen = pca;
          have = true;
          if (not_line) break;
        }
        if ((have && !flat) || rho * 2.0 > limit * (1.0 + 1e-12)) break;
        rho *= 2.0;
      }
      if (!have) continue;
      const std::array<float, 3> v = h.toViewpoint(id);
      const double dot = chosen.normal[0] * v[0] + chosen.normal[1] * v[1] + chosen.normal[2] * v[2];
      const double s = dot < 0.0 ? -1.0 : 1.0;
      result[i] = SampleNormal{{static_cast<float>(s * chosen.normal[0]), static_cast<float>(s * chosen.normal[1]),
                                static_cast<float>(s * chosen.normal[2])},
                               static_cast<float>(chosen.surfaceVariation()), true};
    }
  });
  return result;
}

}  // namespace hpds
