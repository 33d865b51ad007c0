// KITTI odometry pose files: one pose per non-empty line, 12 numbers forming a row-major 3x4 matrix [R | t] that maps
// sensor coordinates into the world frame (translation in the file's units, metres for KITTI).
//
// Contract
// - readKittiPoses returns the poses in file order. Blank (whitespace-only) lines are skipped but still counted for
//   line numbers.
// - Each rotation must be orthonormal with determinant +1 within 1e-3 (KITTI prints ~7 significant digits, so real
//   files deviate by ~1e-6). A rotation that is not orthonormal to double precision is then replaced by the nearest
//   true rotation (SVD projection), so callers always get an exact isometry; one that already is orthonormal is kept
//   bit for bit, so a write/read round trip is exact.
// - writeKittiPoses writes each number in the shortest decimal form that parses back to the identical double
//   (std::to_chars, independent of the global locale), so a write/read round trip is exact.
// - Errors: std::runtime_error whose message starts with the path and, for content errors, gives the 1-based line
//   number: wrong number count, non-numeric token, NaN/Inf, invalid rotation; missing/unreadable file; I/O failure.
//   Also thrown by writeKittiPoses for a non-finite pose.
// - Thread-safety: reentrant; concurrent calls on different paths are safe.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace hpds {

[[nodiscard]] std::vector<Eigen::Isometry3d> readKittiPoses(const std::string &path);

/// Empty when `pose` is rigid as the readers accept it (finite; rotation orthonormal with determinant +1 within
/// 1e-3; bottom row exactly 0 0 0 1), else a sentence saying what is wrong. Pipeline::addFrame applies it to
/// frame.sensor_to_fixed.
[[nodiscard]] std::string rigidPoseProblem(const Eigen::Isometry3d &pose);

void writeKittiPoses(const std::string &path, const std::vector<Eigen::Isometry3d> &poses);

}  // namespace hpds
