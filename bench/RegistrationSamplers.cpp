#include "RegistrationSamplers.hpp"

#include <chrono>
#include <cmath>

#include "hpds/eval/GridSubsampling.hpp"
#include "hpds/normals/SampleCovariance.hpp"

namespace hpds::bench {

std::vector<Eigen::Vector3d> framePoints(const PointBuffer &points) {
  const PointField *fx = points.layout().find("x"), *fy = points.layout().find("y"), *fz = points.layout().find("z");
  std::vector<Eigen::Vector3d> out;
  out.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint8_t *r = points.record(i);
    const Eigen::Vector3d p(readAsDouble(r, *fx), readAsDouble(r, *fy), readAsDouble(r, *fz));
    if (p.allFinite() && !(p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0)) out.push_back(p);
  }
  return out;
}

namespace {
HpdsConfig scanConfig(HpdsConfig c, int output_level) {
  c.mode = Mode::Scan;
  c.output.level = output_level;
  c.output.spacing = 0.0;
  c.normals.enabled = true;
  c.normals.covariances = true;
  validateConfig(c);
  return c;
}
}  // namespace

HpdsFrame::HpdsFrame(const PointBuffer &points, const HpdsConfig &config, int coarsest, int deepest) {
  Frame frame;
  frame.points = points;
  for (int d = coarsest; d <= deepest; ++d) {
    auto pipeline = std::make_unique<Pipeline>(scanConfig(config, d));
    (void)pipeline->addFrame(frame);
    pipelines_[d] = std::move(pipeline);
  }
}

SampledCloud HpdsFrame::levels(int d, double *seconds) const {
  const Pipeline &pipeline = *pipelines_.at(d);
  const Hierarchy &h = pipeline.hierarchy();
  const std::vector<SampleId> ids = pipeline.outputSamples();
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<LocalPca> neighbourhoods;
  const std::vector<SampleNormal> normals = pipeline.normals(ids, &neighbourhoods);
  const std::vector<SampleCovariance> covs =
      estimateCovariances(h, ids, pipeline.outputLevel(), normals, neighbourhoods, pipeline.config());
  if (seconds) *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  SampledCloud out;
  out.xyz.reserve(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    out.xyz.emplace_back(h.position(ids[i]));
    out.normal.emplace_back(normals[i].normal[0], normals[i].normal[1], normals[i].normal[2]);
    const float *c = covs[i].cov;
    Eigen::Matrix3d m;
    m << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
    out.covariance.push_back(m);
    // The identity marks a neighbourhood that does not pin a normal (SampleCovariance.hpp); a plane has trace < 3.
    out.plane_like.push_back(covs[i].valid && !(c[0] == 1.0f && c[3] == 1.0f && c[5] == 1.0f));
  }
  return out;
}

namespace {
// Cells from 1 mm to 100 m bracket every count between one point and all of them on a lidar frame.
constexpr double kMinCell = 1e-3, kMaxCell = 100.0;
}  // namespace

SampledCloud voxelCentroidsAtCount(const std::vector<Eigen::Vector3d> &points, std::size_t target, double tolerance,
                                   const Eigen::Vector3d &shift) {
  const CountMatch m = matchCellToCount([&](double cell) { return voxelCentroids(points, cell, shift * cell).size(); },
                                        target, tolerance, kMinCell, kMaxCell);
  SampledCloud out;
  out.xyz = voxelCentroids(points, m.cell, shift * m.cell);
  out.cell = m.cell;
  out.count_matched = m.within;
  return out;
}

SampledCloud randomPerVoxelAtCount(const std::vector<Eigen::Vector3d> &points, std::size_t target, double tolerance,
                                   std::uint64_t seed, const Eigen::Vector3d &shift) {
  const CountMatch m = matchCellToCount(
      [&](double cell) { return gridRandom(points, cell, seed, shift * cell).size(); }, target, tolerance, kMinCell,
      kMaxCell);
  SampledCloud out;
  for (std::uint32_t i : gridRandom(points, m.cell, seed, shift * m.cell)) out.xyz.push_back(points[i]);
  out.cell = m.cell;
  out.count_matched = m.within;
  return out;
}

}  // namespace hpds::bench
