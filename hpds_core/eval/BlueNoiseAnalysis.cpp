#include "hpds/eval/BlueNoiseAnalysis.hpp"

#include <nanoflann.hpp>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "hpds/util/ParallelFor.hpp"

namespace hpds {

namespace {

constexpr double kPi = 3.14159265358979323846;

bool inside(const Eigen::Vector2d &p, const SquareWindow &w) {
  return p.x() >= w.x0 && p.x() < w.x0 + w.size && p.y() >= w.y0 && p.y() < w.y0 + w.size;
}

std::vector<Eigen::Vector2d> clipToWindow(const std::vector<Eigen::Vector2d> &points, const SquareWindow &w) {
  std::vector<Eigen::Vector2d> out;
  out.reserve(points.size());
  for (const auto &p : points)
    if (inside(p, w)) out.emplace_back(p.x() - w.x0, p.y() - w.y0);
  return out;
}

// Buckets of edge >= r_max over [0, size)^2, so every pair closer than r_max is in the same or an adjacent bucket.
struct Buckets {
  int n = 1;
  double edge = 1.0;
  std::vector<std::vector<std::uint32_t>> cells;

  Buckets(const std::vector<Eigen::Vector2d> &pts, double size, double r_max) {
    n = std::max(1, std::min(1024, static_cast<int>(std::floor(size / r_max))));
    edge = size / n;
    cells.resize(static_cast<std::size_t>(n) * n);
    for (std::size_t i = 0; i < pts.size(); ++i) cells[index(cellOf(pts[i].x()), cellOf(pts[i].y()))].push_back(
        static_cast<std::uint32_t>(i));
  }
  [[nodiscard]] int cellOf(double c) const { return std::clamp(static_cast<int>(std::floor(c / edge)), 0, n - 1); }
  [[nodiscard]] std::size_t index(int cx, int cy) const { return static_cast<std::size_t>(cy) * n + cx; }
};

}  // namespace

RadialDistribution radialDistribution(const std::vector<Eigen::Vector2d> &points, const SquareWindow &window,
                                      double r_max, int bins, bool periodic) {
  if (bins < 1) throw std::invalid_argument("radialDistribution: bins must be >= 1");
  if (!(r_max > 0.0) || !(window.size > 0.0))
    throw std::invalid_argument("radialDistribution: r_max and the window size must be > 0");
  if (periodic ? r_max > 0.5 * window.size : r_max >= 0.5 * window.size)
    throw std::invalid_argument("radialDistribution: r_max " + std::to_string(r_max) +
                                " is too large for a window of size " + std::to_string(window.size));
  const std::vector<Eigen::Vector2d> pts = clipToWindow(points, window);
  const double size = window.size;
  RadialDistribution out;
  out.r.resize(static_cast<std::size_t>(bins));
  out.g.assign(static_cast<std::size_t>(bins), 0.0);
  const double dr = r_max / bins;
  for (int b = 0; b < bins; ++b) out.r[static_cast<std::size_t>(b)] = (b + 0.5) * dr;
  out.density = static_cast<double>(pts.size()) / (size * size);
  if (pts.size() < 2) return out;

  const Buckets buckets(pts, size, r_max);
  std::vector<double> hist(static_cast<std::size_t>(bins), 0.0);
  const double r2max = r_max * r_max;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d &p = pts[i];
    if (!periodic && (p.x() < r_max || p.y() < r_max || p.x() > size - r_max || p.y() > size - r_max)) continue;
    ++out.reference_points;
    const int cx = buckets.cellOf(p.x()), cy = buckets.cellOf(p.y());
    // Visit each distinct neighbour bucket once: with fewer than 3 buckets per axis, wrapping maps several offsets
    // onto the same bucket and would count its pairs twice.
    int visited[9][2];
    int nvisited = 0;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        int bx = cx + dx, by = cy + dy;
        if (periodic) {
          bx = (bx + buckets.n) % buckets.n;
          by = (by + buckets.n) % buckets.n;
        } else if (bx < 0 || by < 0 || bx >= buckets.n || by >= buckets.n) {
          continue;
        }
        bool seen = false;
        for (int s = 0; s < nvisited; ++s) seen = seen || (visited[s][0] == bx && visited[s][1] == by);
        if (seen) continue;
        visited[nvisited][0] = bx;
        visited[nvisited][1] = by;
        ++nvisited;
        for (std::uint32_t j : buckets.cells[buckets.index(bx, by)]) {
          if (j == i) continue;
          double ddx = pts[j].x() - p.x(), ddy = pts[j].y() - p.y();
          if (periodic) {
            ddx -= size * std::round(ddx / size);
            ddy -= size * std::round(ddy / size);
          }
          const double d2 = ddx * ddx + ddy * ddy;
          if (d2 >= r2max) continue;
          const int b = std::min(bins - 1, static_cast<int>(std::sqrt(d2) / dr));
          hist[static_cast<std::size_t>(b)] += 1.0;
        }
      }
  }
  if (out.reference_points == 0) return out;
  // A Poisson process of the same density expects density * annulus area neighbours per reference point. The
  // density counts the reference point itself among N, hence (N - 1) / area for an unbiased expectation.
  const double rho = (static_cast<double>(pts.size()) - 1.0) / (size * size);
  for (int b = 0; b < bins; ++b) {
    const double r0 = b * dr, r1 = (b + 1) * dr;
    const double expected = static_cast<double>(out.reference_points) * rho * kPi * (r1 * r1 - r0 * r0);
    out.g[static_cast<std::size_t>(b)] = hist[static_cast<std::size_t>(b)] / expected;
  }
  return out;
}

PowerSpectrum powerSpectrum(const std::vector<Eigen::Vector2d> &points, const SquareWindow &window, int half_extent,
                            int threads) {
  if (half_extent < 1) throw std::invalid_argument("powerSpectrum: half_extent must be >= 1");
  if (!(window.size > 0.0)) throw std::invalid_argument("powerSpectrum: the window size must be > 0");
  const std::vector<Eigen::Vector2d> pts = clipToWindow(points, window);
  const int K = half_extent, W = 2 * K + 1;
  PowerSpectrum out;
  out.half_extent = K;
  out.frequency_step = 1.0 / window.size;
  out.points = pts.size();
  out.power.assign(static_cast<std::size_t>(W) * W, 0.0);

  if (!pts.empty()) {
    // P(-k) = P(k) for real point sets, so only rows ky >= 0 are summed (row 0 in full) and mirrored afterwards.
    // Per row ky each point contributes e^{-2 pi i ky y} * e^{-2 pi i kx x}; the kx powers are built by repeated
    // multiplication from k = -K, with the phases taken relative to the window, where |x| < size keeps them exact.
    const double inv_n = 1.0 / static_cast<double>(pts.size());
    parallelFor(static_cast<std::size_t>(K + 1), threads, [&](std::size_t b, std::size_t e) {
      std::vector<double> re(static_cast<std::size_t>(W)), im(static_cast<std::size_t>(W));
      for (std::size_t kyu = b; kyu < e; ++kyu) {
        const int ky = static_cast<int>(kyu);
        std::fill(re.begin(), re.end(), 0.0);
        std::fill(im.begin(), im.end(), 0.0);
        for (const auto &p : pts) {
          const double ax = -2.0 * kPi * p.x() / window.size, ay = -2.0 * kPi * p.y() / window.size;
          const double sr = std::cos(ax), si = std::sin(ax);
          double er = 0.0, ei = 0.0;
          // Plain doubles instead of std::complex: its operator* carries NaN/Inf recovery that blocks vectorising.
          // The product is re-anchored from an exact cos/sin every 64 steps, which bounds its drift.
          for (int kx = -K; kx <= K; ++kx) {
            if (((kx + K) & 63) == 0) {
              const double ph = ay * ky + ax * kx;
              er = std::cos(ph);
              ei = std::sin(ph);
            }
            re[static_cast<std::size_t>(kx + K)] += er;
            im[static_cast<std::size_t>(kx + K)] += ei;
            const double nr = er * sr - ei * si;
            ei = er * si + ei * sr;
            er = nr;
          }
        }
        for (int kx = -K; kx <= K; ++kx) {
          const std::size_t j = static_cast<std::size_t>(kx + K);
          out.power[static_cast<std::size_t>(ky + K) * W + j] = (re[j] * re[j] + im[j] * im[j]) * inv_n;
        }
      }
    });
    for (int ky = 1; ky <= K; ++ky)
      for (int kx = -K; kx <= K; ++kx)
        out.power[static_cast<std::size_t>(-ky + K) * W + (-kx + K)] = out.power[static_cast<std::size_t>(ky + K) * W + (kx + K)];
  }

  out.radial_frequency.resize(static_cast<std::size_t>(K));
  out.radial_power.assign(static_cast<std::size_t>(K), 0.0);
  std::vector<double> count(static_cast<std::size_t>(K), 0.0);
  for (int ky = -K; ky <= K; ++ky)
    for (int kx = -K; kx <= K; ++kx) {
      const int b = static_cast<int>(std::lround(std::sqrt(double(kx) * kx + double(ky) * ky)));
      if (b < 1 || b > K) continue;
      out.radial_power[static_cast<std::size_t>(b - 1)] += out.at(kx, ky);
      count[static_cast<std::size_t>(b - 1)] += 1.0;
    }
  for (int b = 1; b <= K; ++b) {
    out.radial_frequency[static_cast<std::size_t>(b - 1)] = b * out.frequency_step;
    if (count[static_cast<std::size_t>(b - 1)] > 0.0)
      out.radial_power[static_cast<std::size_t>(b - 1)] /= count[static_cast<std::size_t>(b - 1)];
  }
  return out;
}

namespace {
struct Cloud3 {
  const std::vector<Eigen::Vector3d> *pts;
  [[nodiscard]] std::size_t kdtree_get_point_count() const { return pts->size(); }
  [[nodiscard]] double kdtree_get_pt(std::uint32_t i, std::size_t d) const { return (*pts)[i][static_cast<int>(d)]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox &) const {
    return false;
  }
};
using Tree3 = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud3, double, std::uint32_t>,
                                                  Cloud3, 3, std::uint32_t>;
}  // namespace

std::vector<double> nearestNeighborDistances(const std::vector<Eigen::Vector3d> &points) {
  std::vector<double> out(points.size(), std::numeric_limits<double>::infinity());
  if (points.size() < 2) return out;
  Cloud3 cloud{&points};
  Tree3 tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  for (std::size_t i = 0; i < points.size(); ++i) {
    // k = 2 returns the point itself first; coincident duplicates then give distance 0, which is the truth.
    std::uint32_t idx[2];
    double d2[2];
    nanoflann::KNNResultSet<double, std::uint32_t> rs(2);
    rs.init(idx, d2);
    tree.findNeighbors(rs, points[i].data(), nanoflann::SearchParams(10));
    if (rs.size() == 2) out[i] = std::sqrt(idx[0] == i ? d2[1] : d2[0]);
  }
  return out;
}

PlaneFit fitPlane(const std::vector<Eigen::Vector3d> &points) {
  PlaneFit fit;
  if (points.size() < 3) return fit;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto &p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto &p : points) cov += (p - c) * (p - c).transpose();
  cov /= static_cast<double>(points.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  if (es.info() != Eigen::Success) return fit;
  const Eigen::Vector3d ev = es.eigenvalues();
  if (!(ev(1) > 1e-12 * std::max(ev(2), 1e-300))) return fit;  // collinear: the plane is undefined
  Eigen::Vector3d n = es.eigenvectors().col(0).normalized();
  if (n.z() < 0.0) n = -n;
  // u follows world x where possible, so that a near-horizontal patch keeps its xy orientation in the plane.
  Eigen::Vector3d ref = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  Eigen::Vector3d u = (ref - ref.dot(n) * n).normalized();
  fit.centroid = c;
  fit.normal = n;
  fit.u = u;
  fit.v = n.cross(u);
  fit.rms = std::sqrt(std::max(0.0, ev(0)));
  fit.valid = true;
  return fit;
}

std::vector<Eigen::Vector2d> projectToPlane(const std::vector<Eigen::Vector3d> &points, const PlaneFit &plane,
                                            double max_distance, std::vector<std::uint32_t> *kept) {
  std::vector<Eigen::Vector2d> out;
  if (kept) kept->clear();
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d d = points[i] - plane.centroid;
    if (std::abs(d.dot(plane.normal)) > max_distance) continue;
    out.emplace_back(d.dot(plane.u), d.dot(plane.v));
    if (kept) kept->push_back(static_cast<std::uint32_t>(i));
  }
  return out;
}

PlanarPatch findPlanarPatch(const std::vector<Eigen::Vector3d> &points, double size, double inlier_distance,
                            double max_tilt_deg) {
  PlanarPatch best;
  if (!(size > 0.0) || points.empty()) return best;
  // Candidates are 2x2 blocks of half-size cells, i.e. patches overlapping by half their edge. Each cell's points
  // are listed once, so that a candidate reads only its own.
  const double half = 0.5 * size;
  std::map<std::pair<long, long>, std::vector<std::uint32_t>> cell_points;
  auto cellOf = [&](const Eigen::Vector3d &p) {
    return std::make_pair(static_cast<long>(std::floor(p.x() / half)), static_cast<long>(std::floor(p.y() / half)));
  };
  for (std::size_t i = 0; i < points.size(); ++i) cell_points[cellOf(points[i])].push_back(static_cast<std::uint32_t>(i));
  std::vector<std::pair<std::size_t, std::pair<long, long>>> candidates;
  for (const auto &kv : cell_points) {
    std::size_t n = 0;
    for (long dy = 0; dy <= 1; ++dy)
      for (long dx = 0; dx <= 1; ++dx) {
        auto it = cell_points.find({kv.first.first + dx, kv.first.second + dy});
        if (it != cell_points.end()) n += it->second.size();
      }
    candidates.emplace_back(n, kv.first);
  }
  // Ties broken by cell index so the choice does not depend on container order.
  std::sort(candidates.begin(), candidates.end(), [](const auto &a, const auto &b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  const double cos_tilt = std::cos(max_tilt_deg * kPi / 180.0);
  // The 64 most populated candidates, and only when none of them qualifies the rest in the same order: on a long
  // drive's map the most populated squares are walls (many rings hit them), and the ground lies further down.
  constexpr std::size_t kFirstTries = 64;
  for (std::size_t c = 0; c < candidates.size(); ++c) {
    if (c == kFirstTries && best.found) break;
    const double x0 = candidates[c].second.first * half, y0 = candidates[c].second.second * half;
    std::vector<std::uint32_t> ids;
    for (long dy = 0; dy <= 1; ++dy)
      for (long dx = 0; dx <= 1; ++dx) {
        auto it = cell_points.find({candidates[c].second.first + dx, candidates[c].second.second + dy});
        if (it != cell_points.end()) ids.insert(ids.end(), it->second.begin(), it->second.end());
      }
    if (ids.size() < 16) break;
    std::sort(ids.begin(), ids.end());  // input order: the fits sum in the same order whichever cells hold them
    std::vector<Eigen::Vector3d> in;
    in.reserve(ids.size());
    for (std::uint32_t i : ids) in.push_back(points[i]);
    // Objects standing on the ground would pull a plain least-squares fit off the ground, so the fit starts from
    // the most populated height band (the ground, for a street patch) and is refined on the points near it.
    const double band = std::max(inlier_distance, 1e-3);
    std::map<long, std::size_t> zhist;
    for (const auto &p : in) ++zhist[static_cast<long>(std::floor(p.z() / band))];
    long mode = zhist.begin()->first;
    std::size_t mode_count = 0;
    for (const auto &kv : zhist) {
      const std::size_t n3 = kv.second + (zhist.count(kv.first - 1) ? zhist[kv.first - 1] : 0) +
                             (zhist.count(kv.first + 1) ? zhist[kv.first + 1] : 0);
      if (n3 > mode_count) mode_count = n3, mode = kv.first;
    }
    PlaneFit fit;
    fit.centroid = Eigen::Vector3d(x0 + half, y0 + half, (mode + 0.5) * band);
    fit.valid = true;
    double width = 1.5 * band;
    for (int round = 0; round < 6 && fit.valid; ++round) {
      std::vector<Eigen::Vector3d> near;
      for (const auto &p : in)
        if (std::abs((p - fit.centroid).dot(fit.normal)) <= width) near.push_back(p);
      fit = fitPlane(near);
      width = inlier_distance;
    }
    if (!fit.valid || fit.normal.z() < cos_tilt) continue;
    std::size_t inl = 0;
    for (const auto &p : in) inl += std::abs((p - fit.centroid).dot(fit.normal)) <= inlier_distance ? 1 : 0;
    if (inl < static_cast<std::size_t>(0.8 * static_cast<double>(in.size()))) continue;
    // The most points on the plane wins, not the most points: counting everything would prefer a square that
    // also holds a curb or a wall, and near-ties between such squares would let sampling noise choose.
    if (best.found && inl <= best.inliers) continue;
    best.center = Eigen::Vector2d(x0 + half, y0 + half);
    best.size = size;
    best.plane = fit;
    best.inliers = inl;
    best.found = true;
  }
  return best;
}

}  // namespace hpds
