#include "hpds_node/FrameProcessor.hpp"

#include <tf2/exceptions.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

namespace hpds_node {

namespace {

// Cell of the hit-test grid, relative to the sensor origin so that indices stay small whatever the map extent.
struct GridKey {
  std::int32_t x, y, z;
  bool operator==(const GridKey &o) const { return x == o.x && y == o.y && z == o.z; }
};
struct GridKeyHash {
  std::size_t operator()(const GridKey &k) const {
    std::uint64_t h = std::uint64_t(std::uint32_t(k.x)) * 0x9E3779B97F4A7C15ull;
    h ^= std::uint64_t(std::uint32_t(k.y)) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= std::uint64_t(std::uint32_t(k.z)) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    return std::size_t(h);
  }
};

// Index bound of the hit grid: points beyond it are left out of the test (the hierarchy refuses coordinates that
// far from the origin in cell units anyway).
constexpr double kMaxGridIndex = 1 << 30;

}  // namespace

const char *toString(DropReason reason) {
  switch (reason) {
    case DropReason::NoTransform:
      return "no_transform";
    case DropReason::LayoutChanged:
      return "layout_changed";
    case DropReason::Overload:
      return "overload";
    case DropReason::NoSubscribers:
      return "no_subscribers";
  }
  return "unknown";
}

bool OutputRequest::any() const {
  return output || new_samples || local_map || std::find(levels.begin(), levels.end(), true) != levels.end();
}

OutputRequest OutputRequest::none(std::size_t level_count) {
  OutputRequest r;
  r.output = r.new_samples = r.local_map = false;
  r.levels.assign(level_count, false);
  return r;
}

std::uint64_t ProcessorStats::malformedTotal() const {
  std::uint64_t n = 0;
  for (std::uint64_t v : malformed) n += v;
  return n;
}

std::uint64_t ProcessorStats::droppedTotal() const {
  std::uint64_t n = malformedTotal();
  for (std::uint64_t v : dropped) n += v;
  return n;
}

bool lookupSensorPose(const tf2::BufferCore &buffer, const std::string &target, const std::string &source,
                      const ros::Time &stamp, Eigen::Isometry3d &pose, std::string *why) {
  geometry_msgs::TransformStamped t;
  try {
    t = buffer.lookupTransform(target, source, stamp);
  } catch (const tf2::TransformException &e) {
    if (why) *why = e.what();
    return false;
  }
  // tf2 hands back a stored transform bit for bit only while it is the newest sample; once a later one is in the
  // buffer it slerps with t = 0, which changes the last bits. Whether the node's buffer already holds the next
  // transform is a matter of timing (the replay's always does), so the pose is rounded to a grid far below lidar
  // precision (quaternion to float32, ~1e-7 rad; translation to 2^-20 m, ~1 um): the samples then depend on the
  // recorded transforms only, and the node and `hpds replay` agree.
  const auto &r = t.transform.rotation;
  Eigen::Quaterniond q(double(float(r.w)), double(float(r.x)), double(float(r.y)), double(float(r.z)));
  q.normalize();
  constexpr double kGrid = 1048576.0;  // 2^20 per metre
  const auto &p = t.transform.translation;
  pose = Eigen::Isometry3d::Identity();
  pose.linear() = q.toRotationMatrix();
  pose.translation() = Eigen::Vector3d(std::nearbyint(p.x * kGrid), std::nearbyint(p.y * kGrid),
                                       std::nearbyint(p.z * kGrid)) / kGrid;
  if (!pose.matrix().allFinite() || !std::isfinite(q.norm())) {
    if (why) *why = "transform " + source + " -> " + target + " is not finite";
    return false;
  }
  return true;
}

FrameProcessor::FrameProcessor(const NodeConfig &config) : config_(config), pipeline_(config.hpds) {
  validateRosConfig(config_.ros, config_.hpds);
}

std::string FrameProcessor::targetFrame() const {
  return config_.hpds.mode == hpds::Mode::Map ? config_.ros.fixed_frame : config_.ros.output_frame;
}

CloudError FrameProcessor::check(const sensor_msgs::PointCloud2 &msg, std::string *why) {
  ++stats_.received;
  const CloudError e = validateCloud(msg, why);
  if (e != CloudError::None) ++stats_.malformed[static_cast<int>(e)];
  return e;
}

void FrameProcessor::countDrop(DropReason reason) { ++stats_.dropped[static_cast<int>(reason)]; }

ProcessedFrame FrameProcessor::process(const sensor_msgs::PointCloud2 &msg, const Eigen::Isometry3d &sensor_to_target,
                                       const OutputRequest &wants) {
  const auto t0 = std::chrono::steady_clock::now();
  ProcessedFrame r;
  const std::string target = targetFrame();
  const bool map_mode = config_.hpds.mode == hpds::Mode::Map;

  // 1. Convert (validated again: cheap, and process() must not trust its caller with raw bytes).
  hpds::Frame frame;
  r.malformed = fromRosCloud(msg, frame.points, &r.why);
  if (r.malformed != CloudError::None) {
    ++stats_.malformed[static_cast<int>(r.malformed)];
    return r;
  }
  frame.stamp = msg.header.stamp.toSec();
  if (!target.empty()) frame.sensor_to_fixed = sensor_to_target;

  // 2. Insert. The pipeline refuses (before changing anything) a frame whose fields differ from the map's.
  hpds::FrameResult inserted;
  try {
    inserted = pipeline_.addFrame(frame);
  } catch (const std::invalid_argument &e) {
    r.drop = DropReason::LayoutChanged;
    r.why = e.what();
    countDrop(r.drop);
    return r;
  }
  r.processed = true;
  r.counters = inserted.counters;

  // 3. Outputs, in the target frame (or the input frame), stamped with the input stamp.
  std_msgs::Header header;
  header.stamp = msg.header.stamp;
  header.frame_id = target.empty() ? msg.header.frame_id : target;
  const hpds::Hierarchy &h = pipeline_.hierarchy();
  const int L = pipeline_.outputLevel();
  if (wants.output) {
    const auto ids = map_mode ? samplesHit(frame.points, frame.sensor_to_fixed, 0, L, 2.0 * h.radius(L))
                              : pipeline_.outputSamples();
    toMsg(ids, header, r.output);
    r.has_output = true;
  }
  if (map_mode && wants.new_samples) {
    toMsg(pipeline_.atOutputLevels(inserted.new_samples), header, r.new_samples);
    r.has_new_samples = true;
  }
  for (std::size_t i = 0; i < config_.ros.publish_levels.size(); ++i) {
    if (i < wants.levels.size() && !wants.levels[i]) continue;
    const int d = config_.ros.publish_levels[i];
    std::vector<hpds::SampleId> ids;
    if (map_mode) {
      ids = samplesHit(frame.points, frame.sensor_to_fixed, d, d, 2.0 * h.radius(d));
    } else {
      for (hpds::SampleId id : h.samplesUpTo(d))
        if (h.level(id) == d) ids.push_back(id);
    }
    r.levels.emplace_back(d, sensor_msgs::PointCloud2());
    toMsg(ids, header, r.levels.back().second);
  }
  if (map_mode && config_.ros.local_map_rate > 0.0) {
    // Driven by frame stamps, not a wall/ROS timer, so that the replay emits exactly what the node does; the map
    // only changes when a frame arrives anyway.
    const bool due = !local_map_sent_ || frame.stamp < last_local_map_stamp_ ||
                     frame.stamp - last_local_map_stamp_ >= 1.0 / config_.ros.local_map_rate - 1e-9;
    if (due && wants.local_map) {
      const Eigen::Vector3d c = frame.sensor_to_fixed.translation();
      const double center[3] = {c.x(), c.y(), c.z()};
      toMsg(pipeline_.outputSamplesNear(center, config_.ros.local_map_radius), header, r.local_map);
      r.has_local_map = true;
    }
    if (due) {
      local_map_sent_ = true;
      last_local_map_stamp_ = frame.stamp;
    }
  }

  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++stats_.processed;
  if (frame.points.empty()) ++stats_.empty;
  stats_.seconds_sum += r.seconds;
  stats_.seconds_max = std::max(stats_.seconds_max, r.seconds);
  stats_.points += r.counters;
  return r;
}

void FrameProcessor::toMsg(const std::vector<hpds::SampleId> &ids, const std_msgs::Header &header,
                           sensor_msgs::PointCloud2 &out) const {
  toRosCloud(pipeline_.makeCloud(ids, /*with_frame_field=*/false), header, out);
}

std::vector<hpds::SampleId> FrameProcessor::samplesHit(const hpds::PointBuffer &points,
                                                       const Eigen::Isometry3d &sensor_to_target, int min_level,
                                                       int max_level, double hit_radius) const {
  // The frame's points as the pipeline accepted them (same skip rules), in the map frame, bucketed in cells of
  // edge hit_radius around the sensor: a sample is hit when a point lies within hit_radius, so only the 27 cells
  // around the sample's own need looking at.
  const hpds::PointLayout &layout = points.layout();
  const hpds::PointField *fx = layout.find("x"), *fy = layout.find("y"), *fz = layout.find("z");
  const hpds::InputConfig &in = config_.hpds.input;
  const double min_r2 = in.min_range * in.min_range;
  const double max_r2 = in.max_range > 0.0 ? in.max_range * in.max_range : INFINITY;
  const Eigen::Vector3d origin = sensor_to_target.translation();
  const double inv = 1.0 / hit_radius;
  auto keyOf = [&](const Eigen::Vector3d &p, GridKey &k) {
    const Eigen::Vector3d q = (p - origin) * inv;
    if (!(q.cwiseAbs().maxCoeff() < kMaxGridIndex)) return false;
    k = GridKey{std::int32_t(std::floor(q.x())), std::int32_t(std::floor(q.y())), std::int32_t(std::floor(q.z()))};
    return true;
  };

  std::vector<Eigen::Vector3d> world;
  world.reserve(points.size());
  std::unordered_map<GridKey, std::vector<std::uint32_t>, GridKeyHash> grid;
  double max_dist = 0.0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint8_t *rec = points.record(i);
    const Eigen::Vector3d p(hpds::readAsDouble(rec, *fx), hpds::readAsDouble(rec, *fy), hpds::readAsDouble(rec, *fz));
    if (!p.allFinite()) continue;
    if (in.skip_zero_points && p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0) continue;
    const double r2 = p.squaredNorm();
    if (r2 < min_r2 || r2 > max_r2) continue;
    const Eigen::Vector3d w = sensor_to_target * p;
    GridKey k;
    if (!w.allFinite() || !keyOf(w, k)) continue;
    grid[k].push_back(static_cast<std::uint32_t>(world.size()));
    world.push_back(w);
    max_dist = std::max(max_dist, (w - origin).norm());
  }
  std::vector<hpds::SampleId> hit;
  if (world.empty()) return hit;

  const double h2 = hit_radius * hit_radius;
  const hpds::Hierarchy &hierarchy = pipeline_.hierarchy();
  const double center[3] = {origin.x(), origin.y(), origin.z()};
  hierarchy.forEachInBall(center, max_dist + hit_radius, max_level, [&](hpds::SampleId id, double) {
    if (hierarchy.level(id) < min_level) return;
    const double *s = hierarchy.position(id);
    const Eigen::Vector3d sp(s[0], s[1], s[2]);
    GridKey k;
    if (!keyOf(sp, k)) return;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = grid.find(GridKey{k.x + dx, k.y + dy, k.z + dz});
          if (it == grid.end()) continue;
          for (std::uint32_t pi : it->second)
            if ((world[pi] - sp).squaredNorm() < h2) {
              hit.push_back(id);
              return;
            }
        }
  });
  std::sort(hit.begin(), hit.end());
  return hit;
}

}  // namespace hpds_node
