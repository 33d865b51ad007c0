// Why this variant exists (measured by bench/normal_accuracy against exact normals):
// - One Poisson-disk level keeps one raw point per r_D, so PCA over it sees the full range noise, where a voxel
//   centroid has averaged it away. The finer levels of the same hierarchy hold the averaging points; the footprint
//   stays the output level's, so the neighbourhood keeps the level's isotropic extent.
// - Where the input is sparser than r_D (far ground, few beams) a level holds whole scan lines and a neighbourhood
//   may lie on one of them: its smallest-eigenvalue direction is then arbitrary about the line. Doubling the
//   footprint until it spans two lines is what choosing a coarser level locally amounts to.
#include "normals/RefinedNormals.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <utility>

#include "hpds/normals/LocalPca.hpp"
#include "hpds/util/ParallelFor.hpp"
#include "sampling/BallGrid.hpp"
#include "sampling/KeyRadixSort.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace hpds {

std::vector<double> refinedSearchRadii(const Hierarchy &h, const NormalParams &params) {
  const int level = std::min(params.level, h.maxDepth());
  const double max_radius = 2.0 * h.cellSize();
  const double base = params.radius > 0.0 ? params.radius : 2.5 * h.radius(level);
  std::vector<double> radii;
  for (double r = base;; r *= 2.0) {
    radii.push_back(r);
    if (r >= max_radius) break;
  }
  return radii;
}

std::unique_ptr<BallGridPoints> AveragingGrids::make(std::size_t g, const PointSet &points,
                                                     const BallGridPoints *first) const {
  if (g == 0 || g >= radii.size()) return std::make_unique<BallGridPoints>(points, radii.at(g), lo, hi);
  int doublings = 0;
  double r = radii[0];
  while (r < radii[g] && doublings < 30) r *= 2.0, ++doublings;
  if (r != radii[g]) return std::make_unique<BallGridPoints>(points, radii[g], lo, hi);
  if (!by_radius.empty() && by_radius[0]) first = by_radius[0].get();
  if (first) return std::make_unique<BallGridPoints>(*first, doublings, points, lo, hi);
  const BallGridPoints made(points, radii[0], lo, hi);
  return std::make_unique<BallGridPoints>(made, doublings, points, lo, hi);
}

std::size_t AveragingGrids::memUsage() const {
  std::size_t bytes = 0;
  for (const auto &g : by_radius)
    if (g) bytes += g->memUsage();
  return bytes;
}

namespace {

/// What a refined estimate needs besides its queries.
struct RefinedSetup {
  NormalParams params;
  double max_radius = 0.0;     ///< twice the level-0 cell edge: no footprint grows past it
  std::vector<double> radii;   ///< refinedSearchRadii
  PointSet fine;               ///< the averaging points
  bool over_centroids = false; ///< `fine` is the frame's centroids, searched through `grids` (or over their box)
  const AveragingGrids *grids = nullptr;
  AveragingGrids *keep = nullptr;  ///< over centroids: grids sorted here are kept in it for later calls
  /// Over centroids without `keep`: the first grid when this estimate had to sort it, for its later rounds' grids to
  /// be grouped from (a setup lives for one estimate).
  mutable std::unique_ptr<BallGridPoints> first_here;
};

/// Queries: element i at base + 3 * index[i].
struct QuerySet {
  const double *base;
  const std::uint32_t *index;
  std::size_t size;
};

std::size_t gridFor(const RefinedSetup &s, double rho) {
  std::size_t g = 0;
  while (s.radii[g] < rho && g + 1 < s.radii.size()) ++g;
  return g;
}

/// Per-thread scratch of a sweep's callbacks, reused from query to query.
struct SweepScratch {
  std::vector<double> values;
  std::vector<std::uint32_t> slots;
};

/// Calls fn(i, view, scratch) for the queries subset[...] with their neighbours of `points` within `radius`.
template <typename Fn>
void sweep(const RefinedSetup &s, const PointSet &points, const QuerySet &q, const std::vector<std::uint32_t> &subset,
           double radius, Fn &&fn) {
  std::vector<std::uint32_t> qidx(subset.size());
  for (std::size_t t = 0; t < subset.size(); ++t) qidx[t] = q.index[subset[t]];
  const PointSet queries{q.base, qidx.data(), qidx.size()};
  std::optional<BallGridPoints> sorted_here;
  std::unique_ptr<BallGridPoints> made_here;
  const BallGridPoints *ahead = nullptr;
  if (s.over_centroids && points == s.fine && s.grids) {
    const std::size_t grids = std::min(s.grids->radii.size(), s.grids->by_radius.size());
    std::size_t g = 0;
    while (g < grids && s.grids->radii[g] != radius) ++g;
    if (g < grids && s.grids->by_radius[g]) {
      ahead = s.grids->by_radius[g].get();
    } else if (g < grids && s.keep == s.grids) {
      // The first grid is kept too: the later ones are grouped from it.
      if (g > 0 && !s.keep->by_radius[0]) s.keep->by_radius[0] = s.keep->make(0, points);
      s.keep->by_radius[g] = s.keep->make(g, points);
      ahead = s.keep->by_radius[g].get();
    } else if (g < grids) {
      // Not kept across calls, but across this estimate's rounds: the first grid, which the later ones group from.
      if (!s.grids->by_radius[0] && !s.first_here) s.first_here = s.grids->make(0, points);
      if (g == 0 && !s.grids->by_radius[0]) {
        ahead = s.first_here.get();
      } else {
        made_here = s.grids->make(g, points, s.first_here.get());
        ahead = made_here.get();
      }
    } else {
      ahead = &sorted_here.emplace(points, radius, s.grids->lo, s.grids->hi);
    }
  }
  std::optional<BallGrid> grid_storage;
  const BallGrid &grid = ahead ? grid_storage.emplace(*ahead, queries) : grid_storage.emplace(points, queries, radius);
  // The later rounds hold few queries (HDL-32: 1 578 and 534 of 8 873) with wide footprints, microseconds each:
  // threads from 32 cells on, and 8 chunks per thread against the uneven cost (2 threads, HDL-32: those rounds
  // 0.82 -> 0.50 and 0.75 -> 0.51 ms against a thread per 256 cells in 4 chunks each).
  parallelFor(grid.cellCount(), s.params.threads, [&](std::size_t b, std::size_t e) {
    SweepScratch scratch;
    grid.visit(b, e, [&](std::size_t t, const BallView &v) { fn(subset[t], v, scratch); });
  }, /*grain=*/32, /*chunks_per_thread=*/8);
}

/// The growth's two tests of a neighbourhood of radius^2 `r2`, shared by the grown balls and the plane through a
/// scan line: one scan line (l1 < line_ratio * l2), and flat (RMS distance to its plane <= max_plane_rms * radius).
bool lineLike(const LocalPca &pca, const NormalParams &params) { return pca.l1 < params.line_ratio * pca.l2; }
bool flat(const LocalPca &pca, const NormalParams &params, double r2) {
  return pca.l0 <= params.max_plane_rms * params.max_plane_rms * r2;
}

/// A monotone stand-in for the angle of (a, b) modulo pi, in [0, 2): 0, 1 and 2 at 0, 90 and 180 degrees (within
/// 4 degrees of linear in between); one division instead of atan2, which was most of planeThroughLine's cost.
/// NaN (a = b = 0) gives 0.
inline double diamondAngle(double a, double b) {
#if defined(__SSE2__)
  // With masks in SSE registers, the scalar branches' exact operations: the signs of a and b follow no pattern
  // from point to point, and GCC kept the ternaries below as branches (mispredicted about every other point: a
  // third of planeThroughLine's time).
  const __m128d A = _mm_set_sd(a), B = _mm_set_sd(b), zero = _mm_setzero_pd(), sign = _mm_set_sd(-0.0);
  const __m128d flip = _mm_or_pd(_mm_cmplt_sd(B, zero), _mm_and_pd(_mm_cmpeq_sd(B, zero), _mm_cmplt_sd(A, zero)));
  const __m128d fa = _mm_xor_pd(A, _mm_and_pd(flip, sign)), fb = _mm_xor_pd(B, _mm_and_pd(flip, sign));
  const __m128d first = _mm_cmpge_sd(fa, zero);
  auto select = [](__m128d m, __m128d x, __m128d y) { return _mm_or_pd(_mm_and_pd(m, x), _mm_andnot_pd(m, y)); };
  const __m128d ratio = _mm_div_sd(select(first, fb, fa), select(first, _mm_add_sd(fa, fb), _mm_sub_sd(fb, fa)));
  const __m128d angle = select(first, ratio, _mm_sub_sd(_mm_set_sd(1.0), ratio));
  return _mm_cvtsd_f64(_mm_max_sd(angle, zero));  // MAXSD gives its second operand for NaN
#else
  const bool flip = b < 0.0 || (b == 0.0 && a < 0.0);
  const double fa = flip ? -a : a, fb = flip ? -b : b;
  const bool first = fa >= 0.0;
  const double ratio = (first ? fb : fa) / (first ? fa + fb : fb - fa);
  const double angle = first ? ratio : 1.0 - ratio;
  return angle > 0.0 ? angle : 0.0;
#endif
}
/// The unit direction (c, s) of diamond angle p.
void diamondDirection(double p, double &c, double &s) {
  const double a = 1.0 - p, b = p <= 1.0 ? p : 2.0 - p;
  const double n = std::hypot(a, b);
  c = a / n, s = b / n;
}

/// A neighbourhood left on one scan line whose grown ball is not flat: the ball reached another surface (the ground
/// below a wall's ring, a box beside it) before it held a second line of this one. The line pins the plane up to a
/// rotation about it; the plane through the line that points of the ball on both sides of it support is the
/// surface the line lies on (a wall's rings above and below), where a flat ball would have been. Measured on
/// planar_urban in scan mode: 7 % of the wall samples stopped so, nearly all more than 30 degrees off.
/// `rho`: the grown ball's radius; the line is the previous footprint's ball (radius rho / 2). The plane must hold
/// params.min_neighbors points, at least kSide of them off the line on each side, and pass the growth's own tests
/// (not lineLike, flat); nullopt otherwise. Of planes tied on votes, the flattest that passes.
std::optional<LocalPca> planeThroughLine(const BallView &v, double rho, const NormalParams &params,
                                         SweepScratch &scratch) {
  constexpr int kBins = 36;         // 5-degree bins of the plane's angle about the line
  constexpr std::size_t kSide = 3;  // points off the line on each side
  const double r2 = rho * rho, inner_r2 = 0.25 * r2;
  // The line: the principal axis of the inner ball, through its mean (offsets from the query are within the ball,
  // so one pass of sums loses nothing that matters here). It held a line-like neighbourhood, so >= 3 points; on a
  // noise-free line l1 is 0 and the PCA not valid as a plane, but l2 still gives the axis.
  PcaAccumulator inner(v.q);
  inner.addWithin(v.xyz, v.inside, v.d2, v.count, inner_r2);
  const LocalPca spread = inner.solveNormal();
  double axis[3], mean[3];
  if (!(spread.l2 > 0.0) || !inner.eigenvector(spread.l2, axis)) return std::nullopt;
  inner.mean(mean);
  const Eigen::Vector3d line(axis[0], axis[1], axis[2]);
  const Eigen::Vector3d u = line.unitOrthogonal(), w = line.cross(u);
  // Off the line: beyond three times its own scatter across it (range noise along the rays).
  const double off = std::max(3.0 * std::sqrt(spread.l1), 0.1 * rho), off2 = off * off;
  // Each point of the ball as (a, b), its offset from the line in the basis u, w (kept for the refit below); those
  // off the line vote for the angle of the plane through it. Branch-free, as which points are off the line follows
  // no pattern.
  scratch.values.resize(3 * v.count);
  scratch.slots.resize(v.count);
  double *ab = scratch.values.data(), *d2s = ab + 2 * v.count;
  std::uint32_t *slots = scratch.slots.data();
  // Four histograms, point t voting in t % 4: neighbours mostly vote for the same bin, and one histogram's
  // increments would wait on each other through memory.
  std::uint32_t votes[4][kBins] = {};
  const double qx = v.q[0] + mean[0], qy = v.q[1] + mean[1], qz = v.q[2] + mean[2];
  for (std::size_t t = 0; t < v.count; ++t) {
    const double *p = v.xyz + 3 * std::size_t(v.inside[t]);
    const double dx = p[0] - qx, dy = p[1] - qy, dz = p[2] - qz;
    const double a = dx * u.x() + dy * u.y() + dz * u.z(), b = dx * w.x() + dy * w.y() + dz * w.z();
    ab[2 * t] = a, ab[2 * t + 1] = b;
    // (0, 0) is on the line: its bin is never counted, but the conversion must stay defined (diamondAngle: 0).
    const double angle = diamondAngle(a, b);
    const std::size_t bin = std::min<std::size_t>(kBins - 1, static_cast<std::size_t>(angle * (kBins / 2.0)));
    votes[t & 3][bin] += v.d2[t] < r2 && a * a + b * b >= off2 ? 1 : 0;
  }
  std::array<std::size_t, kBins> bins{};
  for (std::size_t k = 0; k < kBins; ++k) bins[k] = votes[0][k] + votes[1][k] + votes[2][k] + votes[3][k];
  // Two adjacent bins (cyclic: the angle is modulo pi) with the most votes. On a tie, the window whose plane refits
  // flattest (smallest l0): the line's axis has an arbitrary sign, which mirrors the bins, so "the first" would
  // depend on it. Ties are common: a plane whose votes fall in one bin ties the two windows on either side of it.
  std::size_t best_count = 0;
  for (std::size_t k = 0; k < kBins; ++k) best_count = std::max(best_count, bins[k] + bins[(k + 1) % kBins]);
  if (best_count < 2 * kSide) return std::nullopt;
  const double band = 2.0 * params.max_plane_rms * rho;
  std::optional<LocalPca> chosen;
  for (std::size_t k = 0; k < kBins; ++k) {
    if (bins[k] + bins[(k + 1) % kBins] != best_count) continue;
    // The plane holds the line and the direction (c, sn) in u, w; its normal is line x that direction, (-sn, c).
    double c = 0.0, sn = 0.0;
    diamondDirection(static_cast<double>(k + 1) * (2.0 / kBins), c, sn);
    // The points of the ball within the band (in visiting order, as the sums need).
    std::size_t above = 0, below = 0, n = 0;
    for (std::size_t t = 0; t < v.count; ++t) {
      const double a = ab[2 * t], b = ab[2 * t + 1];
      const bool in = v.d2[t] < r2 && std::abs(c * b - sn * a) <= band, off_line = a * a + b * b >= off2;
      const bool up = c * a + sn * b > 0.0;
      slots[n] = v.inside[t], d2s[n] = v.d2[t];
      n += in ? 1 : 0;
      above += in && off_line && up ? 1 : 0;
      below += in && off_line && !up ? 1 : 0;
    }
    if (above < kSide || below < kSide || static_cast<int>(n) < params.min_neighbors) continue;
    PcaAccumulator acc(v.q);
    acc.addWithin(v.xyz, slots, d2s, n, r2);
    const LocalPca pca = acc.solveNormal();
    if (!pca.valid || !flat(pca, params, r2) || lineLike(pca, params)) continue;
    if (!chosen || pca.l0 < chosen->l0) chosen = pca;
  }
  return chosen;
}

/// Step 2 of the estimator for the queries `pending` (indices into q), footprints starting at rho[i]: every
/// averaging point inside the footprint; a line-like result grows the footprint; a grown neighbourhood is only
/// taken if it resolves the line and is flat (RMS distance to its plane <= max_plane_rms * radius): a ball reaching
/// from a scan line on the ground into a wall would average two surfaces, and a longer piece of the same line is no
/// better than the first. Where the first grown ball that is not flat leaves a line, the plane through the line
/// that the ball supports on both sides is taken instead (planeThroughLine). Each query's outcome depends on its
/// own position and footprint only.
void growNeighbourhoods(const RefinedSetup &s, const QuerySet &q, std::vector<std::uint32_t> pending,
                        std::vector<double> &rho, LocalPca *chosen, std::uint8_t *have) {
  const NormalParams &params = s.params;
  const double growth = std::max(1.0, params.max_growth);
  std::vector<double> limit(q.size);
  for (std::uint32_t i : pending) limit[i] = std::min(s.max_radius, rho[i] * growth);
  std::vector<std::uint8_t> again(q.size, 0);
  std::vector<std::uint32_t> round;
  while (!pending.empty()) {
    std::size_t g = s.radii.size();
    for (std::uint32_t i : pending) g = std::min(g, gridFor(s, rho[i]));
    round.clear();
    double radius = s.radii[g];
    for (std::uint32_t i : pending)
      if (gridFor(s, rho[i]) == g) {
        round.push_back(i);
        radius = std::max(radius, rho[i]);
        again[i] = 0;
      } else {
        again[i] = 1;  // a later round
      }
    sweep(s, s.fine, q, round, radius, [&](std::uint32_t i, const BallView &v, SweepScratch &scratch) {
      const double r2 = rho[i] * rho[i];
      PcaAccumulator acc(v.q);
      acc.addWithin(v.xyz, v.inside, v.d2, v.count, r2);
      // Too few neighbours: nothing is chosen and only the limit stops growth, whatever the PCA says (a
      // neighbourhood only gains points as it grows, so no earlier round chose one either), so it is not solved.
      // Most first rounds at fine levels are such: a footprint of a few centimetres holds a short piece of one line.
      bool settled = false;
      if (static_cast<int>(acc.count()) >= params.min_neighbors) {
        const LocalPca pca = acc.solveNormal();
        const bool is_flat = flat(pca, params, r2);
        const bool not_line = !lineLike(pca, params);
        const bool had_line = have[i] && lineLike(chosen[i], params);
        if (pca.valid && (!have[i] || (is_flat && not_line))) {
          chosen[i] = pca;
          have[i] = 1;
          if (not_line) return;
        }
        settled = have[i] && !is_flat;
        // A scan line whose grown ball reached another surface first: the plane through it, if one is supported.
        if (settled && had_line)
          if (const std::optional<LocalPca> plane = planeThroughLine(v, rho[i], params, scratch)) {
            chosen[i] = *plane;
            return;
          }
      }
      if (settled || rho[i] * 2.0 > limit[i] * (1.0 + 1e-12)) return;
      rho[i] *= 2.0;
      again[i] = 1;
    });
    pending.erase(std::remove_if(pending.begin(), pending.end(), [&](std::uint32_t i) { return !again[i]; }),
                  pending.end());
  }
}

/// The queries ids[0..n) in the order of their cells of edge `edge` (x-major, z fastest, as BallGrid sorts them):
/// order[j] is the index into ids of the j-th. The sweeps visit queries in cell order and keep per-query state
/// (footprint, chosen PCA) by query index; indexed in sample id order, which is the random insertion order, every
/// visit was a cache miss on that state (VLS-128 at the defaults: a third of the sweep's time waited on it).
std::vector<std::uint32_t> cellOrder(const double *base, const std::vector<SampleId> &ids, double edge) {
  std::vector<KeyedIndex> keyed(ids.size());
  double lo[3] = {INFINITY, INFINITY, INFINITY};
  for (SampleId id : ids)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], base[3 * std::size_t(id) + a]);
  // 21 bits per axis; beyond that (wide data) the order is only less local, never wrong: it is an order of visits.
  constexpr double kTop = double((1u << 21) - 1);
  const double inv = 1.0 / edge;
  std::uint64_t widest = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const double *p = base + 3 * std::size_t(ids[i]);
    std::uint64_t c[3];
    for (int a = 0; a < 3; ++a) {
      const double f = (p[a] - lo[a]) * inv;
      c[a] = f >= 0.0 && f < kTop ? static_cast<std::uint64_t>(f) : f >= kTop ? std::uint64_t(kTop) : 0;
    }
    keyed[i] = KeyedIndex{c[0] << 42 | c[1] << 21 | c[2], static_cast<std::uint32_t>(i)};
    widest |= keyed[i].key;
  }
  sortByKeyStable(keyed, bitWidth(widest));
  std::vector<std::uint32_t> order(ids.size());
  for (std::size_t j = 0; j < keyed.size(); ++j) order[j] = keyed[j].index;
  return order;
}

}  // namespace

void refinedNeighbourhoodsOverCentroids(const double *base, const std::uint32_t *index, std::size_t count,
                                        const NormalParams &params, double cell_size,
                                        const std::vector<double> &centroids, AveragingGrids &grids,
                                        LocalPca *chosen, std::uint8_t *have) {
  if (params.k != 0 || !(params.radius > 0.0))
    throw std::invalid_argument("refinedNeighbourhoodsOverCentroids: needs a fixed footprint (k 0, radius > 0)");
  if (count == 0) return;
  RefinedSetup s;
  s.params = params;
  s.params.threads = 1;
  s.max_radius = 2.0 * cell_size;
  s.radii = grids.radii;
  s.fine = PointSet{centroids.data(), nullptr, centroids.size() / 3};
  s.over_centroids = true;
  s.grids = &grids;
  s.keep = &grids;
  std::vector<double> rho(count, params.radius);
  std::vector<std::uint32_t> pending(count);
  for (std::size_t i = 0; i < count; ++i) {
    pending[i] = static_cast<std::uint32_t>(i);
    have[i] = 0;
  }
  growNeighbourhoods(s, QuerySet{base, index, count}, std::move(pending), rho, chosen, have);
}

std::vector<SampleNormal> estimateNormalsRefined(const Hierarchy &h, const std::vector<SampleId> &ids,
                                                 const NormalParams &params, const std::vector<double> *centroids,
                                                 std::vector<LocalPca> *neighbourhoods, const AveragingGrids *grids,
                                                 const KnownNeighbourhoods *known) {
  std::vector<SampleNormal> result(ids.size(), invalidNormal());
  if (ids.empty()) return result;
  if (known && (params.k != 0 || !centroids))
    throw std::invalid_argument("estimateNormalsRefined: known neighbourhoods need centroids and a fixed footprint");
  const int level = std::min(params.level, h.maxDepth());
  const int finest = std::min(level + std::max(0, params.neighborhood_level_offset), h.maxDepth());
  RefinedSetup s;
  s.params = params;
  s.max_radius = 2.0 * h.cellSize();
  s.radii = refinedSearchRadii(h, params);
  s.over_centroids = centroids != nullptr;
  s.grids = centroids ? grids : nullptr;
  const double growth = std::max(1.0, params.max_growth);
  const double base = params.radius > 0.0 ? params.radius : 2.5 * h.radius(level);
  const double *hbase = h.position(0);
  // The queries in cell order (cellOrder): query j is ids[order[j]]; results go back to ids' order at the end.
  const std::vector<std::uint32_t> order = cellOrder(hbase, ids, base);
  std::vector<SampleId> sorted_ids(ids.size());
  for (std::size_t j = 0; j < ids.size(); ++j) sorted_ids[j] = ids[order[j]];
  const QuerySet queries{hbase, sorted_ids.data(), sorted_ids.size()};

  // Points: samples of levels 0..finest near the queried ids (a map may hold far more than a query needs), and
  // those of levels 0..level for k-NN footprints. Over centroids with a fixed footprint no sample is read.
  std::vector<SampleId> fine, coarse;
  if (!centroids || params.k > 0) {
    const double margin = std::min(s.max_radius, base * growth * 4.0);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (SampleId id : ids)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], h.position(id)[a] - margin);
        hi[a] = std::max(hi[a], h.position(id)[a] + margin);
      }
    fine = h.samplesUpTo(centroids ? level : finest);
    fine.erase(std::remove_if(fine.begin(), fine.end(),
                              [&](SampleId id) {
                                const double *p = h.position(id);
                                return p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] || p[2] < lo[2] ||
                                       p[2] > hi[2];
                              }),
               fine.end());
    if (params.k > 0)
      for (SampleId id : fine)
        if (h.level(id) <= level) coarse.push_back(id);
  }
  const PointSet coarse_set{hbase, coarse.data(), coarse.size()};
  s.fine = centroids ? PointSet{centroids->data(), nullptr, centroids->size() / 3}
                     : PointSet{hbase, fine.data(), fine.size()};

  // Search radii: one per doubling of the base radius up to twice the level-0 cell edge. A footprint rho is searched
  // with the smallest of them >= rho, all queries of one radius at once (BallGrid), round after round: a query
  // whose footprint doubles waits for the next round. Each query's result depends only on its own neighbourhoods.
  std::vector<LocalPca> chosen(ids.size());
  std::vector<std::uint8_t> have(ids.size(), 0);
  std::vector<std::uint32_t> pending;
  pending.reserve(ids.size());
  for (std::size_t j = 0; j < ids.size(); ++j)
    if (known && known->state[order[j]] != KnownNeighbourhoods::kUnknown) {
      have[j] = known->state[order[j]] == KnownNeighbourhoods::kChosen;
      if (have[j]) chosen[j] = known->chosen[order[j]];
    } else {
      pending.push_back(static_cast<std::uint32_t>(j));
    }

  // 1. Footprint at the output level: the radius, or the k-th nearest sample of levels 0..level within it.
  std::vector<double> rho(ids.size(), params.radius > 0.0 ? params.radius : s.max_radius);
  if (params.k > 0) {
    std::vector<std::uint8_t> again(ids.size(), 0);
    std::vector<std::uint32_t> left = pending;
    const std::size_t k = static_cast<std::size_t>(params.k);
    for (std::size_t g = 0; g < s.radii.size() && !left.empty(); ++g) {
      const bool last = g + 1 == s.radii.size();
      auto footprint = [&](std::uint32_t i, const BallView &v, SweepScratch &scratch) {
        std::vector<double> &d2s = scratch.values;
        const bool enough = v.count >= k;
        again[i] = 0;
        if (enough) {
          d2s.assign(v.d2, v.d2 + v.count);
          std::nth_element(d2s.begin(), d2s.begin() + static_cast<std::ptrdiff_t>(k - 1), d2s.end());
          // Just past the k-th distance, so that neighbour itself is inside the strict ball.
          rho[i] = std::min(rho[i], std::sqrt(d2s[k - 1]) * (1.0 + 1e-9) + 1e-12);
        } else if (params.radius > 0.0 && s.radii[g] >= params.radius) {
          rho[i] = std::min(rho[i], s.radii[g]);
        } else if (last) {
          rho[i] = std::min(rho[i], 2.0 * s.radii[g]);  // every radius tried: the footprint stays the search limit
        } else {
          again[i] = 1;
        }
      };
      sweep(s, coarse_set, queries, left, s.radii[g], footprint);
      left.erase(std::remove_if(left.begin(), left.end(), [&](std::uint32_t i) { return !again[i]; }), left.end());
    }
    // Queries outside every search grid (far outliers) saw no callback: their footprint stays as initialised.
  }

  // 2. Every averaging point inside the footprint, grown where line-like (growNeighbourhoods).
  growNeighbourhoods(s, queries, std::move(pending), rho, chosen.data(), have.data());
  for (std::size_t j = 0; j < ids.size(); ++j)
    if (have[j]) result[order[j]] = unorientedNormal(chosen[j]);
  if (neighbourhoods)
    for (std::size_t j = 0; j < ids.size(); ++j)
      if (have[j]) (*neighbourhoods)[order[j]] = chosen[j];
  orientTowardViewpoints(h, ids, result, params.up, params.threads);
  return result;
}

}  // namespace hpds
