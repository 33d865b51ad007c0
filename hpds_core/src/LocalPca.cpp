#include "hpds/LocalPca.hpp"

#include <Eigen/Eigenvalues>
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

}  // namespace hpds
