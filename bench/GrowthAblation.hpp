// The growth rule of NormalParams::max_growth applied to a plain PCL cloud: normal_accuracy's ablation that gives the
// voxel grid the same estimator refinement as hpds.
#pragma once

#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "hpds/normals/LocalPca.hpp"

namespace hpds::bench {

/// The growth rule of NormalParams::max_growth (RefinedNormals.cpp) applied to a plain cloud, for the ablation that
/// gives the voxel grid the same estimator refinement as hpds: footprint from `coarse`, PCA over `fine`; a grown
/// neighbourhood replaces the first only if it is flat and no longer line-like; growth stops at the first non-flat one.
struct Growth {
  double line_ratio = 0.05;
  double max_growth = 8.0;
  double max_plane_rms = 0.02;
};

using GrowthCloud = pcl::PointCloud<pcl::PointXYZ>;

inline std::vector<Eigen::Vector3d> adaptiveNormals(const GrowthCloud::Ptr &query, const GrowthCloud::Ptr &coarse,
                                                    const GrowthCloud::Ptr &fine, bool knn, int k, double radius,
                                                    const Growth &v) {
  pcl::search::KdTree<pcl::PointXYZ> tc, tf;
  tc.setInputCloud(coarse);
  tf.setInputCloud(fine);
  std::vector<Eigen::Vector3d> out(query->size(), Eigen::Vector3d::Constant(NAN));
  std::vector<int> idx;
  std::vector<float> d2;
  for (std::size_t i = 0; i < query->size(); ++i) {
    const pcl::PointXYZ qp = (*query)[i];
    const double q[3] = {qp.x, qp.y, qp.z};
    double rho = radius;
    if (knn) {
      tc.nearestKSearch(qp, k, idx, d2);
      rho = std::sqrt(*std::max_element(d2.begin(), d2.end())) * 1.0001 + 1e-6;
    }
    const double rho0 = rho;
    bool have = false;
    for (;;) {
      tf.radiusSearch(qp, rho, idx, d2);
      PcaAccumulator acc(q);
      for (int j : idx) {
        const double p[3] = {(*fine)[j].x, (*fine)[j].y, (*fine)[j].z};
        acc.add(p);
      }
      const LocalPca pca = acc.solve(/*accurate=*/false);
      const bool enough = acc.count() >= 3 && pca.valid;
      const bool flat = pca.l0 <= v.max_plane_rms * v.max_plane_rms * rho * rho;
      const bool not_line = pca.l1 >= v.line_ratio * pca.l2;
      if (enough && (!have || (flat && not_line))) {
        out[i] = {pca.normal[0], pca.normal[1], pca.normal[2]};
        have = true;
        if (not_line) break;
      }
      if ((have && !flat) || rho * 2.0 > v.max_growth * rho0 * (1.0 + 1e-12)) break;
      rho *= 2.0;
    }
  }
  return out;
}

}  // namespace hpds::bench
