// GridSubsampling: the single-grid subsamplings the paper compares against (section 1, figure 5), for analyses and
// benchmarks run on the same input as the hierarchy.
//
// Contract
// - The grid is world-anchored like the hierarchy's: cell floor((p - origin) / cell) per axis, origin = 0 by default.
//   A non-zero origin lets a benchmark keep a flat synthetic surface (the ground at z = 0) off the cell boundaries,
//   where a grid would put two samples a noise width apart.
// - gridRandom: one point per occupied cell, drawn uniformly among the cell's points. The draw is a hash of
//   (seed, point index), so it depends neither on input order nor on the platform.
// - gridClosestToCenter: per occupied cell the point nearest the cell centre (ties: lower index).
// - voxelCentroids: per occupied cell the mean of its points (not an input point; what PCL's VoxelGrid returns).
// - Index results are sorted ascending; centroid results are ordered by cell key. All ignore non-finite points.
// - cellForCount: the cell edge whose subsampling size is closest to `target`, by bisection on log(cell) between
//   lo and hi (the count only roughly decreases with the cell edge, so the best probe seen is returned).
// - Throws std::invalid_argument for a cell edge that is not finite and positive.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <vector>

namespace hpds {

[[nodiscard]] std::vector<std::uint32_t> gridRandom(const std::vector<Eigen::Vector3d> &points, double cell,
                                                    std::uint64_t seed,
                                                    const Eigen::Vector3d &origin = Eigen::Vector3d::Zero());
[[nodiscard]] std::vector<std::uint32_t> gridClosestToCenter(const std::vector<Eigen::Vector3d> &points, double cell,
                                                             const Eigen::Vector3d &origin = Eigen::Vector3d::Zero());
[[nodiscard]] std::vector<Eigen::Vector3d> voxelCentroids(const std::vector<Eigen::Vector3d> &points, double cell,
                                                          const Eigen::Vector3d &origin = Eigen::Vector3d::Zero());

/// `count(cell)` returns the subsampling size for a cell edge; see the contract.
template <typename CountFn>
[[nodiscard]] double cellForCount(CountFn &&count, std::size_t target, double lo, double hi, int iterations = 30) {
  double best = lo;
  std::size_t best_gap = static_cast<std::size_t>(-1);
  for (int i = 0; i < iterations; ++i) {
    const double mid = std::sqrt(lo * hi);
    const std::size_t n = count(mid);
    const std::size_t gap = n > target ? n - target : target - n;
    if (gap < best_gap) best_gap = gap, best = mid;
    if (gap == 0) break;
    if (n > target)
      lo = mid;  // too many points: cells must grow
    else
      hi = mid;
  }
  return best;
}

}  // namespace hpds
