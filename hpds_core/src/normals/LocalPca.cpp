#include "hpds/normals/LocalPca.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace hpds {

LocalPca PcaAccumulator::solve(bool accurate) const {
  LocalPca out;
  if (n_ < 3) return out;
  const double inv = 1.0 / static_cast<double>(n_);
  const double mx = s_[0] * inv, my = s_[1] * inv, mz = s_[2] * inv;
  Eigen::Matrix3d c;
  c(0, 0) = ss_[0] * inv - mx * mx;
  c(0, 1) = c(1, 0) = ss_[1] * inv - mx * my;
  c(0, 2) = c(2, 0) = ss_[2] * inv - mx * mz;
  c(1, 1) = ss_[3] * inv - my * my;
  c(1, 2) = c(2, 1) = ss_[4] * inv - my * mz;
  c(2, 2) = ss_[5] * inv - mz * mz;
  if (!c.allFinite()) return out;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  if (accurate)
    es.compute(c);
  else
    es.computeDirect(c);
  if (es.info() != Eigen::Success) return out;
  const Eigen::Vector3d ev = es.eigenvalues().cwiseMax(0.0);  // round-off can make l0 slightly negative
  out.l0 = ev(0);
  out.l1 = ev(1);
  out.l2 = ev(2);
  const Eigen::Vector3d nrm = es.eigenvectors().col(0).normalized();
  out.normal[0] = nrm.x();
  out.normal[1] = nrm.y();
  out.normal[2] = nrm.z();
  // A plane needs two clearly non-zero spreads; otherwise the smallest-eigenvalue direction is not a normal.
  const double trace = out.l0 + out.l1 + out.l2;
  out.valid = trace > 0.0 && out.l1 > 1e-9 * trace && nrm.allFinite();
  return out;
}

void PcaAccumulator::mean(double m[3]) const {
  const double inv = n_ ? 1.0 / static_cast<double>(n_) : 0.0;
  for (int a = 0; a < 3; ++a) m[a] = s_[a] * inv;
}

void PcaAccumulator::covariance(double c[6]) const {
  const double inv = 1.0 / static_cast<double>(n_);
  const double mx = s_[0] * inv, my = s_[1] * inv, mz = s_[2] * inv;
  c[0] = ss_[0] * inv - mx * mx, c[1] = ss_[1] * inv - mx * my, c[2] = ss_[2] * inv - mx * mz;
  c[3] = ss_[3] * inv - my * my, c[4] = ss_[4] * inv - my * mz, c[5] = ss_[5] * inv - mz * mz;
}

bool PcaAccumulator::kernelDirection(const double c[6], double l, double floor, double out[3]) {
  const double xx = c[0], xy = c[1], xz = c[2], yy = c[3], yz = c[4], zz = c[5];
  const double a = xx - l, d = yy - l, f = zz - l;
  const double v0[3] = {xy * yz - xz * d, xz * xy - a * yz, a * d - xy * xy};  // row0 x row1
  const double v1[3] = {xy * f - xz * yz, xz * xz - a * f, a * yz - xy * xz};  // row0 x row2
  const double v2[3] = {d * f - yz * yz, yz * xz - xy * f, xy * yz - d * xz};  // row1 x row2
  const double n0 = v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2];
  const double n1 = v1[0] * v1[0] + v1[1] * v1[1] + v1[2] * v1[2];
  const double n2 = v2[0] * v2[0] + v2[1] * v2[1] + v2[2] * v2[2];
  const double *v = v0;
  double nn = n0;
  if (n1 > nn) v = v1, nn = n1;
  if (n2 > nn) v = v2, nn = n2;
  if (!(nn > floor) || !std::isfinite(nn)) return false;
  const double s = 1.0 / std::sqrt(nn);
  out[0] = v[0] * s, out[1] = v[1] * s, out[2] = v[2] * s;
  return true;
}

bool PcaAccumulator::eigenvector(double l, double v[3]) const {
  if (n_ == 0) return false;
  double c[6];
  covariance(c);
  const double trace = c[0] + c[3] + c[5];
  // The largest row cross product of C - l I is the product of l's gaps to the other two eigenvalues (each at most
  // the trace) times 0.58..1: below 1e-5 of the trace squared, l is within about 1e-4 of the trace of another
  // eigenvalue, and the direction would rest on l's last digits (solveNormal's l1 and l2 lose about half their
  // digits when close: 0.15 rad off at a gap of 1e-8).
  const double t2 = trace * trace;
  return trace > 0.0 && kernelDirection(c, l, 1e-10 * t2 * t2, v);
}

LocalPca PcaAccumulator::solveNormal() const {
  LocalPca out;
  if (n_ < 3) return out;
  double c[6];
  covariance(c);
  const double xx = c[0], xy = c[1], xz = c[2], yy = c[3], yz = c[4], zz = c[5];
  const double trace = xx + yy + zz;
  if (!std::isfinite(trace + xy + xz + yz) || !(trace > 0.0)) return out;
  // Eigenvalues m + sqrt(p) t of C = m I + B (m = trace / 3, p = tr(B^2) / 6), where t are the roots of the
  // scale-free cubic h(t) = t^3 - 3 t - 2 r, r = det(B) / (2 p^1.5) in [-1, 1]; the smallest, t0, is in [-2, -1].
  const double m = trace / 3.0, b00 = xx - m, b11 = yy - m, b22 = zz - m;
  const double p = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (xy * xy + xz * xz + yz * yz)) / 6.0;
  const double sp = std::sqrt(p);
  if (!(p * sp > 0.0)) {  // isotropic (to round-off): every direction is an eigenvector, as Eigen's identity
    out.l0 = out.l1 = out.l2 = m;
    out.normal[0] = 1.0;
    out.valid = true;
    return out;
  }
  const double det = b00 * (b11 * b22 - yz * yz) - xy * (xy * b22 - yz * xz) + xz * (xy * yz - b11 * xz);
  const double r = std::clamp(0.5 * det / (p * sp), -1.0, 1.0);
  // Start: t0 = 2 cos(acos(r) / 3 + 2 pi / 3) = -2 cos(w), w = (pi - acos(r)) / 3 in [0, pi / 3], with cheap
  // approximations (acos: Abramowitz & Stegun 4.4.45, |error| < 7e-5; cos: Taylor to w^8, < 5e-7) instead of the
  // libm atan2, sin and cos of Eigen's closed form; then Newton.
  const double ar = std::fabs(r);
  double ac = std::sqrt(1.0 - ar) * (1.5707288 + ar * (-0.2121144 + ar * (0.0742610 - 0.0187293 * ar)));
  if (r < 0.0) ac = M_PI - ac;
  const double w = (M_PI - ac) / 3.0, w2 = w * w;
  double t = -2.0 * (1.0 + w2 * (-0.5 + w2 * (1.0 / 24.0 + w2 * (-1.0 / 720.0 + w2 / 40320.0))));
  double l, l1, l2;
  if (sp < 1e-4 * m) {
    // Nearly isotropic: Newton on h, whose roots are well apart at this scale. Below t0 (< -1) h is increasing
    // and concave: the iterates rise monotonically to t0 (a start just above t0 first lands below it).
    if (!(t < -1.0 - 1e-6)) t = -2.0;
    for (int it = 0; it < 100; ++it) {
      const double hp = 3.0 * (t * t - 1.0);
      if (!(hp > 0.0)) break;
      const double step = -((t * t - 3.0) * t - 2.0 * r) / hp;
      t += step;
      if (std::fabs(step) <= 1e-15 || step * step * std::fabs(3.0 * t) <= 1e-15 * hp) break;
    }
    t = std::clamp(t, -2.0, -1.0);
    const double disc = std::sqrt(std::max(0.0, 12.0 - 3.0 * t * t));  // h(t) = (t - t0)(t^2 + t0 t + t0^2 - 3)
    l = m + sp * t;
    l1 = m + sp * 0.5 * (-t - disc);
    l2 = m + sp * 0.5 * (-t + disc);
  } else {
    // Otherwise Newton on the unshifted f(l) = l^3 - c2 l^2 + c1 l - c0 (trace, sum of the principal 2x2 minors,
    // determinant), which keeps l0's relative precision when l0 (and l1: a line) are tiny against the trace, where
    // the shifted form loses it. Same monotone convergence below l0 <= c2 / 3; from 0 if the start is past the
    // local maximum (l0 ~ l1).
    const double m_yz = yy * zz - yz * yz, m_xz = xx * zz - xz * xz, m_xy = xx * yy - xy * xy;
    const double c2 = trace, c1 = m_xy + m_xz + m_yz;
    const double c0 = xx * m_yz - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz);
    auto fp = [&](double x) { return (3.0 * x - 2.0 * c2) * x + c1; };
    l = std::max(0.0, m + sp * t);
    if (!(fp(l) > 0.0)) l = 0.0;
    const double tol = 1e-15 * c2;
    for (int it = 0; it < 100; ++it) {
      const double d1 = fp(l);
      if (!(d1 > 0.0)) break;
      const double step = -(((l - c2) * l + c1) * l - c0) / d1;
      l += step;
      // Done when the step, or Newton's estimate of the new iterate's error (step^2 f'' / 2f'), is at round-off.
      if (std::fabs(step) <= tol || step * step * std::fabs(3.0 * l - c2) <= tol * d1) break;
    }
    // 0 <= l0 <= c1 / c2 always (l1 l2 >= l0^2). On a line (l0, l1 ~ 0) c0 and c1 are mostly round-off, and a
    // Newton step from 0, c0 / c1, can land anywhere within the trace either side of 0 (l0 was 8 % of it on
    // noise-free collinear points, with l1 then 0): the bounds keep l0 and l1 within c1 / c2 of the truth there.
    l = std::max(0.0, std::min(l, c1 / c2));
    // The other two: l1 + l2 = c2 - l0, l1 l2 = c1 - l0 (l1 + l2); the small root in the cancellation-free form.
    const double sum = c2 - l, prod = c1 - l * sum;
    l2 = 0.5 * (sum + std::sqrt(std::max(0.0, sum * sum - 4.0 * prod)));
    l1 = l2 > 0.0 ? std::min(prod / l2, l2) : 0.0;
  }
  out.l0 = std::max(0.0, l);
  out.l1 = std::max(0.0, l1);
  out.l2 = std::max(0.0, l2);
  // Normal: kernel of C - l0 I. Rank 1 (l0 = l1 exactly, to round-off): no cross product; Eigen's closed form picks
  // a normal then.
  if (!kernelDirection(c, l, 1e-30 * trace * trace * trace * trace, out.normal)) return solve(false);
  const double sum = out.l0 + out.l1 + out.l2;
  out.valid = sum > 0.0 && out.l1 > 1e-9 * sum;
  return out;
}

}  // namespace hpds
