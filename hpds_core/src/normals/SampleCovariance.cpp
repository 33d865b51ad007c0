#include "hpds/normals/SampleCovariance.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace hpds {

SampleCovariance planeCovariance(const SampleNormal &normal, double epsilon) {
  SampleCovariance c{};
  const double n[3] = {normal.normal[0], normal.normal[1], normal.normal[2]};
  const double norm2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  if (!normal.valid || !(norm2 > 0.0) || !std::isfinite(norm2)) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (float &v : c.cov) v = nan;
    c.valid = false;
    return c;
  }
  // The stored float normal is unit to ~1e-7: dividing by its squared norm keeps epsilon exact along it.
  const double s = (1.0 - epsilon) / norm2;
  c.cov[0] = static_cast<float>(1.0 - s * n[0] * n[0]);
  c.cov[1] = static_cast<float>(-s * n[0] * n[1]);
  c.cov[2] = static_cast<float>(-s * n[0] * n[2]);
  c.cov[3] = static_cast<float>(1.0 - s * n[1] * n[1]);
  c.cov[4] = static_cast<float>(-s * n[1] * n[2]);
  c.cov[5] = static_cast<float>(1.0 - s * n[2] * n[2]);
  c.valid = true;
  return c;
}

std::vector<SampleCovariance> planeCovariances(const std::vector<SampleNormal> &normals, double epsilon) {
  std::vector<SampleCovariance> out;
  out.reserve(normals.size());
  for (const SampleNormal &n : normals) out.push_back(planeCovariance(n, epsilon));
  return out;
}

namespace {
/// The one rule behind both overloads: no normal or a line-like neighbourhood, the identity (no plane known); else
/// the plane of `plane` when it is given and valid, of the normal otherwise.
std::vector<SampleCovariance> covariancesFor(const std::vector<SampleNormal> &normals,
                                             const std::vector<LocalPca> &neighbourhoods,
                                             const std::vector<SampleNormal> *plane, double epsilon,
                                             double line_ratio) {
  if (normals.size() != neighbourhoods.size())
    throw std::invalid_argument("sampleCovariances: one neighbourhood per normal");
  if (plane && plane->size() != normals.size())
    throw std::invalid_argument("sampleCovariances: one plane normal per normal");
  std::vector<SampleCovariance> out;
  out.reserve(normals.size());
  for (std::size_t i = 0; i < normals.size(); ++i) {
    const LocalPca &pca = neighbourhoods[i];
    if (!normals[i].valid)
      out.push_back(SampleCovariance{{1.0f, 0.0f, 0.0f, 1.0f, 0.0f, 1.0f}, false});
    else if (pca.l1 < line_ratio * pca.l2)
      out.push_back(SampleCovariance{{1.0f, 0.0f, 0.0f, 1.0f, 0.0f, 1.0f}, true});
    else if (plane && (*plane)[i].valid)
      out.push_back(planeCovariance((*plane)[i], epsilon));
    else
      out.push_back(planeCovariance(normals[i], epsilon));
  }
  return out;
}
}  // namespace

std::vector<SampleCovariance> sampleCovariances(const std::vector<SampleNormal> &normals,
                                               const std::vector<LocalPca> &neighbourhoods, double epsilon,
                                               double line_ratio) {
  return covariancesFor(normals, neighbourhoods, nullptr, epsilon, line_ratio);
}

std::vector<SampleCovariance> sampleCovariances(const std::vector<SampleNormal> &normals,
                                               const std::vector<LocalPca> &neighbourhoods,
                                               const NormalConfig &config) {
  return sampleCovariances(normals, neighbourhoods, config.covariance_epsilon, config.covariance_line_ratio);
}

std::vector<SampleCovariance> sampleCovariances(const std::vector<SampleNormal> &normals,
                                               const std::vector<LocalPca> &neighbourhoods,
                                               const std::vector<SampleNormal> &plane_normals, double epsilon,
                                               double line_ratio) {
  return covariancesFor(normals, neighbourhoods, &plane_normals, epsilon, line_ratio);
}

std::vector<SampleCovariance> estimateCovariances(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                                                  int level, const std::vector<SampleNormal> &normals,
                                                  const std::vector<LocalPca> &neighbourhoods,
                                                  const HpdsConfig &config) {
  const NormalConfig &n = config.normals;
  if (n.covariance_k <= 0) return sampleCovariances(normals, neighbourhoods, n);
  const std::vector<SampleNormal> planes = estimateNormals(hierarchy, ids, covarianceNormalParams(config, level));
  return sampleCovariances(normals, neighbourhoods, planes, n.covariance_epsilon, n.covariance_line_ratio);
}

}  // namespace hpds
