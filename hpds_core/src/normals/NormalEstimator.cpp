#include "hpds/normals/NormalEstimator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "hpds/normals/LocalPca.hpp"
#include "hpds/points/ViewDirection.hpp"
#include "hpds/util/ParallelFor.hpp"
#include "sampling/BallGrid.hpp"
#include "normals/RefinedNormals.hpp"

namespace hpds {

NormalParams normalParamsFor(const HpdsConfig &config, int level) {
  NormalParams p;
  p.level = level;
  p.k = config.normals.k;
  p.radius = config.normals.radius;
  if (p.radius <= 0.0 && p.k == 0) p.radius = 2.5 * poissonRadius(resolveOutput(config).cell_size, level);
  p.min_neighbors = config.normals.min_neighbors;
  p.neighborhood_level_offset = config.normals.neighborhood_level_offset;
  p.max_growth = config.normals.max_growth;
  p.threads = config.threads;
  return p;
}

NormalParams covarianceNormalParams(const HpdsConfig &config, int level) {
  NormalParams p;
  p.level = level;
  p.k = config.normals.covariance_k;
  p.min_neighbors = config.normals.min_neighbors;
  p.threads = config.threads;
  return p;
}

double neighborhoodReach(const NormalParams &p, double cell_size, double level_radius) {
  const double cap = 2.0 * cell_size;  // max_radius of both estimators
  const bool refined = p.neighborhood_level_offset > 0 || p.max_growth > 1.0;
  if (!refined) {
    // A fixed radius is searched as is; the adaptive k-NN radius doubles from 2 r_level until it reaches the cap, so
    // its last search is below twice the cap (or 2 r_level itself, when that is already beyond it).
    if (p.radius > 0.0) return p.radius;
    return std::max(2.0 * level_radius, 2.0 * cap);
  }
  // Refined, k > 0: the k-th nearest is searched with radii doubling from `base` until one reaches the cap (below
  // twice the cap, or `base` itself beyond it); footprints are at most max(radius, cap) and grow to at most the cap.
  if (p.k > 0) return std::max(p.radius > 0.0 ? p.radius : 2.5 * level_radius, 2.0 * cap);
  // k = 0: the footprint is the radius (the cap without one) and grows by doubling up to min(cap, footprint * growth).
  const double footprint = p.radius > 0.0 ? p.radius : cap;
  return std::max(footprint, std::min(cap, footprint * std::max(1.0, p.max_growth)));
}

SampleNormal invalidNormal() {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  return SampleNormal{{nan, nan, nan}, nan, false};
}

SampleNormal unorientedNormal(const LocalPca &pca) {
  if (!pca.valid) return invalidNormal();
  // Points exactly on one line leave the normal's direction about the line undetermined: no normal, rather than an
  // arbitrary one. The closed-form solver puts such a line's middle eigenvalue at ~4e-9 of the largest; a real scan
  // line's range noise keeps it orders of magnitude above 1e-7 (a width of 3e-4 of its length).
  if (!(pca.l1 > 1e-7 * pca.l2)) return invalidNormal();
  return SampleNormal{{static_cast<float>(pca.normal[0]), static_cast<float>(pca.normal[1]),
                       static_cast<float>(pca.normal[2])},
                      static_cast<float>(pca.surfaceVariation()), true};
}

void orientTowardViewpoints(const Hierarchy &h, const std::vector<SampleId> &ids, std::vector<SampleNormal> &normals,
                            const std::array<double, 3> &up, int threads) {
  // A neighbourhood left on one scan line (45 % of the ground samples of the demo frames at the defaults) is spread
  // along the line and, by the range noise, along its rays: its PCA normal is perpendicular to the view, and the view
  // alone gave it either sign (a fifth of the ground faced down). So does a far plane seen at a grazing angle below
  // its normal's error. Within kTie of perpendicular, a normal near `up` (within 60 degrees) of a sample below the
  // sensor faces up: a surface below the sensor that is near horizontal can only be seen from above (ground, roofs,
  // a road going down or up; wrong only for an underside seen grazing, the lower half of a sphere's outline). Above
  // the sensor no side is the likelier one (ceilings face down, a road rising above the sensor's height up: forcing
  // either turned all of the other wrong), so the view decides there. A normal far from `up` (a wall's) keeps the
  // view's sign. kTie = 0.2 (11.5 degrees): the scan line's rays differ from the sample's own by a few degrees; on
  // real frames 0.1 left more ground facing down (VLS-128 1.2 against 0.8 %), on the synthetic scenes both are the
  // same.
  constexpr double kTie = 0.2, kNearUp = 0.5;
  // Below the direction code's error (5e-4 rad) a sample is level with the sensor, not below it.
  constexpr double kLevel = 1e-3;
  // The tests below on the unnormalised view direction u, squared, instead of a decoded unit vector: its square root
  // and divisions were most of this loop's time (1.7 % of the HDL-32 frame path, 2.4 % of the VLS-128's).
  // |n.v| < kTie is (n.u)^2 < kTie^2 |u|^2, and up.v >= kLevel is up.u >= 0 with (up.u)^2 >= kLevel^2 |u|^2.
  // Only samples within rounding of a threshold can decide otherwise than on the unit vector.
  constexpr double kTie2 = kTie * kTie, kLevel2 = kLevel * kLevel;
  parallelFor(ids.size(), threads, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      SampleNormal &n = normals[i];
      if (!n.valid) continue;
      double u[3];
      viewDirectionUnscaled(h.viewCode(ids[i]), u);
      const double uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
      const double nx = n.normal[0], ny = n.normal[1], nz = n.normal[2];
      double toward = nx * u[0] + ny * u[1] + nz * u[2];
      if (toward * toward < kTie2 * uu) {
        const double along = nx * up[0] + ny * up[1] + nz * up[2];
        const double sensor_above = u[0] * up[0] + u[1] * up[1] + u[2] * up[2];
        if (std::abs(along) >= kNearUp && sensor_above >= 0.0 && sensor_above * sensor_above >= kLevel2 * uu)
          toward = along;
      }
      if (toward < 0.0) n.normal[0] = -n.normal[0], n.normal[1] = -n.normal[1], n.normal[2] = -n.normal[2];
    }
  }, /*grain=*/std::size_t(1) << 15);  // a few ns per sample: a thread only pays for itself from tens of thousands
}

namespace {
/// The samples of `candidates` (increasing ids) inside the box around `queries` widened by r, into `inside`, and a
/// BallGrid of radius r over them for the queries; usually the queries are exactly the candidates (all output
/// samples), and then one sort serves both. `queries` must not be empty.
BallGrid gridAround(const Hierarchy &h, const std::vector<SampleId> &candidates, const std::vector<SampleId> &queries,
                    double r, std::vector<SampleId> &inside) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (SampleId id : queries) {
    const double *p = h.position(id);
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a] - r), hi[a] = std::max(hi[a], p[a] + r);
  }
  inside.clear();
  for (SampleId id : candidates) {
    const double *p = h.position(id);
    if (p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1] && p[2] >= lo[2] && p[2] <= hi[2])
      inside.push_back(id);
  }
  const double *base = h.position(0);  // a query exists, so the position array does
  const PointSet points{base, inside.data(), inside.size()};
  return BallGrid(points, inside == queries ? points : PointSet{base, queries.data(), queries.size()}, r);
}
}  // namespace

std::vector<SampleNormal> estimateNormals(const Hierarchy &h, const std::vector<SampleId> &ids,
                                          const NormalParams &params, std::vector<LocalPca> *neighbourhoods) {
  if (neighbourhoods) neighbourhoods->assign(ids.size(), LocalPca{});
  if (params.neighborhood_level_offset > 0 || params.max_growth > 1.0)
    return estimateNormalsRefined(h, ids, params, nullptr, neighbourhoods);
  std::vector<SampleNormal> result(ids.size(), invalidNormal());
  if (ids.empty()) return result;
  const int level = std::min(params.level, h.maxDepth());

  // Normals are stored unoriented and turned toward the viewpoints at the end (orientTowardViewpoints).
  auto store = [&](std::size_t i, const PcaAccumulator &acc) {
    const LocalPca pca = acc.solveNormal();
    result[i] = unorientedNormal(pca);
    if (neighbourhoods) (*neighbourhoods)[i] = pca;
  };

  if (params.radius > 0.0) {
    // Fixed radius: the union samples of levels 0..level near the queried ids and the queries, both sorted by cell
    // once (BallGrid); queries of one cell share the search of their 27 cells, and each is one pass over them.
    // Candidates in increasing id order (ties of the k nearest resolve by this index).
    std::vector<SampleId> inside;
    const BallGrid grid = gridAround(h, h.samplesUpTo(level), ids, params.radius, inside);
    const std::size_t k = params.k > 0 ? static_cast<std::size_t>(params.k) : 0;
    const std::size_t min_n = static_cast<std::size_t>(std::max(params.min_neighbors, 0));
    parallelFor(grid.cellCount(), params.threads, [&](std::size_t b, std::size_t e) {
      std::vector<std::pair<double, std::uint32_t>> nb;
      grid.visit(b, e, [&](std::size_t i, const BallView &v) {
        if (v.count < min_n || v.count < 3) return;
        PcaAccumulator acc(v.q);
        if (k == 0 || v.count <= k) {
          // Every neighbour: the sums straight from the scan, no neighbour list.
          acc.addWithin(v.xyz, v.inside, v.d2, v.count, INFINITY);  // every one is within the radius
        } else {
          // (distance, index) pairs: ties resolve by index, so the neighbourhood is deterministic.
          nb.clear();
          for (std::size_t t = 0; t < v.count; ++t) nb.emplace_back(v.d2[t], v.point[v.inside[t]]);
          std::nth_element(nb.begin(), nb.begin() + static_cast<std::ptrdiff_t>(k), nb.end());
          if (k < min_n) return;
          for (std::size_t t = 0; t < k; ++t) acc.add(h.position(inside[nb[t].second]));
        }
        store(i, acc);
      }, std::max<std::size_t>(min_n, 3));
    }, /*grain=*/1024);  // ~0.4 us per cell: a thread per ~0.4 ms of work at least
    orientTowardViewpoints(h, ids, result, params.up, params.threads);
    return result;
  }

  // Adaptive radius (k nearest, no radius): balls of radius 2 r_level, doubling until k are found or the radius
  // reaches the cap. Each round searches the still open queries at once (a BallGrid over the union samples near
  // them), as the fixed radius does: per query, a walk over the level grids cost ~16 us at k = 30.
  const double max_radius = 2.0 * h.cellSize();
  const std::size_t k = static_cast<std::size_t>(std::max(params.k, 0));
  const std::vector<SampleId> all = h.samplesUpTo(level);  // increasing ids: (distance, index) ties resolve by id
  std::vector<std::uint32_t> open(ids.size());  // positions in ids of the queries still without k neighbours
  for (std::size_t i = 0; i < ids.size(); ++i) open[i] = static_cast<std::uint32_t>(i);
  std::vector<SampleId> inside, queries;
  std::vector<std::uint8_t> resolved;
  for (double r = 2.0 * h.radius(level); !open.empty() && !all.empty(); r *= 2.0) {
    const bool last = r >= max_radius;
    queries.clear();
    for (std::uint32_t i : open) queries.push_back(ids[i]);
    const BallGrid grid = gridAround(h, all, queries, r, inside);
    resolved.assign(open.size(), 0);
    parallelFor(grid.cellCount(), params.threads, [&](std::size_t b, std::size_t e) {
      std::vector<std::pair<double, std::uint32_t>> nb;
      grid.visit(b, e, [&](std::size_t t, const BallView &v) {
        if (v.count < k && !last) return;  // the next round's larger ball
        resolved[t] = 1;
        nb.clear();
        for (std::size_t j = 0; j < v.count; ++j) nb.emplace_back(v.d2[j], v.point[v.inside[j]]);
        if (k > 0 && nb.size() > k) {
          std::nth_element(nb.begin(), nb.begin() + static_cast<std::ptrdiff_t>(k), nb.end());
          nb.resize(k);
        }
        if (nb.size() < static_cast<std::size_t>(std::max(params.min_neighbors, 0))) return;
        // Summed nearest first: the normal's last bits then depend on the neighbours alone.
        std::sort(nb.begin(), nb.end());
        PcaAccumulator acc(v.q);
        for (const auto &n : nb) acc.add(h.position(inside[n.second]));
        store(open[t], acc);
      });
    }, /*grain=*/256);
    if (last) break;  // what is left has no cell in the grid (beyond its 2^21-cell range): no neighbours
    std::size_t kept = 0;
    for (std::size_t t = 0; t < open.size(); ++t)
      if (!resolved[t]) open[kept++] = open[t];
    open.resize(kept);
  }
  orientTowardViewpoints(h, ids, result, params.up, params.threads);
  return result;
}

}  // namespace hpds
