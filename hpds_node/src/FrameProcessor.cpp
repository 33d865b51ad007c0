#include "hpds_node/FrameProcessor.hpp"

#include <tf2/exceptions.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace hpds_node {

namespace {

// Keys of the hit-test grid: cell indices relative to the sensor, 21 bits per axis, so they pack into one integer.
constexpr std::int64_t kKeyBias = std::int64_t(1) << 20;
constexpr double kMaxGridIndex = double(kKeyBias - 2);  // room for the +-1 neighbour offsets

std::uint64_t packKey(std::int64_t x, std::int64_t y, std::int64_t z) {
  return (std::uint64_t(x + kKeyBias) << 42) | (std::uint64_t(y + kKeyBias) << 21) | std::uint64_t(z + kKeyBias);
}

// Open-addressing set/map of packed keys: the hit test probes it 1-27 times per candidate sample, for every sample
// in range, so it has to be a flat table, not node-based.
class FlatKeyMap {
 public:
  explicit FlatKeyMap(std::size_t expected) {
    std::size_t cap = 16;
    int bits = 4;
    while (cap < 2 * expected) cap <<= 1, ++bits;
    keys_.assign(cap, kEmpty);
    values_.assign(cap, 0);
    mask_ = cap - 1;
    shift_ = 64 - bits;
  }
  void insert(std::uint64_t key, std::uint32_t value) {
    std::size_t i = slot(key);
    while (keys_[i] != kEmpty && keys_[i] != key) i = (i + 1) & mask_;
    keys_[i] = key;
    values_[i] = value;
  }
  /// Value of `key`, or -1.
  [[nodiscard]] std::int64_t find(std::uint64_t key) const {
    for (std::size_t i = slot(key);; i = (i + 1) & mask_) {
      if (keys_[i] == key) return values_[i];
      if (keys_[i] == kEmpty) return -1;
    }
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
  // Fibonacci hashing: the top bits of the product mix every bit of the key (neighbouring cells differ in the
  // low bits only, which a plain mask would cluster).
  std::size_t slot(std::uint64_t key) const { return std::size_t((key * 0x9E3779B97F4A7C15ull) >> shift_); }
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::size_t mask_ = 0;
  int shift_ = 60;
};

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
  // around the sample's own can hold one. Most samples in range are not hit (seen earlier, or occluded now); a
  // second table of the occupied cells grown by one cell rejects those with a single probe.
  const hpds::PointLayout &layout = points.layout();
  const hpds::PointField *fx = layout.find("x"), *fy = layout.find("y"), *fz = layout.find("z");
  const hpds::InputConfig &in = config_.hpds.input;
  const double min_r2 = in.min_range * in.min_range;
  const double max_r2 = in.max_range > 0.0 ? in.max_range * in.max_range : INFINITY;
  const Eigen::Vector3d origin = sensor_to_target.translation();
  const double inv = 1.0 / hit_radius;
  auto cellOf = [&](const Eigen::Vector3d &p, std::int64_t k[3]) {
    const Eigen::Vector3d q = (p - origin) * inv;
    if (!(q.cwiseAbs().maxCoeff() < kMaxGridIndex)) return false;
    for (int a = 0; a < 3; ++a) k[a] = std::int64_t(std::floor(q[a]));
    return true;
  };

  std::vector<Eigen::Vector3d> world;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed;  // (cell key, index into world)
  world.reserve(points.size());
  keyed.reserve(points.size());
  double max_dist = 0.0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint8_t *rec = points.record(i);
    const Eigen::Vector3d p(hpds::readAsDouble(rec, *fx), hpds::readAsDouble(rec, *fy), hpds::readAsDouble(rec, *fz));
    if (!p.allFinite()) continue;
    if (in.skip_zero_points && p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0) continue;
    const double r2 = p.squaredNorm();
    if (r2 < min_r2 || r2 > max_r2) continue;
    const Eigen::Vector3d w = sensor_to_target * p;
    std::int64_t k[3];
    if (!w.allFinite() || !cellOf(w, k)) continue;
    keyed.emplace_back(packKey(k[0], k[1], k[2]), static_cast<std::uint32_t>(world.size()));
    world.push_back(w);
    max_dist = std::max(max_dist, (w - origin).norm());
  }
  std::vector<hpds::SampleId> hit;
  if (world.empty()) return hit;

  // Points grouped by cell: cell c's points are sorted_points[starts[c] .. starts[c + 1]).
  std::sort(keyed.begin(), keyed.end());
  std::vector<std::uint32_t> sorted_points(keyed.size()), starts;
  std::vector<std::uint64_t> cell_keys;
  for (std::size_t i = 0; i < keyed.size(); ++i) {
    if (i == 0 || keyed[i].first != keyed[i - 1].first) {
      cell_keys.push_back(keyed[i].first);
      starts.push_back(static_cast<std::uint32_t>(i));
    }
    sorted_points[i] = keyed[i].second;
  }
  starts.push_back(static_cast<std::uint32_t>(keyed.size()));
  FlatKeyMap cells(cell_keys.size()), near(27 * cell_keys.size());
  for (std::size_t c = 0; c < cell_keys.size(); ++c) {
    cells.insert(cell_keys[c], static_cast<std::uint32_t>(c));
    const std::int64_t x = std::int64_t(cell_keys[c] >> 42) - kKeyBias,
                       y = std::int64_t((cell_keys[c] >> 21) & 0x1FFFFF) - kKeyBias,
                       z = std::int64_t(cell_keys[c] & 0x1FFFFF) - kKeyBias;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) near.insert(packKey(x + dx, y + dy, z + dz), 0);
  }

  // Samples are visited in id order, which walks the hierarchy's position and level arrays sequentially; a
  // ball query would visit them in hash order, one cache miss each, and the ball around the sensor holds most of
  // the map anyway. The result comes out sorted by id.
  const double h2 = hit_radius * hit_radius;
  const double reach = max_dist + hit_radius, reach2 = reach * reach;
  const hpds::Hierarchy &hierarchy = pipeline_.hierarchy();
  for (hpds::SampleId id = 0, end = static_cast<hpds::SampleId>(hierarchy.idBound()); id < end; ++id) {
    if (!hierarchy.isLive(id)) continue;
    const int level = hierarchy.level(id);
    if (level < min_level || level > max_level) continue;
    const double *s = hierarchy.position(id);
    const Eigen::Vector3d sp(s[0], s[1], s[2]);
    if ((sp - origin).squaredNorm() >= reach2) continue;
    std::int64_t k[3];
    if (!cellOf(sp, k) || near.find(packKey(k[0], k[1], k[2])) < 0) continue;
    bool is_hit = false;
    for (int dx = -1; dx <= 1 && !is_hit; ++dx)
      for (int dy = -1; dy <= 1 && !is_hit; ++dy)
        for (int dz = -1; dz <= 1 && !is_hit; ++dz) {
          const std::int64_t c = cells.find(packKey(k[0] + dx, k[1] + dy, k[2] + dz));
          if (c < 0) continue;
          for (std::uint32_t i = starts[c]; i < starts[c + 1] && !is_hit; ++i)
            is_hit = (world[sorted_points[i]] - sp).squaredNorm() < h2;
        }
    if (is_hit) hit.push_back(id);
  }
  return hit;
}

}  // namespace hpds_node
