// Deliberately shares nothing with the sampler (no CellKey/LevelGrid/Hierarchy): a bug there must not be able to
// hide itself here. Neighbour queries go through nanoflann, cells through long-double floor.
#include "hpds/eval/SamplingVerifier.hpp"

#include <nanoflann.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <limits>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>

namespace hpds {
namespace {

constexpr int kMaxLevel = 21;
constexpr double kInf = std::numeric_limits<double>::infinity();
/// Cells of the finest level a coordinate stays below to be inserted (the sampler's exact-key limit, 2^30 - 8).
constexpr long double kKeyRangeCells = 1073741824.0L - 8.0L;
/// Far more than the sampler's rounding of |v| / edge there (below 1e-6 cells): points this close to the bound
/// may have gone either way, and are left out rather than guessed.
constexpr long double kKeyRangeMargin = 1e-3L;

using Vec3 = std::array<double, 3>;

// A prefix of the level-sorted sample array: U_D is always pts[0, n).
struct PrefixCloud {
  const Vec3 *pts = nullptr;
  std::size_t n = 0;
  [[nodiscard]] std::size_t kdtree_get_point_count() const { return n; }
  [[nodiscard]] double kdtree_get_pt(std::uint32_t i, std::size_t dim) const { return pts[i][dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox &) const {
    return false;
  }
};

using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PrefixCloud, double, std::uint32_t>,
                                                 PrefixCloud, 3, std::uint32_t>;

// Nearest neighbour other than `skip`, searched only inside the initial bound: a self-hit must not shrink the
// search ball (KNN with k=2 would mis-handle coincident duplicates), and a known upper bound prunes the tree.
struct NearestExcept {
  double best_sq;
  std::uint32_t skip;
  [[nodiscard]] double worstDist() const { return best_sq; }
  [[nodiscard]] bool full() const { return true; }
  bool addPoint(double d_sq, std::uint32_t i) {
    if (i != skip && d_sq < best_sq) best_sq = d_sq;
    return true;
  }
};

// Every point strictly inside radius_sq; only used around violations, so it stays small.
struct CollectWithin {
  double radius_sq;
  std::vector<std::pair<std::uint32_t, double>> *out;
  [[nodiscard]] double worstDist() const { return radius_sq; }
  [[nodiscard]] bool full() const { return true; }
  [[nodiscard]] std::size_t size() const { return out->size(); }
  bool addPoint(double d_sq, std::uint32_t i) {
    if (d_sq < radius_sq) out->emplace_back(i, d_sq);
    return true;
  }
};

int resolveThreadCount(int threads) {
  if (threads > 0) return threads;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw ? static_cast<int>(hw) : 1;
}

// Small loops are not worth a thread start.
std::size_t chunkCount(std::size_t n, int threads) {
  return std::max<std::size_t>(1, std::min<std::size_t>(static_cast<std::size_t>(threads), n / 1024));
}

// Calls fn(chunk, begin, end) on `chunks` fixed ranges covering [0, n). Callers reduce per chunk and combine with
// order-independent operations, which keeps the result identical for any thread count.
template <class Fn>
void forChunks(std::size_t n, int threads, Fn &&fn) {
  const std::size_t chunks = chunkCount(n, threads);
  const std::size_t step = (n + chunks - 1) / chunks;
  if (chunks == 1) {
    fn(std::size_t{0}, std::size_t{0}, n);
    return;
  }
  std::vector<std::thread> pool;
  std::vector<std::exception_ptr> errors(chunks);
  for (std::size_t c = 0; c < chunks; ++c) {
    const std::size_t b = std::min(n, c * step), e = std::min(n, b + step);
    pool.emplace_back([&, c, b, e] {
      try {
        fn(c, b, e);
      } catch (...) {
        errors[c] = std::current_exception();
      }
    });
  }
  for (auto &t : pool) t.join();
  for (auto &err : errors)
    if (err) std::rethrow_exception(err);
}

struct Xyz {
  const PointField *f[3];
};

Xyz requireXyz(const PointBuffer &cloud, const char *what) {
  Xyz xyz{};
  const char *names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    xyz.f[a] = cloud.layout().find(names[a]);
    if (!xyz.f[a]) throw std::invalid_argument(std::string("verifySampling: ") + what + " has no '" + names[a] + "' field");
  }
  return xyz;
}

Vec3 readXyz(const PointBuffer &cloud, const Xyz &xyz, std::size_t i) {
  const std::uint8_t *rec = cloud.record(i);
  return {readAsDouble(rec, *xyz.f[0]), readAsDouble(rec, *xyz.f[1]), readAsDouble(rec, *xyz.f[2])};
}

bool isFinite(const Vec3 &p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); }

// Level-D cell checks with their own arithmetic. Points within tol of a face may have been rounded across it and
// so belong to either cell: they are left out instead of guessed. Cell indices beyond 2^62 cannot be formed
// reliably; such points are reported as violations (no real sampling gets there).
std::size_t countCellViolations(const Vec3 *pts, std::size_t n, double cell, double tol) {
  constexpr long double kIndexLimit = 4.6e18L;  // < 2^62
  std::vector<std::array<std::int64_t, 3>> keys;
  keys.reserve(n);
  std::size_t unverifiable = 0;
  const long double c = cell;
  for (std::size_t i = 0; i < n; ++i) {
    std::array<std::int64_t, 3> key{};
    bool interior = true, in_range = true;
    for (int a = 0; a < 3; ++a) {
      const long double x = pts[i][a];
      const long double k = std::floor(x / c);
      if (!(std::fabs(k) < kIndexLimit)) {
        in_range = false;
        break;
      }
      // The quotient's rounding may put x just outside [k c, (k+1) c); the face distances below then come out
      // <= 0 or tiny, which is exactly the "near a face" case and excludes the point.
      const long double lo = x - k * c, hi = (k + 1) * c - x;
      if (!(lo > tol && hi > tol)) interior = false;
      key[a] = static_cast<std::int64_t>(k);
    }
    if (!in_range) {
      ++unverifiable;
      continue;
    }
    if (interior) keys.push_back(key);
  }
  std::sort(keys.begin(), keys.end());
  std::size_t dup = 0;
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (keys[i] == keys[i - 1]) ++dup;
  return dup + unverifiable;
}

}  // namespace

/// Close pairs a chunk holds before applying them to the older points.
constexpr std::size_t kPairBatch = std::size_t(1) << 16;
/// A level is checked only while the tolerance stays within this fraction of its radius.
constexpr double kResolvedFraction = 0.1;

std::size_t VerifyReport::total_violations() const {
  std::size_t total = 0;
  for (const auto &l : levels)
    total += l.spacing_violations + l.cell_violations + l.coverage_violations + (l.unresolved ? 1 : 0);
  return total;
}

VerifyReport verifySampling(const PointBuffer &sampling, double cell_size, const PointBuffer *input, int threads,
                            int max_depth, int through_level) {
  if (!(std::isfinite(cell_size) && cell_size > 0.0))
    throw std::invalid_argument("verifySampling: cell_size must be finite and > 0");
  const Xyz sxyz = requireXyz(sampling, "sampling");
  const PointField *level_field = sampling.layout().find("level");
  if (!level_field) throw std::invalid_argument("verifySampling: sampling has no 'level' field");
  Xyz ixyz{};
  if (input) ixyz = requireXyz(*input, "input");
  threads = resolveThreadCount(threads);

  // Sort samples by level so that every U_D is a prefix; non-finite samples are only counted.
  const std::size_t n_samples = sampling.size();
  std::vector<int> level_of(n_samples);
  std::array<std::size_t, kMaxLevel + 2> per_level{};  // finite samples per level, later prefix offsets
  std::array<std::size_t, kMaxLevel + 1> nonfinite{};
  std::array<std::size_t, kMaxLevel + 1> count{};
  int max_level = -1;
  double max_abs = 0.0;
  std::vector<Vec3> raw(n_samples);
  for (std::size_t i = 0; i < n_samples; ++i) {
    const double lv = readAsDouble(sampling.record(i), *level_field);
    if (!(lv >= 0.0 && lv <= kMaxLevel && lv == std::floor(lv)))
      throw std::invalid_argument("verifySampling: sample " + std::to_string(i) + " has level " + std::to_string(lv) +
                                  ", expected an integer in 0..21");
    const int l = static_cast<int>(lv);
    level_of[i] = l;
    max_level = std::max(max_level, l);
    ++count[l];
    raw[i] = readXyz(sampling, sxyz, i);
    if (isFinite(raw[i])) {
      ++per_level[l + 1];
      for (double v : raw[i]) max_abs = std::max(max_abs, std::fabs(v));
    } else {
      ++nonfinite[l];
    }
  }
  if (!(through_level >= -1 && through_level <= kMaxLevel))
    throw std::invalid_argument("verifySampling: through_level " + std::to_string(through_level) +
                                ": expected -1 or a level in 0..21");
  if (max_depth != -1 && !(max_depth >= std::max(max_level, 0) && max_depth <= kMaxLevel))
    throw std::invalid_argument("verifySampling: max_depth " + std::to_string(max_depth) +
                                (max_depth >= 0 && max_depth < max_level
                                     ? " is shallower than level " + std::to_string(max_level) +
                                           ", which the sampling holds"
                                     : ": expected -1 or a level in 0..21"));
  for (int l = 0; l <= kMaxLevel; ++l) per_level[l + 1] += per_level[l];
  const std::array<std::size_t, kMaxLevel + 2> level_begin = per_level;  // level l occupies [begin[l], begin[l+1])
  std::vector<Vec3> pts(level_begin[kMaxLevel + 1]);
  {
    auto cursor = level_begin;
    for (std::size_t i = 0; i < n_samples; ++i)
      if (isFinite(raw[i])) pts[cursor[level_of[i]]++] = raw[i];
  }
  raw = {};

  VerifyReport report;
  report.cell_size = cell_size;
  // Half an ulp of the stored type: float64 when x, y and z all are, else float32 (integers are exact but a sampling
  // stored as such is not hpds's; the float32 bound covers them).
  bool doubles = true;
  for (const PointField *f : sxyz.f) doubles &= f->type == FieldType::Float64;
  report.tolerance = 4.0 * std::ldexp(1.0, doubles ? -53 : -24) * max_abs;
  const double tol = report.tolerance;

  // Coverage candidates: sensor no-returns (non-finite or exactly the origin) are not points of the scene, and no
  // sample can cover a point the sampler never inserted.
  report.key_range_depth = max_depth >= 0 ? max_depth : std::max(max_level, 0);
  const long double key_bound =
      (kKeyRangeCells - kKeyRangeMargin) * std::ldexp(static_cast<long double>(cell_size), -report.key_range_depth);
  const auto beyondKeyRange = [&](const Vec3 &p) {
    return std::fabs(static_cast<long double>(p[0])) >= key_bound ||
           std::fabs(static_cast<long double>(p[1])) >= key_bound ||
           std::fabs(static_cast<long double>(p[2])) >= key_bound;
  };
  std::vector<Vec3> probes;
  if (input) {
    report.input_points = input->size();
    probes.reserve(input->size());
    for (std::size_t i = 0; i < input->size(); ++i) {
      const Vec3 p = readXyz(*input, ixyz, i);
      if (!isFinite(p) || (p[0] == 0.0 && p[1] == 0.0 && p[2] == 0.0)) continue;
      if (beyondKeyRange(p)) {
        ++report.input_beyond_key_range;
        continue;
      }
      probes.push_back(p);
    }
  }
  const bool have_probes = !probes.empty();
  std::vector<double> probe_dist(probes.size(), kInf);  // distance to U_D, exact after each level

  std::vector<double> nn(pts.size(), kInf);  // see the update rule in the level loop
  double min_nn = kInf;                      // min pair distance in U_D
  std::size_t nonfinite_union = 0;

  PrefixCloud cloud{pts.data(), 0};
  std::unique_ptr<Tree> tree;
  const nanoflann::SearchParams params(32, 0.0f, false);

  for (int d = 0; d <= std::max(max_level, through_level); ++d) {
    const double cell = std::ldexp(cell_size, -d);
    const double r = std::sqrt(3.0) / 2.0 * cell;
    const double thr = r - tol;
    const std::size_t begin = level_begin[d], end = level_begin[d + 1];
    nonfinite_union += nonfinite[d];

    LevelReport lr;
    lr.level = d;
    lr.count = count[d];
    lr.union_count = end + nonfinite_union;

    if (end > begin) {
      cloud.n = end;
      tree = std::make_unique<Tree>(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    }

    // New points get their exact nearest neighbour in U_D. An older point p only needs the new points closer than
    // r_D - tol: a farther one is also no violation at any finer level (r shrinks), and the pair's minimum is
    // already caught from the new side. So nn[p] < r_E - tol decides exactly for every level E.
    const std::size_t n_new = end - begin;
    const std::size_t nc = chunkCount(n_new, threads);
    std::vector<double> chunk_min(nc, kInf);
    // The close pairs are applied to the older points in batches under a lock (a min, so in any order): with a
    // wrong --cell-size nearly every pair is close, and holding them all took memory quadratic in the samples.
    std::mutex older_mutex;
    auto applyToOlder = [&](std::vector<std::pair<std::uint32_t, double>> &pairs) {
      const std::lock_guard<std::mutex> lock(older_mutex);
      for (const auto &[p, dist] : pairs) nn[p] = std::min(nn[p], dist);
      pairs.clear();
    };
    if (n_new > 0) {
      forChunks(n_new, threads, [&](std::size_t c, std::size_t b, std::size_t e) {
        std::vector<std::pair<std::uint32_t, double>> found, pairs;
        for (std::size_t k = begin + b; k < begin + e; ++k) {
          NearestExcept res{kInf, static_cast<std::uint32_t>(k)};
          tree->findNeighbors(res, pts[k].data(), params);
          nn[k] = std::sqrt(res.best_sq);
          chunk_min[c] = std::min(chunk_min[c], nn[k]);
          if (thr > 0.0 && nn[k] < thr && begin > 0) {
            // Slightly enlarged so that the sqrt comparison below, not the squared one, decides.
            found.clear();
            CollectWithin within{thr * thr * (1.0 + 1e-9), &found};
            tree->findNeighbors(within, pts[k].data(), params);
            for (const auto &[p, d_sq] : found)
              if (p < begin) pairs.emplace_back(p, std::sqrt(d_sq));
            if (pairs.size() >= kPairBatch) applyToOlder(pairs);
          }
        }
        applyToOlder(pairs);
      });
    }
    for (std::size_t c = 0; c < nc; ++c) min_nn = std::min(min_nn, chunk_min[c]);
    lr.min_nn_over_r = min_nn / r;
    lr.spacing_violations = nonfinite_union;
    for (std::size_t k = 0; k < end; ++k)
      if (nn[k] < thr) ++lr.spacing_violations;

    lr.cell_violations = countCellViolations(pts.data() + begin, n_new, cell, tol);
    lr.unresolved = !(tol <= kResolvedFraction * r);

    lr.max_coverage_over_r = std::numeric_limits<double>::quiet_NaN();
    if (have_probes) {
      const std::size_t pc = chunkCount(probes.size(), threads);
      std::vector<double> chunk_max(pc, 0.0);
      std::vector<std::size_t> chunk_bad(pc, 0);
      const double limit = 2.0 * r + tol;
      forChunks(probes.size(), threads, [&](std::size_t c, std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k) {
          // U_D only grows, so last level's distance bounds the search ball.
          if (end > 0) {
            NearestExcept res{probe_dist[k] * probe_dist[k], std::numeric_limits<std::uint32_t>::max()};
            tree->findNeighbors(res, probes[k].data(), params);
            probe_dist[k] = std::min(probe_dist[k], std::sqrt(res.best_sq));
          }
          chunk_max[c] = std::max(chunk_max[c], probe_dist[k]);
          if (probe_dist[k] > limit) ++chunk_bad[c];
        }
      });
      double mx = 0.0;
      for (std::size_t c = 0; c < pc; ++c) {
        mx = std::max(mx, chunk_max[c]);
        lr.coverage_violations += chunk_bad[c];
      }
      lr.max_coverage_over_r = mx / r;
    }
    report.levels.push_back(lr);
  }
  return report;
}

std::string formatReport(const VerifyReport &report) {
  std::string out;
  char line[320];
  std::snprintf(line, sizeof line, "cell size %.6g m, tolerance %.3g m, violations %zu\n", report.cell_size,
                report.tolerance, report.total_violations());
  out += line;
  if (report.input_beyond_key_range > 0) {
    const double edge = std::ldexp(report.cell_size, -report.key_range_depth);
    std::snprintf(line, sizeof line,
                  "%zu of the %zu input points lie beyond the exact key range of level %d (a coordinate of %.4g m "
                  "or more: 2^30 - 8 cells of %.4g m), where the sampler inserts none: not checked for coverage\n",
                  report.input_beyond_key_range, report.input_points, report.key_range_depth,
                  static_cast<double>(kKeyRangeCells) * edge, edge);
    out += line;
  }
  for (const auto &l : report.levels)
    if (l.unresolved) {
      std::snprintf(line, sizeof line,
                    "levels %d and finer cannot be checked: the stored positions are only exact to %.3g m, more "
                    "than a tenth of r_%d (float32 x y z at coordinates up to %.3g m; write them as float64, "
                    "output.float64_xyz), one violation each\n",
                    l.level, report.tolerance, l.level, report.tolerance / 4.0 * std::ldexp(1.0, 24));
      out += line;
      break;
    }
  std::snprintf(line, sizeof line, "%5s %12s %10s %10s %9s %8s %8s %9s %8s\n", "level", "r_D", "count", "union",
                "min_nn/r", "viol", "cells", "cover/r", "uncov");
  out += line;
  const auto num = [](double v) {
    char buf[32];
    if (std::isnan(v))
      std::snprintf(buf, sizeof buf, "-");
    else if (std::isinf(v))
      std::snprintf(buf, sizeof buf, "inf");
    else
      std::snprintf(buf, sizeof buf, "%.4f", v);
    return std::string(buf);
  };
  for (const auto &l : report.levels) {
    const double r = std::sqrt(3.0) / 2.0 * std::ldexp(report.cell_size, -l.level);
    const bool cov = !std::isnan(l.max_coverage_over_r);
    std::snprintf(line, sizeof line, "%5d %12.6g %10zu %10zu %9s %8zu %8zu %9s %8s\n", l.level, r, l.count,
                  l.union_count, num(l.min_nn_over_r).c_str(), l.spacing_violations, l.cell_violations,
                  num(l.max_coverage_over_r).c_str(), cov ? std::to_string(l.coverage_violations).c_str() : "-");
    out += line;
  }
  return out;
}

}  // namespace hpds
