// hpds: the one-call API. Downsample one point cloud to a hierarchical additive Poisson-disk sampling, optionally
// with normals, in one call; `hpds::Pipeline` (hpds/pipeline/Pipeline.hpp) is the streaming interface behind it
// (frames with poses, map mode).
//
// Contract
// - `points` are in metres; the sensor (the viewpoint normals face, and input.min_range/max_range are measured from)
//   is at the origin, or at `viewpoint` in the overload that takes one (a cloud kept in another frame). NaN/Inf
//   points, exact (0,0,0) no-returns (input.skip_zero_points) and points outside input.min_range/max_range are
//   skipped; they never appear in the result. So are points beyond the exact cell-key range of the finest level
//   (|coordinate| >= 2^30 cells of level hierarchy.max_depth: 1.55e7 m at the defaults; 8.4e6 to 1.7e7 m for any
//   output.spacing above 1.4 cm with the derived cell; less for finer spacings, a larger hierarchy.max_depth or a
//   smaller fixed cell): Samples::out_of_range counts them. Sample georeferenced points relative to a local origin.
// - The samples are those `hpds sample` writes for the same points and config (one frame, its mode and seed), in
//   the same order: levels 0..D of the output level D (output.level / output.spacing).
// - Deterministic: the same points and config give the same samples, whatever config.threads is.
// - Throws std::invalid_argument for an invalid config (the message names the key, as the CLI does), a viewpoint
//   that is not finite, or more than 2^32 - 1 points.
// - Thread-safe: calls share no state; each call may use config.threads worker threads.
// - Streams (frames with poses, map mode, save/load): hpds::Pipeline with hpds::frameFromPoints
//   (hpds/points/Frame.hpp), hpds::saveMap / loadMap (hpds/io/HierarchyFile.hpp).
// - Memory: the call holds the whole cloud and its hierarchy at once, about 190 bytes per input point with the
//   shipped normals for a lidar cloud, of which a fifth or less become samples (measured: 4 M points peaked at
//   0.76 GB on one thread, 1.1 GB on two); more where most points become samples (a cloud already sparser than the
//   spacing: about 350 bytes per point).
#pragma once

#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/util/Interrupt.hpp"

namespace hpds {

/// The result of downsample(): one entry per sample in every vector.
struct Samples {
  std::vector<std::uint32_t> index;  ///< position of the sample in the input
  std::vector<std::uint8_t> level;   ///< hierarchy level 0..D of the sample
  /// With config.normals.enabled (else empty): unit normal facing the sensor (except a near-horizontal one nearly
  /// perpendicular to the ray, a single scan line's, which faces up where the sample is below the sensor; thresholds
  /// in hpds/normals/NormalEstimator.hpp), and curvature l0 / (l0 + l1 + l2); NaN where a normal could not be estimated
  /// (too few neighbours, degenerate neighbourhood), as in PCL.
  std::vector<Eigen::Vector3f> normal;
  std::vector<float> curvature;
  /// With config.normals.covariances (else empty): the sample's covariance for generalized ICP
  /// (hpds/normals/SampleCovariance.hpp: dimensionless, a plane's; at the default normals.covariance_k its small
  /// axis is the normal of the 30 nearest output samples, not `normal`; the identity on one scan line and where
  /// `normal` is NaN): never NaN, so that every one can go to GICP as it is.
  std::vector<Eigen::Matrix3f> covariance;
  /// Input points left out, by reason (see the contract): NaN/Inf coordinates, exact (0,0,0) no-returns, outside
  /// input.min_range/max_range, and beyond the exact key range of the finest level. The last is the one a caller
  /// may not expect (georeferenced coordinates): when it is not 0, part of the cloud was not sampled.
  std::uint64_t skipped_invalid = 0, skipped_zero = 0, skipped_range = 0, out_of_range = 0;
  /// mode: map only: samples the map gave up to stay within map.max_samples (the farthest from the viewpoint go
  /// first; the map's other rule, map.evict_distance, acts before a frame and so never in one call). Not 0: the
  /// result no longer covers the cloud; raise map.max_samples (0 = no cap) or use scan mode for one cloud.
  std::uint64_t evicted = 0;
  /// The resolution the call ran with (resolveOutput): the samples are levels 0..output_level, at least `radius`
  /// metres apart, of a hierarchy whose level-0 cells are `cell_size` metres wide.
  int output_level = -1;
  double radius = 0.0, cell_size = 0.0;

  [[nodiscard]] std::size_t size() const { return index.size(); }
};

/// Downsamples `points` with `config` (see the contract).
[[nodiscard]] Samples downsample(const std::vector<Eigen::Vector3f> &points, const HpdsConfig &config = HpdsConfig{});
/// The same with the sensor at `viewpoint` (finite; std::invalid_argument otherwise), in the points' frame.
[[nodiscard]] Samples downsample(const std::vector<Eigen::Vector3f> &points, const HpdsConfig &config,
                                 const Eigen::Vector3d &viewpoint);
/// downsample for double-precision points (georeferenced coordinates: float32 keeps 0.5 m at 5e6 m), sampled at their
/// full precision, as `hpds sample` samples a file with float64 x y z. Its own name: an overload would make existing
/// calls with a braced list (`downsample({}, config)`) ambiguous.
[[nodiscard]] Samples downsampleDoubles(const std::vector<Eigen::Vector3d> &points,
                                        const HpdsConfig &config = HpdsConfig{});
[[nodiscard]] Samples downsampleDoubles(const std::vector<Eigen::Vector3d> &points, const HpdsConfig &config,
                                        const Eigen::Vector3d &viewpoint);
/// The same, stopped by another thread: once `interrupt` is set they throw hpds::Interrupted (hpds/util/Interrupt.hpp)
/// at their next stage boundary, within about a second on millions of points (a binding's Ctrl-C, a cancel button).
[[nodiscard]] Samples downsample(const std::vector<Eigen::Vector3f> &points, const HpdsConfig &config,
                                 const Eigen::Vector3d &viewpoint, const std::atomic<bool> &interrupt);
[[nodiscard]] Samples downsampleDoubles(const std::vector<Eigen::Vector3d> &points, const HpdsConfig &config,
                                        const Eigen::Vector3d &viewpoint, const std::atomic<bool> &interrupt);

/// Reads a config file in config/hpds.yaml's format over the defaults, with the same validation as the CLI and the
/// node. Throws std::invalid_argument naming the key (or the file, when it cannot be read or parsed).
[[nodiscard]] HpdsConfig loadConfig(const std::string &path);

}  // namespace hpds
