// The node's scan-mode frame path as normal_accuracy scores it: every frame sampled on its own by one pipeline (as
// the node keeps it), its output cloud built with normals, and each output point's position, normal and ground-truth
// index (the `gt` field the frames carry) read back from that cloud.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <Eigen/Core>

#include "hpds/pipeline/Pipeline.hpp"

namespace hpds::bench {

struct ScanModeNormals {
  std::vector<Eigen::Vector3d> positions;  ///< fixed frame, as published (float32)
  std::vector<Eigen::Vector3d> normals;    ///< NaN where the estimate failed
  std::vector<std::uint32_t> truth;        ///< the `gt` field of each output point
};

/// `config` with mode scan and normals on; frames must carry a `gt` field.
inline ScanModeNormals scanModeNormals(const std::vector<Frame> &frames, HpdsConfig config) {
  config.mode = Mode::Scan;
  config.normals.enabled = true;
  Pipeline pipeline(config);
  ScanModeNormals out;
  for (const Frame &f : frames) {
    pipeline.addFrame(f);
    const PointBuffer cloud = pipeline.makeCloud(pipeline.outputSamples(), false);
    const PointLayout &l = cloud.layout();
    const PointField *pos[3] = {l.find("x"), l.find("y"), l.find("z")};
    const PointField *nrm[3] = {l.find("normal_x"), l.find("normal_y"), l.find("normal_z")};
    const PointField *gt = l.find("gt");
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      Eigen::Vector3d p, n;
      for (int a = 0; a < 3; ++a) {
        p[a] = readAsDouble(cloud.record(i), *pos[a]);
        n[a] = readAsDouble(cloud.record(i), *nrm[a]);
      }
      out.positions.push_back(p);
      out.normals.push_back(n);
      out.truth.push_back(static_cast<std::uint32_t>(readAsDouble(cloud.record(i), *gt)));
    }
  }
  return out;
}

}  // namespace hpds::bench
