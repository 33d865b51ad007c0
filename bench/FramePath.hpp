// The node's per-frame work as the benchmark times it (FrameProcessor without ROS), and the configs it is timed
// with: shared by perf_benchmark's PCL and small_gicp rows.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace bench {

/// Output level D and level-0 cell edge every row is measured at (D = 5, c_D = 0.125 m by default).
struct LevelSetting {
  int level = 5;
  double cell_size = 4.0;
};

/// Downsampling alone: levels 0..D built, nothing deeper, no normals (what a live downsampler runs).
inline hpds::HpdsConfig downsampleConfig(const LevelSetting &s, int threads) {
  hpds::HpdsConfig c;
  c.hierarchy.cell_size = s.cell_size;
  c.hierarchy.max_depth = s.level;
  c.output.level = s.level;
  c.threads = threads;
  return c;
}

/// The frame path with the shipped normal settings (NormalConfig's defaults) at output level D: the pipeline builds
/// whatever those normals read (scan mode's buildDepth()), under the default max_depth.
inline hpds::HpdsConfig framePathConfig(const LevelSetting &s, int threads) {
  hpds::HpdsConfig c;
  c.hierarchy.cell_size = s.cell_size;
  c.hierarchy.max_depth = std::max(c.hierarchy.max_depth, s.level);
  c.output.level = s.level;
  c.normals.enabled = true;
  c.threads = threads;
  return c;
}

struct NodePathRun {
  std::size_t points = 0;
  std::size_t valid_normals = 0;  ///< counted only when asked (countValid), outside the timed work
  double insert_s = 0.0, normals_s = 0.0;
};

/// Output points whose normal_x is a number (invalid normals are NaN); 0 without normals.
inline std::size_t countValidNormals(const hpds::PointBuffer &cloud) {
  const hpds::PointField *f = cloud.layout().find("normal_x");
  if (!f) return 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    float v;
    std::memcpy(&v, cloud.record(i) + f->offset, sizeof v);
    n += std::isfinite(v) ? 1 : 0;
  }
  return n;
}

/// The node's per-frame work on a pipeline kept across frames: the message's bytes copied in, insertion, the output
/// cloud (normals as configured), its bytes copied out.
inline NodePathRun nodePath(hpds::Pipeline &pipeline, const hpds::Frame &frame, bool count_valid = false) {
  NodePathRun run;
  hpds::Frame in;
  in.points = frame.points;
  in.sensor_to_fixed = frame.sensor_to_fixed;
  run.insert_s = pipeline.addFrame(in).seconds_insert;
  const hpds::PointBuffer out = pipeline.makeCloud(pipeline.outputSamples(), false, &run.normals_s);
  const std::vector<std::uint8_t> msg_data(out.bytes());
  run.points = msg_data.size() / std::max<std::size_t>(1, out.layout().point_step);
  if (count_valid) run.valid_normals = countValidNormals(out);
  return run;
}

}  // namespace bench
