#include "RegistrationRunners.hpp"

#include <pcl/features/normal_3d.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>
#include <pcl/registration/icp.h>
#include <pcl/search/kdtree.h>

#include <chrono>

namespace hpds::bench {

namespace {

using Clock = std::chrono::steady_clock;

pcl::PointCloud<pcl::PointXYZ>::Ptr toXyz(const std::vector<Eigen::Vector3d> &xyz) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr c(new pcl::PointCloud<pcl::PointXYZ>);
  c->reserve(xyz.size());
  for (const auto &p : xyz) c->push_back(pcl::PointXYZ(float(p.x()), float(p.y()), float(p.z())));
  return c;
}

/// The cloud with normals: given ones, or k-NN PCA normals of the cloud itself; points without one dropped.
pcl::PointCloud<pcl::PointNormal>::Ptr withNormals(const SampledCloud &cloud, int knn) {
  pcl::PointCloud<pcl::PointNormal>::Ptr out(new pcl::PointCloud<pcl::PointNormal>);
  std::vector<Eigen::Vector3d> normals = cloud.normal;
  if (normals.empty()) {
    const auto xyz = toXyz(cloud.xyz);
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    pcl::PointCloud<pcl::Normal> estimated;
    ne.setInputCloud(xyz);
    ne.setSearchMethod(pcl::search::KdTree<pcl::PointXYZ>::Ptr(new pcl::search::KdTree<pcl::PointXYZ>));
    ne.setKSearch(knn);
    ne.compute(estimated);
    for (const auto &n : estimated) normals.emplace_back(n.normal_x, n.normal_y, n.normal_z);
  }
  for (std::size_t i = 0; i < cloud.xyz.size(); ++i) {
    if (!normals[i].allFinite() || (!cloud.plane_like.empty() && !cloud.plane_like[i])) continue;
    pcl::PointNormal p;
    p.x = float(cloud.xyz[i].x()), p.y = float(cloud.xyz[i].y()), p.z = float(cloud.xyz[i].z());
    p.normal_x = float(normals[i].x()), p.normal_y = float(normals[i].y()), p.normal_z = float(normals[i].z());
    p.curvature = 0.0f;
    out->push_back(p);
  }
  return out;
}

using Matrices = pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ>::MatricesVector;

/// The covariances as given (never NaN: SampleCovariance.hpp); `fallback` counts the samples without a normal,
/// whose covariance is the identity.
std::shared_ptr<Matrices> givenCovariances(const SampledCloud &cloud, std::size_t &fallback) {
  auto out = std::make_shared<Matrices>(cloud.covariance.begin(), cloud.covariance.end());
  for (const Eigen::Vector3d &n : cloud.normal) fallback += n.allFinite() ? 0 : 1;
  return out;
}

Eigen::Isometry3d toIsometry(const Eigen::Matrix4f &m) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.matrix() = m.cast<double>();
  // PCL composes float matrices: re-orthonormalise so the error metric sees a rotation.
  const Eigen::Quaterniond q(t.linear());
  t.linear() = q.normalized().toRotationMatrix();
  return t;
}

}  // namespace

RegistrationResult registerPointToPlane(const SampledCloud &source, const SampledCloud &target,
                                        const Eigen::Isometry3d &start, const RegistrationSettings &s) {
  // The source's normals are not used by the (asymmetric) point-to-plane objective; the type needs the fields.
  pcl::PointCloud<pcl::PointNormal>::Ptr src(new pcl::PointCloud<pcl::PointNormal>);
  for (const auto &p : source.xyz) {
    pcl::PointNormal q;
    q.x = float(p.x()), q.y = float(p.y()), q.z = float(p.z());
    q.normal_x = q.normal_y = 0.0f, q.normal_z = 1.0f, q.curvature = 0.0f;
    src->push_back(q);
  }
  const auto t0 = Clock::now();
  const auto tgt = withNormals(target, s.knn);
  pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal> icp;
  icp.setUseSymmetricObjective(false);
  icp.setInputSource(src);
  icp.setInputTarget(tgt);
  icp.setMaxCorrespondenceDistance(s.max_correspondence);
  icp.setMaximumIterations(s.max_iterations);
  icp.setTransformationEpsilon(s.transformation_epsilon);
  pcl::PointCloud<pcl::PointNormal> aligned;
  icp.align(aligned, start.matrix().cast<float>());
  RegistrationResult r;
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  r.transform = toIsometry(icp.getFinalTransformation());
  return r;
}

RegistrationResult registerGicp(const SampledCloud &source, const SampledCloud &target, const Eigen::Isometry3d &start,
                                CovarianceSource covariances, const RegistrationSettings &s) {
  const auto src = toXyz(source.xyz), tgt = toXyz(target.xyz);
  RegistrationResult r;
  const auto t0 = Clock::now();
  pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
  gicp.setInputSource(src);
  gicp.setInputTarget(tgt);
  if (covariances == CovarianceSource::Given) {
    gicp.setSourceCovariances(givenCovariances(source, r.fallback));
    gicp.setTargetCovariances(givenCovariances(target, r.fallback));
  }
  gicp.setCorrespondenceRandomness(s.knn);
  gicp.setMaxCorrespondenceDistance(s.max_correspondence);
  gicp.setMaximumIterations(s.max_iterations);
  pcl::PointCloud<pcl::PointXYZ> aligned;
  gicp.align(aligned, start.matrix().cast<float>());
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  r.transform = toIsometry(gicp.getFinalTransformation());
  return r;
}

}  // namespace hpds::bench
