// Principal component analysis of a small neighbourhood: normal, eigenvalues, curvature, sphericity.
//
// Contract: eigenvalues ascending (l0 <= l1 <= l2) of the covariance of the neighbours about their centroid;
// `normal` is the eigenvector of l0 (unit, sign arbitrary). `valid` is false for fewer than 3 points or a
// degenerate (point- or line-like) neighbourhood, where the normal direction is undefined.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hpds {

struct LocalPca {
  double normal[3] = {0.0, 0.0, 0.0};
  double l0 = 0.0, l1 = 0.0, l2 = 0.0;
  bool valid = false;

  /// l0 / (l0 + l1 + l2): PCL's "curvature", the paper's surface variation.
  [[nodiscard]] double surfaceVariation() const { return (l0 + l1 + l2) > 0.0 ? l0 / (l0 + l1 + l2) : 0.0; }
  /// l0 / l2: the paper's sphericity.
  [[nodiscard]] double sphericity() const { return l2 > 0.0 ? l0 / l2 : 0.0; }
};

/// Accumulates points (relative to a reference point, so that large coordinates keep their precision).
class PcaAccumulator {
 public:
  explicit PcaAccumulator(const double reference[3]) : ref_{reference[0], reference[1], reference[2]} {}
  void add(const double p[3]) { add(p[0], p[1], p[2]); }
  void add(double px, double py, double pz) {
    const double x = px - ref_[0], y = py - ref_[1], z = pz - ref_[2];
    ++n_;
    s_[0] += x, s_[1] += y, s_[2] += z;
    ss_[0] += x * x, ss_[1] += x * y, ss_[2] += x * z, ss_[3] += y * y, ss_[4] += y * z, ss_[5] += z * z;
  }
  /// `p` counted `weight` times (a representative of that many points).
  void add(const double p[3], std::size_t weight) {
    const double w = static_cast<double>(weight);
    const double x = p[0] - ref_[0], y = p[1] - ref_[1], z = p[2] - ref_[2];
    n_ += weight;
    s_[0] += w * x, s_[1] += w * y, s_[2] += w * z;
    ss_[0] += w * x * x, ss_[1] += w * x * y, ss_[2] += w * x * z, ss_[3] += w * y * y, ss_[4] += w * y * z,
        ss_[5] += w * z * z;
  }
  /// add(xyz + 3 * slot[t]) for every t < count with d2[t] < r2, in order: the same sums, bit for bit, kept in
  /// registers through the loop (add() stores nine sums a point; in the normal sweeps that was a sixth of their time).
  void addWithin(const double *xyz, const std::uint32_t *slot, const double *d2, std::size_t count, double r2) {
    double s0 = s_[0], s1 = s_[1], s2 = s_[2];
    double q0 = ss_[0], q1 = ss_[1], q2 = ss_[2], q3 = ss_[3], q4 = ss_[4], q5 = ss_[5];
    std::size_t n = n_;
    for (std::size_t t = 0; t < count; ++t) {
      if (!(d2[t] < r2)) continue;
      const double *p = xyz + 3 * std::size_t(slot[t]);
      const double x = p[0] - ref_[0], y = p[1] - ref_[1], z = p[2] - ref_[2];
      ++n;
      s0 += x, s1 += y, s2 += z;
      q0 += x * x, q1 += x * y, q2 += x * z, q3 += y * y, q4 += y * z, q5 += z * z;
    }
    s_[0] = s0, s_[1] = s1, s_[2] = s2;
    ss_[0] = q0, ss_[1] = q1, ss_[2] = q2, ss_[3] = q3, ss_[4] = q4, ss_[5] = q5;
    n_ = n;
  }
  [[nodiscard]] std::size_t count() const { return n_; }
  /// Eigen-decomposition of the covariance; `accurate` uses Eigen's iterative solver, else its closed form.
  [[nodiscard]] LocalPca solve(bool accurate = true) const;
  /// The same result as solve() for normal estimation, faster: the closed form on the scale-free characteristic
  /// cubic with cheap acos/cos approximations polished by Newton (no libm trigonometry), and only the smallest
  /// eigenvalue's eigenvector. Agrees with the iterative solver to ~1e-15 of the trace (eigenvalues) and
  /// ~1e-15 / (relative gap l1 - l0) rad (normal); more accurate than Eigen's closed form (solve(false)) where l0
  /// nears l1.
  [[nodiscard]] LocalPca solveNormal() const;
  /// The mean of the points added, relative to the reference point (zero when none were).
  void mean(double m[3]) const;
  /// The unit eigenvector (sign arbitrary) of eigenvalue `l` of the covariance, e.g. l2 of solveNormal() for the
  /// direction of a line-like neighbourhood: the largest cross product of two rows of C - l I, accurate to about
  /// (error of l) / (gap to the nearest other eigenvalue) rad. False where that gap is below about 1e-4 of the
  /// trace (the direction is then not defined well enough by an l from solveNormal) or nothing was added.
  [[nodiscard]] bool eigenvector(double l, double v[3]) const;

 private:
  /// The covariance about the mean: xx xy xz yy yz zz.
  void covariance(double c[6]) const;
  /// The kernel direction of C - l I from its rows' cross products; false below `floor` (squared norm).
  static bool kernelDirection(const double c[6], double l, double floor, double v[3]);

  double ref_[3];
  double s_[3] = {0, 0, 0};
  double ss_[6] = {0, 0, 0, 0, 0, 0};
  std::size_t n_ = 0;
};

}  // namespace hpds
