// A jump of the sensor between two consecutive frames of a map: a speed no vehicle reaches. A SLAM system's
// relocalisation (a step of map -> odom), a restarted odometry or a pose of another trajectory puts the next frame's
// points somewhere else than the map's, and the map then holds the surroundings twice, misaligned, without a word.
// The node and `hpds replay` say so (and count it), so that a user can clear the map.
//
// Contract
// - poseJump: the move from `from` (sensor position [m] in the fixed frame, at stamp `from_stamp` [s]) to `to` (at
//   `to_stamp`) when it is longer than kPoseJumpMinMetres and faster than kPoseJumpSpeed; std::nullopt otherwise,
//   and whenever the stamps do not increase (zero stamps, a looped bag), where no speed can be told.
// - Thread-safety: free functions, reentrant.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>

namespace hpds {

/// [m/s] Faster than any ground vehicle or drone mapping with a lidar (180 km/h).
inline constexpr double kPoseJumpSpeed = 50.0;
/// [m] Shorter moves are within what pose noise and a stamp's jitter can make of one sensor period.
inline constexpr double kPoseJumpMinMetres = 2.0;

struct PoseJump {
  double metres = 0.0;   ///< how far the sensor moved
  double seconds = 0.0;  ///< between the two frames' stamps
};

[[nodiscard]] std::optional<PoseJump> poseJump(const Eigen::Vector3d &from, double from_stamp, const Eigen::Vector3d &to,
                                               double to_stamp);

/// One sentence for a log or stderr: how far in how long, the likely causes, and that the map now mixes both poses.
/// `clear_advice`: how this program starts a new map (the node's service, a new replay).
[[nodiscard]] std::string poseJumpWarning(const PoseJump &jump, const std::string &clear_advice);

}  // namespace hpds
