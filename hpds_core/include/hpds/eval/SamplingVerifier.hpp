// SamplingVerifier: checks a finished sampling against the hierarchy's guarantees, independently of the sampler.
//
// Contract
// - Input: a PointBuffer with numeric fields x, y, z and `level` (integer values 0..21), the level-0 cell size C,
//   and optionally the input cloud the sampling was made from (fields x, y, z).
// - Level D has cell edge c_D = C * 2^-D (cells [k c_D, (k+1) c_D) per axis, anchored at the world origin) and
//   radius r_D = sqrt(3)/2 * c_D. U_D is the union of the samples of levels 0..D. For every D from 0 to the
//   highest level present, or to `through_level` when that is deeper (the level a sampling was asked to reach: its
//   empty levels then count, and an input must be covered at their radii), it checks
//     (1) cells:    at most one level-D sample per level-D cell;
//     (2) spacing:  every pair of U_D is at least r_D apart;
//     (3) coverage: every input point lies within 2 r_D of U_D (only when an input cloud is given).
// - Tolerance: samplings are usually stored as float32, which moves each coordinate by at most 2^-24 * |coordinate|
//   (half an ulp); a distance between two rounded points moves by at most 2 * sqrt(3) * 2^-24 * M < 4 * 2^-24 * M,
//   M = max |coordinate| over the finite sample coordinates. So tol = 4 * 2^-24 * M (4 * 2^-53 * M when x, y and z
//   are all float64) and
//     a pair is a spacing violation only if its distance < r_D - tol,
//     a cell holds a duplicate only if two of its level-D samples are both farther than tol from every face,
//     an input point is uncovered only if its distance to U_D > 2 r_D + tol.
//   The tolerance depends on the sampling only, so adding an input cloud never changes (1) or (2). A level whose
//   r_D is below 10 tol cannot be checked (float32 positions far from the origin): it is `unresolved` and counts as
//   one violation, rather than passing a check that could not fail.
// - Samples with a NaN/Inf coordinate cannot be valid: each counts as one spacing violation in every U_D holding it.
//   Input points with a NaN/Inf coordinate or exactly at (0,0,0) (sensor no-returns) are ignored for coverage.
// - Key range: the sampler inserts no point with a coordinate of (2^30 - 8) or more cells of its finest level
//   M (edge C * 2^-M, M = hierarchy.max_depth), so no sample covers one. Such input points are not checked for
//   coverage; they are counted in `input_beyond_key_range`. `max_depth` -1 takes M as the deepest level present
//   (the sampler's is at least that, so the points left out were surely never inserted). The bound is taken a
//   thousandth of a cell short: a point on it may have been refused by the sampler's rounding.
// - Throws std::invalid_argument when the sampling lacks x/y/z or `level` (or the input lacks x/y/z), when C is not
//   finite and positive, when a level value is not an integer in 0..21, or when `max_depth` is not -1 or a level
//   from the deepest one present to 21, or when `through_level` is not -1 or a level in 0..21.
// - `threads` (<= 0: hardware concurrency) splits the per-point loops into fixed chunks; every reduction is a min,
//   max or count, so the report does not depend on the thread count.
// - Cost: one k-d tree build per level over U_D plus one nearest-neighbour query per sample, one per input point and
//   level, and extra radius queries only around violations.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "hpds/points/PointBuffer.hpp"

namespace hpds {

struct LevelReport {
  int level = 0;
  std::size_t count = 0;        ///< samples at this level (non-finite ones included)
  std::size_t union_count = 0;  ///< samples in U_D (levels 0..level)
  double min_nn_over_r = 0.0;   ///< min nearest-neighbour distance in U_D / r_D; +inf with fewer than 2 finite points
  std::size_t spacing_violations = 0;  ///< points of U_D whose nearest neighbour in U_D is closer than r_D - tol
  std::size_t cell_violations = 0;     ///< per level-D cell: (samples farther than tol from every face) - 1, if > 0
  double max_coverage_over_r = 0.0;    ///< max over input points of dist to U_D / r_D; NaN without usable input
  std::size_t coverage_violations = 0; ///< input points farther than 2 r_D + tol from U_D
  bool unresolved = false;             ///< tol > r_D / 10: the stored positions are too coarse to check this level
};

struct VerifyReport {
  double cell_size = 0.0;  ///< C [m]
  double tolerance = 0.0;  ///< tol [m], see the contract
  int key_range_depth = 0;               ///< M, the level whose cells bound the key range (see the contract)
  std::size_t input_points = 0;          ///< points of the input cloud, 0 without one
  std::size_t input_beyond_key_range = 0;  ///< input points beyond the key range: not checked for coverage
  std::vector<LevelReport> levels;  ///< index D = level D, 0..max(max level present, through_level)
  [[nodiscard]] std::size_t total_violations() const;
};

/// Checks `sampling` (see the contract); `input` may be null (no coverage check). `max_depth`: the
/// hierarchy.max_depth the sampling was made with, for the key range, or -1 (see the contract). `through_level`:
/// check levels 0..through_level at least (-1: up to the deepest level present).
[[nodiscard]] VerifyReport verifySampling(const PointBuffer &sampling, double cell_size, const PointBuffer *input,
                                          int threads = 1, int max_depth = -1, int through_level = -1);

/// A fixed-width table, one row per level: level, r_D, count, union, min_nn/r, viol, cells, cover/r ('-' without
/// input), uncov; then the total. A line before it says how many input points lay beyond the key range, if any.
[[nodiscard]] std::string formatReport(const VerifyReport &report);

}  // namespace hpds
