#include <limits>
#include <stdexcept>

#include "hpds/config/ConfigYaml.hpp"
#include "hpds/hpds.hpp"
#include "hpds/normals/SampleCovariance.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {

namespace {

// Each record carries the point's input position next to x/y/z (frameFromPoints), so a sample names the point it
// came from.
template <typename Scalar>
constexpr std::uint32_t kIndexOffset = 3 * sizeof(Scalar);

template <typename Scalar>
Samples downsampleFrame(const std::vector<Eigen::Matrix<Scalar, 3, 1>> &points, const HpdsConfig &config,
                        const Eigen::Vector3d &viewpoint, const std::atomic<bool> *interrupt = nullptr) {
  if (!viewpoint.allFinite()) throw std::invalid_argument("downsample: viewpoint is not finite");
  if (points.size() > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("downsample: " + std::to_string(points.size()) +
                                " points, at most 2^32 - 1 fit the sample index");
  Pipeline pipeline(config);
  pipeline.setInterrupt(interrupt);
  throwIfInterrupted(interrupt, "before the frame");
  Frame frame = frameFromPoints(points);
  frame.viewpoint = viewpoint;
  const FrameCounters counters = pipeline.addFrame(frame).counters;
  const Hierarchy &hierarchy = pipeline.hierarchy();
  const std::vector<SampleId> ids = pipeline.outputSamples();

  Samples out;
  out.output_level = pipeline.outputLevel();
  out.radius = pipeline.outputResolution().radius;
  out.cell_size = pipeline.outputResolution().cell_size;
  out.skipped_invalid = counters.skipped_invalid;
  out.skipped_zero = counters.skipped_zero;
  out.skipped_range = counters.skipped_range;
  out.out_of_range = counters.out_of_range;
  out.evicted = counters.evicted;
  out.index.resize(ids.size());
  out.level.resize(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    std::memcpy(&out.index[i], hierarchy.record(ids[i]) + kIndexOffset<Scalar>, sizeof(std::uint32_t));
    out.level[i] = static_cast<std::uint8_t>(hierarchy.level(ids[i]));
  }
  if (config.normals.enabled) {
    std::vector<LocalPca> neighbourhoods;
    const std::vector<SampleNormal> normals =
        pipeline.normals(ids, config.normals.covariances ? &neighbourhoods : nullptr);
    if (config.normals.covariances) {
      throwIfInterrupted(interrupt, "before the covariances");
      const std::vector<SampleCovariance> covs = estimateCovariances(hierarchy, ids, pipeline.outputLevel(), normals,
                                                                     neighbourhoods, pipeline.config());
      out.covariance.resize(ids.size());
      for (std::size_t i = 0; i < ids.size(); ++i) {
        const float *c = covs[i].cov;
        out.covariance[i] << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
      }
    }
    out.normal.resize(ids.size());
    out.curvature.resize(ids.size());
    for (std::size_t i = 0; i < ids.size(); ++i) {
      // Invalid results are NaN already (the estimator's contract).
      out.normal[i] = Eigen::Vector3f(normals[i].normal[0], normals[i].normal[1], normals[i].normal[2]);
      out.curvature[i] = normals[i].curvature;
    }
  }
  return out;
}

}  // namespace

Samples downsample(const std::vector<Eigen::Vector3f> &points, const HpdsConfig &config) {
  return downsampleFrame(points, config, Eigen::Vector3d::Zero());
}

Samples downsample(const std::vector<Eigen::Vector3f> &points, const HpdsConfig &config,
                   const Eigen::Vector3d &viewpoint) {
  return downsampleFrame(points, config, viewpoint);
}

Samples downsampleDoubles(const std::vector<Eigen::Vector3d> &points, const HpdsConfig &config) {
  return downsampleFrame(points, config, Eigen::Vector3d::Zero());
}

Samples downsampleDoubles(const std::vector<Eigen::Vector3d> &points, const HpdsConfig &config,
                          const Eigen::Vector3d &viewpoint) {
  return downsampleFrame(points, config, viewpoint);
}

Samples downsample(const std::vector<Eigen::Vector3f> &points, const HpdsConfig &config,
                   const Eigen::Vector3d &viewpoint, const std::atomic<bool> &interrupt) {
  return downsampleFrame(points, config, viewpoint, &interrupt);
}

Samples downsampleDoubles(const std::vector<Eigen::Vector3d> &points, const HpdsConfig &config,
                          const Eigen::Vector3d &viewpoint, const std::atomic<bool> &interrupt) {
  return downsampleFrame(points, config, viewpoint, &interrupt);
}

HpdsConfig loadConfig(const std::string &path) { return loadConfigFile(path); }

}  // namespace hpds
