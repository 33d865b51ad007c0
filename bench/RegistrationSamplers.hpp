// The registration benchmark's inputs: a lidar frame downsampled by hpds (levels 0..d of one hierarchy, with the
// hierarchy's normals and GICP covariances) and by the grid baselines at the same point count.
//
// Contract
// - Frames are in their sensor frame; exact (0,0,0) no-returns and non-finite points are left out for every method.
// - HpdsFrame builds one scan-mode hierarchy per frame (the config's cell size; levels down to the deepest level
//   asked for plus the normals' level offset) and serves every level from it: levels(d) are the samples of levels
//   0..d with normals and covariances estimated for output level d (NormalEstimator.hpp, SampleCovariance.hpp).
//   Samples whose normal could not be estimated keep NaN normals and an invalid covariance.
// - voxelCentroidsAtCount / randomPerVoxelAtCount bisect the cell edge until the count is within `tolerance` of
//   the target (EqualCount.hpp); the grid is anchored at the origin as PCL's VoxelGrid (same cells, same centroids,
//   without VoxelGrid's 32-bit index limit that small leaves on 100 m frames exceed).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/eval/EqualCount.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds::bench {

/// A downsampled frame. `normal` and `covariance` are empty for the grid baselines (the registration computes
/// its own k-NN ones), else parallel to `xyz`.
struct SampledCloud {
  std::vector<Eigen::Vector3d> xyz;
  std::vector<Eigen::Vector3d> normal;      ///< NaN where not estimated
  std::vector<Eigen::Matrix3d> covariance;  ///< NaN where not estimated
  std::vector<std::uint8_t> plane_like;     ///< hpds: 1 where the covariance is a plane (the normal is pinned)
  double cell = 0.0;                        ///< grid baselines: the cell edge that gave this count
  bool count_matched = true;                ///< grid baselines: within the tolerance of the target count
};

/// The finite, non-zero points of a frame, in its sensor frame.
[[nodiscard]] std::vector<Eigen::Vector3d> framePoints(const PointBuffer &points);

class HpdsFrame {
 public:
  /// Samples `points` (sensor frame) with `config` (scan mode, normals and covariances switched on here) down to
  /// level `deepest` (+ the normals' offset).
  HpdsFrame(const PointBuffer &points, HpdsConfig config, int deepest);
  /// Levels 0..d with normals and covariances for output level d; seconds of that estimate in `seconds`.
  [[nodiscard]] SampledCloud levels(int d, double *seconds = nullptr) const;
  [[nodiscard]] std::size_t count(int d) const { return pipeline_.hierarchy().samplesUpTo(d).size(); }

 private:
  HpdsConfig config_;
  Pipeline pipeline_;
};

[[nodiscard]] SampledCloud voxelCentroidsAtCount(const std::vector<Eigen::Vector3d> &points, std::size_t target,
                                                 double tolerance);
[[nodiscard]] SampledCloud randomPerVoxelAtCount(const std::vector<Eigen::Vector3d> &points, std::size_t target,
                                                 double tolerance, std::uint64_t seed);

}  // namespace hpds::bench
