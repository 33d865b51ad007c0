// readKittiPoses (KITTI and TUM lines, comments) on the fuzzer's bytes: only std::runtime_error may come out; accepted
// poses must be exact isometries (orthonormal, det +1, finite) and survive writeKittiPoses/readKittiPoses bit for bit.
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "FuzzSupport.hpp"
#include "hpds/io/PoseFile.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
  const std::string path = hpds::fuzz::writeTemp("poses.txt", data, size);
  std::vector<Eigen::Isometry3d> poses;
  try {
    poses = hpds::readKittiPoses(path);
  } catch (const std::runtime_error &) {
    return 0;
  }
  for (const auto &p : poses) {
    if (!p.matrix().allFinite()) hpds::fuzz::violated("non-finite pose accepted");
    const Eigen::Matrix3d r = p.linear();
    if ((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-9)
      hpds::fuzz::violated("accepted rotation is not orthonormal");
    if (std::abs(r.determinant() - 1.0) > 1e-9) hpds::fuzz::violated("accepted rotation has det != 1");
  }
  const std::string again = hpds::fuzz::writeTemp("again.txt", nullptr, 0);
  hpds::writeKittiPoses(again, poses);
  const auto back = hpds::readKittiPoses(again);
  if (back.size() != poses.size()) hpds::fuzz::violated("round trip changed the pose count");
  for (std::size_t i = 0; i < poses.size(); ++i)
    if (std::memcmp(back[i].matrix().data(), poses[i].matrix().data(), 16 * sizeof(double)) != 0)
      hpds::fuzz::violated("round trip changed pose " + std::to_string(i));
  return 0;
}
