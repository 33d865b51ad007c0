// The registration benchmark's inputs: a lidar frame downsampled by hpds (levels 0..d of one hierarchy, with the
// hierarchy's normals and GICP covariances) and by the grid baselines at the same point count.
//
// Contract
// - Frames are in their sensor frame; exact (0,0,0) no-returns and non-finite points are left out for every method.
// - HpdsFrame samples the frame in scan mode once per output level d asked for (the config's cell size), so that
//   levels(d) is what `hpds sample --level d --covariances` and the node output: the samples of levels 0..d (the
//   same samples in every run: levels 0..d do not depend on how deep a hierarchy is built) with the normals and
//   covariances the pipeline gives for output level d (Pipeline::normals: scan mode averages the frame's own points
//   per cell of level d + offset; SampleCovariance.hpp). Samples whose normal could not be estimated keep NaN
//   normals and get the identity covariance.
// - voxelCentroidsAtCount / randomPerVoxelAtCount bisect the cell edge until the count is within `tolerance` of
//   the target (EqualCount.hpp); the grid is anchored at `shift` * cell (zero: at the origin as PCL's VoxelGrid, same
//   cells, same centroids, without VoxelGrid's 32-bit index limit that small leaves on 100 m frames exceed).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
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
  std::vector<Eigen::Matrix3d> covariance;  ///< the identity where no plane is known
  std::vector<std::uint8_t> plane_like;     ///< hpds: 1 where the covariance is a plane (the normal is pinned)
  double cell = 0.0;                        ///< grid baselines: the cell edge that gave this count
  bool count_matched = true;                ///< grid baselines: within the tolerance of the target count
};

/// The finite, non-zero points of a frame, in its sensor frame.
[[nodiscard]] std::vector<Eigen::Vector3d> framePoints(const PointBuffer &points);

class HpdsFrame {
 public:
  /// Samples `points` (sensor frame) with `config` (scan mode, normals and covariances switched on here) once for
  /// every output level in `coarsest`..`deepest`.
  HpdsFrame(const PointBuffer &points, const HpdsConfig &config, int coarsest, int deepest);
  /// Levels 0..d with normals and covariances for output level d; seconds of that estimate in `seconds`.
  [[nodiscard]] SampledCloud levels(int d, double *seconds = nullptr) const;
  [[nodiscard]] std::size_t count(int d) const { return pipelines_.at(d)->outputSamples().size(); }
  /// The level-0 cell [m] the sampling ran with (the resolved one: hierarchy.cell_size 0 means derived).
  [[nodiscard]] double cellSize() const { return pipelines_.begin()->second->config().hierarchy.cell_size; }

 private:
  std::map<int, std::unique_ptr<Pipeline>> pipelines_;  ///< by output level
};

[[nodiscard]] SampledCloud voxelCentroidsAtCount(const std::vector<Eigen::Vector3d> &points, std::size_t target,
                                                 double tolerance,
                                                 const Eigen::Vector3d &shift = Eigen::Vector3d::Zero());
[[nodiscard]] SampledCloud randomPerVoxelAtCount(const std::vector<Eigen::Vector3d> &points, std::size_t target,
                                                 double tolerance, std::uint64_t seed,
                                                 const Eigen::Vector3d &shift = Eigen::Vector3d::Zero());

}  // namespace hpds::bench
