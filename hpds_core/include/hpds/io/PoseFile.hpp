// Pose files: one pose per line that maps sensor coordinates into the world frame (translation in the file's units,
// metres for KITTI). Two formats, one per file: KITTI odometry (12 numbers, a row-major 3x4 matrix [R | t]) and TUM
// (8 numbers: time x y z qx qy qz qw, as SLAM tools and evo write trajectories).
//
// Contract
// - readKittiPoses reads either format and returns the poses in file order: one pose per frame, matched by order (a
//   TUM line's time is not used). Blank lines and comment lines (first non-blank character '#') are skipped but
//   still counted for line numbers. writeKittiPoses writes KITTI.
// - Each KITTI rotation must be orthonormal with determinant +1 within 1e-3 (KITTI prints ~7 significant digits, so
//   real files deviate by ~1e-6). A rotation that is not orthonormal to double precision is then replaced by the nearest
//   true rotation (SVD projection), so callers always get an exact isometry; one that already is orthonormal is kept
//   bit for bit, so a write/read round trip is exact. How far the projection moves points is reported
//   (PoseCorrection) and warned about beyond what printing rounds (poseCorrectionWarning). Each TUM quaternion must have norm 1 within 1e-3 and is
//   normalised.
// - writeKittiPoses writes each number in the shortest decimal form that parses back to the identical double
//   (std::to_chars, independent of the global locale), so a write/read round trip is exact.
// - Errors: std::runtime_error whose message starts with the path and, for content errors, gives the 1-based line
//   number: wrong number count, formats mixed, non-numeric token, NaN/Inf, invalid rotation or quaternion;
//   missing/unreadable file; I/O failure.
//   Also thrown by writeKittiPoses for a non-finite pose.
// - Alignment: the returned vector is allocated by the library, aligned as its Eigen aligns Eigen::Isometry3d (16
//   bytes for x86-64's baseline). Code built with vector flags that align it more (-mavx: 32, -march=native) would
//   fault loading such elements: readKittiPoses then throws std::invalid_argument saying so (its defaulted last
//   argument is the caller's alignment) rather than return them. Such code compiles its calls with
//   -DEIGEN_MAX_STATIC_ALIGN_BYTES=16, or builds hpds with the same flags. Frame and the one-call API do not care.
// - Thread-safety: reentrant; concurrent calls on different paths are safe.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <string>
#include <vector>

namespace hpds {

/// `caller_alignment`: leave it; its default is the caller's alignment of Eigen::Isometry3d (see the contract).
[[nodiscard]] std::vector<Eigen::Isometry3d> readKittiPoses(const std::string &path,
                                                            std::size_t caller_alignment = alignof(Eigen::Isometry3d));

/// What reading a pose file changed: the largest correction of a KITTI rotation replaced by the nearest true rotation,
/// as the distance it moves a point 1 m from the sensor (the largest |sigma - 1| of the rotation part's singular
/// values: exact, the spectral norm of the change), and the 1-based line of that pose (0: nothing corrected).
struct PoseCorrection {
  double largest = 0.0;
  std::size_t line = 0;
};
/// readKittiPoses, reporting its rotation corrections in `correction`.
[[nodiscard]] std::vector<Eigen::Isometry3d> readKittiPoses(const std::string &path, PoseCorrection &correction,
                                                            std::size_t caller_alignment = alignof(Eigen::Isometry3d));

/// [m per m] Corrections up to this are the rounding of a printed pose (KITTI prints ~7 significant digits: ~1e-7;
/// 6 digits: ~1e-6); above it the file's rotations were scaled or cut short, and the correction moves far points by
/// more than a lidar's noise at 100 m.
inline constexpr double kPoseCorrectionWarning = 1e-5;
/// The warning for a file whose largest correction passes kPoseCorrectionWarning (it names the line and what the
/// correction moves a point 100 m out by), else "".
[[nodiscard]] std::string poseCorrectionWarning(const std::string &path, const PoseCorrection &correction);

/// Empty when `pose` is rigid as the readers accept it (finite; rotation orthonormal with determinant +1 within
/// 1e-3; bottom row exactly 0 0 0 1), else a sentence saying what is wrong. Pipeline::addFrame applies it to
/// frame.sensor_to_fixed.
[[nodiscard]] std::string rigidPoseProblem(const Eigen::Isometry3d &pose);

/// The error for a pose file of `poses` poses given for `inputs` frames (--poses names the option in the CLI and the
/// tiled map build alike): poses are matched to frames by order.
[[nodiscard]] std::string poseCountMismatch(const std::string &poses_path, std::size_t poses, std::size_t inputs);

void writeKittiPoses(const std::string &path, const std::vector<Eigen::Isometry3d> &poses);

}  // namespace hpds
