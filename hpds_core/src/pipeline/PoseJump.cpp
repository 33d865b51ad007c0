#include "hpds/pipeline/PoseJump.hpp"

#include <sstream>

namespace hpds {

std::optional<PoseJump> poseJump(const Eigen::Vector3d &from, double from_stamp, const Eigen::Vector3d &to,
                                 double to_stamp) {
  const double seconds = to_stamp - from_stamp;
  if (!(seconds > 0.0)) return std::nullopt;
  const double metres = (to - from).norm();
  if (!(metres > kPoseJumpMinMetres) || !(metres > kPoseJumpSpeed * seconds)) return std::nullopt;
  return PoseJump{metres, seconds};
}

std::string poseJumpWarning(const PoseJump &jump, const std::string &clear_advice) {
  std::ostringstream s;
  s.precision(3);
  s << "the sensor moved " << jump.metres << " m in " << jump.seconds << " s between two frames ("
    << jump.metres / jump.seconds << " m/s: a relocalisation, a restarted odometry or poses of another trajectory?): "
    << "the map now holds the surroundings as placed before and after, misaligned if either pose was wrong";
  if (!clear_advice.empty()) s << "; " << clear_advice;
  return s.str();
}

}  // namespace hpds
