// hpds::downsample for PCL clouds (target hpds::pcl): the one-call API of hpds/hpds.hpp over pcl::PointCloud.
//
// Contract
// - Any PCL point type with x/y/z. Normals face the cloud's sensor_origin_ (the origin unless set; as PCL's
//   NormalEstimation does), and input.min_range/max_range are measured from it; NaN points are skipped, as are the
//   other points hpds::downsample skips.
// - Returns the real input points, every field copied (intensity, ring, time, ...), in sample order: the same
//   samples, in the same order, as hpds::downsample on the cloud's x/y/z with sensor_origin_ as its viewpoint.
//   header is the input's; the result is unorganised (height 1) and dense.
// - `normals` (optional): resized and filled in the same order (normal_x/y/z and curvature; NaN where not
//   estimable). Normals are estimated only when it is given, whatever config.normals.enabled says.
// - `covariances` (optional): likewise, the samples' covariances for generalized ICP (Samples::covariance), in the
//   type pcl::GeneralizedIterativeClosestPoint's setSourceCovariances/setTargetCovariances take; computed only when
//   given, whatever config.normals.covariances says.
// - Throws std::invalid_argument as hpds::downsample does (a sensor_origin_ that is not finite included), for
//   `config` as given (validateConfig) before the switches above are applied.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <vector>

#include "hpds/hpds.hpp"

namespace hpds {

/// One covariance per sample, as PCL's GICP takes them.
using SampleCovariances = std::vector<Eigen::Matrix3d, Eigen::aligned_allocator<Eigen::Matrix3d>>;

template <typename PointT>
typename pcl::PointCloud<PointT>::Ptr downsample(const pcl::PointCloud<PointT> &cloud, const HpdsConfig &config,
                                                 pcl::PointCloud<pcl::Normal> *normals = nullptr,
                                                 SampleCovariances *covariances = nullptr) {
  // The config as given first: the switches set below would otherwise hide a mistake in it (covariances on with
  // normals off) that hpds::downsample, the CLI and the node all refuse.
  validateConfig(config);
  std::vector<Eigen::Vector3f> xyz(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) xyz[i] = Eigen::Vector3f(cloud[i].x, cloud[i].y, cloud[i].z);
  HpdsConfig run = config;
  run.normals.enabled = normals != nullptr || covariances != nullptr;
  run.normals.covariances = covariances != nullptr;
  const Samples samples = downsample(xyz, run, cloud.sensor_origin_.template head<3>().template cast<double>());

  typename pcl::PointCloud<PointT>::Ptr out(new pcl::PointCloud<PointT>);
  out->header = cloud.header;
  out->sensor_origin_ = cloud.sensor_origin_;
  out->sensor_orientation_ = cloud.sensor_orientation_;
  out->resize(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) (*out)[i] = cloud[samples.index[i]];
  out->width = static_cast<std::uint32_t>(samples.size());
  out->height = 1;
  out->is_dense = true;
  if (normals) {
    normals->header = cloud.header;
    normals->resize(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      pcl::Normal &n = (*normals)[i];
      n.normal_x = samples.normal[i].x();
      n.normal_y = samples.normal[i].y();
      n.normal_z = samples.normal[i].z();
      n.curvature = samples.curvature[i];
    }
    normals->width = static_cast<std::uint32_t>(samples.size());
    normals->height = 1;
    normals->is_dense = false;
  }
  if (covariances) {
    covariances->resize(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) (*covariances)[i] = samples.covariance[i].cast<double>();
  }
  return out;
}

}  // namespace hpds
