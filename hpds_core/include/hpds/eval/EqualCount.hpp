// EqualCount: the grid cell edge at which a subsampling has (nearly) a given number of points, so that baselines are
// compared with hpds at equal point count.
//
// Contract
// - matchCellToCount bisects on log(cell) in [lo, hi] (a larger cell gives fewer points) until count(cell) is within
//   `tolerance` (relative) of `target`, or `max_probes` probes are spent, and returns the best probe seen (the count
//   only roughly decreases with the cell edge, so the last probe need not be the best).
// - `within` says whether the returned count meets the tolerance; the caller decides what a miss means.
// - std::invalid_argument for lo, hi not finite with 0 < lo < hi, a negative tolerance or max_probes < 1.
#pragma once

#include <cmath>
#include <cstddef>
#include <stdexcept>

namespace hpds {

struct CountMatch {
  double cell = 0.0;
  std::size_t count = 0;
  bool within = false;  ///< |count - target| <= tolerance * target
  int probes = 0;
};

/// `count(cell)` returns the subsampling size for a cell edge; see the contract.
template <typename CountFn>
[[nodiscard]] CountMatch matchCellToCount(CountFn &&count, std::size_t target, double tolerance, double lo, double hi,
                                          int max_probes = 40) {
  if (!(lo > 0.0) || !(hi > lo) || !std::isfinite(hi) || !(tolerance >= 0.0) || max_probes < 1)
    throw std::invalid_argument("matchCellToCount: needs 0 < lo < hi finite, tolerance >= 0, max_probes >= 1");
  const double allowed = tolerance * static_cast<double>(target);
  CountMatch best;
  double best_gap = INFINITY;
  for (int i = 0; i < max_probes; ++i) {
    const double mid = std::sqrt(lo * hi);
    const std::size_t n = count(mid);
    const double gap = std::fabs(static_cast<double>(n) - static_cast<double>(target));
    if (gap < best_gap) {
      best_gap = gap;
      best.cell = mid;
      best.count = n;
    }
    best.probes = i + 1;
    if (gap <= allowed) break;
    if (n > target)
      lo = mid;  // too many points: cells must grow
    else
      hi = mid;
  }
  best.within = best_gap <= allowed;
  return best;
}

}  // namespace hpds
