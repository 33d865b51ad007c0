#include "hpds/io/PoseFile.hpp"

#include "io/FileAccess.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <system_error>

namespace hpds {
namespace {

using io_detail::fail;
using io_detail::FilePtr;
using io_detail::quote;
using io_detail::requireRegularFile;


[[noreturn]] void failLine(const std::string &path, std::size_t line, const std::string &what) {
  throw std::runtime_error(path + ":" + std::to_string(line) + ": " + what);
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

// Deviation below which a rotation is already as orthonormal as doubles allow; re-projecting it would only move bits
// and break the exact write/read round trip.
constexpr double kExactTolerance = 1e-12;
constexpr double kAcceptTolerance = 1e-3;

double orthonormalityError(const Eigen::Matrix3d &r) {
  return (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

// Empty, or why r is no rotation within kAcceptTolerance.
std::string rotationProblem(const Eigen::Matrix3d &r, double *err_out = nullptr) {
  const double err = orthonormalityError(r);
  const double det = r.determinant();
  if (err_out) *err_out = err;
  if (err <= kAcceptTolerance && std::abs(det - 1.0) <= kAcceptTolerance) return {};
  char buf[160];
  std::snprintf(buf, sizeof buf, "rotation part is not a rotation (max |R^T R - I| = %.3g, det = %.6g; tolerance 1e-3)",
                err, det);
  return buf;
}

}  // namespace

std::string rigidPoseProblem(const Eigen::Isometry3d &pose) {
  const Eigen::Matrix4d &m = pose.matrix();
  if (!m.allFinite()) return "pose is not finite";
  if (m(3, 0) != 0.0 || m(3, 1) != 0.0 || m(3, 2) != 0.0 || m(3, 3) != 1.0)
    return "pose's bottom row is not 0 0 0 1 (not a rigid transform)";
  return rotationProblem(pose.linear());
}

std::vector<Eigen::Isometry3d> readKittiPoses(const std::string &path, std::size_t caller_alignment) {
  PoseCorrection ignored;
  return readKittiPoses(path, ignored, caller_alignment);
}

std::string poseCorrectionWarning(const std::string &path, const PoseCorrection &correction) {
  if (!(correction.largest > kPoseCorrectionWarning)) return {};
  char buf[480];
  std::snprintf(buf, sizeof buf,
                "--poses: '%s' line %zu: the rotation part is off a true rotation by %.2g (scaled or printed with too "
                "few digits); it was replaced by the nearest rotation, which moves a point 100 m from the sensor by "
                "up to %.3g m against the matrix as written. Write the poses with more digits",
                path.c_str(), correction.line, correction.largest, 100.0 * correction.largest);
  return buf;
}

std::vector<Eigen::Isometry3d> readKittiPoses(const std::string &path, PoseCorrection &correction,
                                              std::size_t caller_alignment) {
  // The vector is allocated here, aligned for this library's Eigen: code whose Eigen expects more would load its
  // elements with instructions that fault on them.
  if (caller_alignment > alignof(Eigen::Isometry3d))
    throw std::invalid_argument(
        "hpds::readKittiPoses: the calling code is built with " + std::to_string(caller_alignment) +
        "-byte Eigen alignment (-mavx, -march=native), hpds with " + std::to_string(alignof(Eigen::Isometry3d)) +
        ": the poses' vector, allocated by hpds, would not be aligned for it. Compile the calling code with "
        "-DEIGEN_MAX_STATIC_ALIGN_BYTES=" + std::to_string(alignof(Eigen::Isometry3d)) +
        ", or build hpds with the same flags");
  correction = PoseCorrection{};
  requireRegularFile(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open: ") + std::strerror(errno));

  std::vector<Eigen::Isometry3d> poses;
  std::string line;
  std::size_t line_no = 0;
  // The format of the file's first pose line (12: KITTI, 8: TUM); a file mixing them is refused, as its lines could
  // not all mean what they say.
  std::size_t format = 0, format_line = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::array<double, 12> v{};
    std::size_t count = 0;
    const char *p = line.data();
    const char *end = p + line.size();
    while (p < end && isSpace(*p)) ++p;
    if (p < end && *p == '#') continue;  // a comment, as TUM files start with
    while (true) {
      while (p < end && isSpace(*p)) ++p;
      if (p == end) break;
      const char *tok_end = p;
      while (tok_end < end && !isSpace(*tok_end)) ++tok_end;
      const std::string token(p, tok_end);
      // from_chars is locale-independent (a German locale must not turn "1.5" into an error) but rejects '+'.
      const char *num = (*p == '+' && tok_end - p > 1) ? p + 1 : p;
      double value = 0.0;
      const auto res = std::from_chars(num, tok_end, value);
      if (res.ec == std::errc::result_out_of_range) failLine(path, line_no, "number " + quote(token) + " is out of range");
      if (res.ec != std::errc() || res.ptr != tok_end) failLine(path, line_no, quote(token) + " is not a number");
      if (!std::isfinite(value)) failLine(path, line_no, "non-finite value " + quote(token));
      if (count < v.size()) v[count] = value;
      ++count;
      p = tok_end;
    }
    if (count == 0) continue;
    if (count != 12 && count != 8)
      failLine(path, line_no,
               "expected 12 numbers (KITTI: a row-major 3x4 [R|t]) or 8 (TUM: time x y z qx qy qz qw), found " +
                   std::to_string(count));
    if (format == 0) {
      format = count;
      format_line = line_no;
    } else if (count != format) {
      failLine(path, line_no,
               std::to_string(count) + " numbers (" + (count == 12 ? "KITTI" : "TUM") + "), but line " +
                   std::to_string(format_line) + " had " + std::to_string(format) + " (" +
                   (format == 12 ? "KITTI" : "TUM") + "): one format per file");
    }

    Eigen::Matrix3d r;
    Eigen::Vector3d t;
    if (count == 12) {
      for (int row = 0; row < 3; ++row) {
        for (int col = 0; col < 3; ++col) r(row, col) = v[row * 4 + col];
        t(row) = v[row * 4 + 3];
      }
      double err = 0.0;
      if (const std::string why = rotationProblem(r, &err); !why.empty()) failLine(path, line_no, why);
      if (err > kExactTolerance) {
        // Nearest rotation in the Frobenius sense; det stays +1 because R was already within 1e-3 of a rotation.
        // R - UV^T = U (S - I) V^T: a point at distance d moves by at most d max|s - 1|, the singular values s being
        // the square roots of R^T R's eigenvalues.
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> gram(r.transpose() * r, Eigen::EigenvaluesOnly);
        const double moved = (gram.eigenvalues().array().max(0.0).sqrt() - 1.0).abs().maxCoeff();
        if (moved > correction.largest) correction = PoseCorrection{moved, line_no};
        const Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
        r = svd.matrixU() * svd.matrixV().transpose();
      }
    } else {
      // TUM: the time stamp (v[0]) is not used, poses are matched to frames by order as KITTI's are.
      t = Eigen::Vector3d(v[1], v[2], v[3]);
      const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
      const double norm = q.norm();
      if (!(std::abs(norm - 1.0) <= kAcceptTolerance)) {
        char buf[160];
        std::snprintf(buf, sizeof buf, "quaternion qx qy qz qw has norm %.6g, not 1 (tolerance 1e-3)", norm);
        failLine(path, line_no, buf);
      }
      r = q.normalized().toRotationMatrix();
    }
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = r;
    pose.translation() = t;
    poses.push_back(pose);
  }
  if (in.bad()) fail(path, std::string("read failed: ") + std::strerror(errno));
  return poses;
}

void writeKittiPoses(const std::string &path, const std::vector<Eigen::Isometry3d> &poses) {
  std::string text;
  text.reserve(poses.size() * 12 * 25);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Matrix4d m = poses[i].matrix();
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 4; ++col) {
        const double value = m(row, col);
        if (!std::isfinite(value)) fail(path, "pose " + std::to_string(i) + " has a non-finite element");
        // Shortest representation that parses back to the same double; locale-independent.
        char buf[32];
        const auto res = std::to_chars(buf, buf + sizeof buf, value);
        text.append(buf, res.ptr);
        text += (row == 2 && col == 3) ? '\n' : ' ';
      }
    }
  }

  io_detail::OutputFile file(path);
  file.write(text.data(), text.size());
  file.close();
}

std::string poseCountMismatch(const std::string &poses_path, std::size_t poses, std::size_t inputs) {
  return "--poses: '" + poses_path + "' has " + std::to_string(poses) + " poses for " + std::to_string(inputs) +
         " inputs: one pose per input, by order (line K poses input K; a TUM line's time is not matched to the "
         "frames)";
}

}  // namespace hpds
