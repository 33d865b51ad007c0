#include "hpds/eval/PoseError.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace hpds {

namespace {
constexpr double kRadToDeg = 57.29577951308232;

double median(std::vector<double> v) {
  const std::size_t n = v.size(), h = n / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(h), v.end());
  if (n % 2 == 1) return v[h];
  const double upper = v[h];
  return 0.5 * (*std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(h)) + upper);
}

double mean(const std::vector<double> &v) {
  double s = 0.0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

// Uniform on the sphere by rejection from the cube, from the engine's raw output (fully specified by the standard,
// unlike its distributions), so a seed gives the same direction everywhere.
Eigen::Vector3d unitDirection(std::mt19937_64 &rng) {
  auto u = [&] { return 2.0 * static_cast<double>(rng() >> 11) * 0x1.0p-53 - 1.0; };
  for (;;) {
    const Eigen::Vector3d v(u(), u(), u());
    const double n2 = v.squaredNorm();
    if (n2 > 1e-12 && n2 <= 1.0) return v / std::sqrt(n2);
  }
}
}  // namespace

PoseError poseError(const Eigen::Isometry3d &estimate, const Eigen::Isometry3d &truth) {
  if (!estimate.matrix().allFinite()) {
    const double inf = std::numeric_limits<double>::infinity();
    return PoseError{inf, inf};
  }
  const Eigen::Isometry3d d = truth.inverse() * estimate;
  // The angle from the quaternion's vector part and scalar (atan2) stays accurate near 0 and 180 degrees, where
  // acos((trace - 1) / 2) loses half the digits.
  const Eigen::Quaterniond q(d.linear());
  const double angle = 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
  return PoseError{d.translation().norm(), angle * kRadToDeg};
}

bool isFailure(const PoseError &e, const FailureLimits &limits) {
  return !(e.translation <= limits.translation) || !(e.rotation_deg <= limits.rotation_deg);
}

ErrorSummary summarizeErrors(const std::vector<PoseError> &errors, const FailureLimits &limits) {
  ErrorSummary s;
  s.count = errors.size();
  if (errors.empty()) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    s.median_translation = s.mean_translation = s.median_rotation_deg = s.mean_rotation_deg = s.failure_rate = nan;
    return s;
  }
  std::vector<double> t, r;
  std::size_t failures = 0;
  for (const PoseError &e : errors) {
    t.push_back(e.translation);
    r.push_back(e.rotation_deg);
    failures += isFailure(e, limits) ? 1 : 0;
  }
  s.median_translation = median(t);
  s.mean_translation = mean(t);
  s.median_rotation_deg = median(r);
  s.mean_rotation_deg = mean(r);
  s.failure_rate = static_cast<double>(failures) / static_cast<double>(errors.size());
  return s;
}

Eigen::Isometry3d perturbedPose(const Eigen::Isometry3d &truth, double translation, double rotation_deg,
                                std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const Eigen::Vector3d axis = unitDirection(rng), shift = unitDirection(rng);
  Eigen::Isometry3d delta = Eigen::Isometry3d::Identity();
  delta.linear() = Eigen::AngleAxisd(rotation_deg / kRadToDeg, axis).toRotationMatrix();
  delta.translation() = translation * shift;
  // Applied on the source side, so poseError(truth * delta, truth) is exactly (translation, rotation_deg).
  return truth * delta;
}

}  // namespace hpds
