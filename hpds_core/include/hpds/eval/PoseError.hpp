// PoseError: how far a registration result is from the true transform, and summaries over many registrations.
//
// Contract
// - Transforms map source coordinates into the target frame. The error of an estimate E against the truth T is the
//   residual motion T^-1 E: its translation norm [m] and its rotation angle [deg, 0..180].
// - A registration fails when either exceeds its limit (defaults 0.2 m, 1 deg); a non-finite estimate fails and
//   counts with infinite errors (so medians and means never hide it).
// - summarizeErrors: median (the mean of the two middle values for an even count) and mean of each error, the
//   failure rate in [0, 1], over every entry; NaN statistics for an empty list.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hpds {

struct PoseError {
  double translation = 0.0;  ///< [m]
  double rotation_deg = 0.0;  ///< [deg]
};

struct FailureLimits {
  double translation = 0.2;  ///< [m]
  double rotation_deg = 1.0;  ///< [deg]
};

[[nodiscard]] PoseError poseError(const Eigen::Isometry3d &estimate, const Eigen::Isometry3d &truth);
[[nodiscard]] bool isFailure(const PoseError &error, const FailureLimits &limits = {});

struct ErrorSummary {
  std::size_t count = 0;
  double median_translation = 0.0, mean_translation = 0.0;  ///< [m]
  double median_rotation_deg = 0.0, mean_rotation_deg = 0.0;
  double failure_rate = 0.0;  ///< failures / count
};

[[nodiscard]] ErrorSummary summarizeErrors(const std::vector<PoseError> &errors, const FailureLimits &limits = {});

/// `truth` moved by a rigid perturbation of exactly `translation` [m] and `rotation_deg` about directions drawn from
/// `seed` (uniform on the sphere, deterministic): a start for registration at a known distance from the answer.
[[nodiscard]] Eigen::Isometry3d perturbedPose(const Eigen::Isometry3d &truth, double translation, double rotation_deg,
                                              std::uint64_t seed);

}  // namespace hpds
