#include "hpds_node/FrameProcessor.hpp"

#include <tf2/exceptions.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>

#include "hpds/io/HierarchyFile.hpp"
#include "hpds/pipeline/OutputCloud.hpp"

namespace hpds_node {

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
    case DropReason::InternalError:
      return "internal_error";
    case DropReason::LostUpstream:
      return "lost_upstream";
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

ProcessorStats &ProcessorStats::operator+=(const ProcessorStats &o) {
  received += o.received;
  processed += o.processed;
  empty += o.empty;
  for (std::size_t i = 0; i < malformed.size(); ++i) malformed[i] += o.malformed[i];
  for (std::size_t i = 0; i < dropped.size(); ++i) dropped[i] += o.dropped[i];
  seconds_sum += o.seconds_sum;
  seconds_max = std::max(seconds_max, o.seconds_max);
  points += o.points;
  pose_jumps += o.pose_jumps;
  return *this;
}

std::string tfFrameId(const std::string &frame_id) {
  const std::size_t first = frame_id.find_first_not_of('/');
  return first == std::string::npos ? std::string() : frame_id.substr(first);
}

bool lookupSensorPose(const tf2::BufferCore &buffer, const std::string &target, const std::string &source,
                      const ros::Time &stamp, Eigen::Isometry3d &pose, std::string *why) {
  geometry_msgs::TransformStamped t;
  try {
    t = buffer.lookupTransform(target, tfFrameId(source), stamp);
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
  // Scan mode builds only the levels something reads: the ~level_<D> topics too.
  for (const int d : config_.ros.publish_levels) pipeline_.requireLevel(d);
}

std::string FrameProcessor::targetFrame() const {
  return config_.hpds.mode == hpds::Mode::Map ? config_.ros.fixed_frame : config_.ros.output_frame;
}

std::string FrameProcessor::samplingSummary() const {
  return std::string(hpds::toString(config_.hpds.mode)) + " mode, " + pipeline_.outputResolution().reason +
         "; levels 0.." + std::to_string(pipeline_.buildDepth()) + " built" +
         (config_.hpds.normals.enabled ? ", normals on" : ", normals off");
}

CloudError FrameProcessor::check(const sensor_msgs::PointCloud2 &msg, std::string *why) {
  ++stats_.received;
  const CloudError e = validateCloud(msg, why);
  if (e != CloudError::None) ++stats_.malformed[static_cast<int>(e)];
  return e;
}

void FrameProcessor::countDrop(DropReason reason, std::uint64_t frames) {
  stats_.dropped[static_cast<int>(reason)] += frames;
}

void FrameProcessor::saveMap(const std::string &path) const {
  if (config_.hpds.mode != hpds::Mode::Map)
    throw std::invalid_argument("saving a map needs mode: map (scan mode keeps no map)");
  hpds::saveMap(path, pipeline_);
}

std::string FrameProcessor::shallowSaveWarning() const {
  return hpds::shallowSaveWarning(pipeline_, loaded_deepest_, loaded_frames_);
}

std::string FrameProcessor::loadMap(const std::string &path) {
  std::string warning = hpds::loadMap(path, pipeline_);  // strong guarantee: throws before anything changes
  loaded_deepest_ = hpds::deepestPopulatedLevel(pipeline_.hierarchy());
  loaded_frames_ = pipeline_.framesProcessed();
  // The loaded map has not been published as a local map yet: send one with the next frame.
  local_map_sent_ = false;
  last_local_map_stamp_ = 0.0;
  last_sensor_.reset();  // where the loaded map's last sensor was is not in the file
  return warning;
}

std::size_t FrameProcessor::clearMap() {
  const std::size_t held = pipeline_.hierarchy().sampleCount();
  pipeline_.clearMap();
  loaded_deepest_ = -1;
  loaded_frames_ = 0;
  local_map_sent_ = false;
  last_local_map_stamp_ = 0.0;
  last_sensor_.reset();
  return held;
}

bool viewpointNeedsLookup(const std::string &cloud_frame, const std::string &sensor_frame) {
  return !sensor_frame.empty() && sensor_frame != tfFrameId(cloud_frame);
}

bool lookupViewpoint(const tf2::BufferCore &buffer, const std::string &cloud_frame, const std::string &sensor_frame,
                     const ros::Time &stamp, Eigen::Vector3d &viewpoint, std::string *why) {
  viewpoint = Eigen::Vector3d::Zero();
  if (!viewpointNeedsLookup(cloud_frame, sensor_frame)) return true;
  Eigen::Isometry3d pose;
  if (!lookupSensorPose(buffer, tfFrameId(cloud_frame), sensor_frame, stamp, pose, why)) return false;
  viewpoint = pose.translation();
  return true;
}

// [s] A transform this far behind a cloud (and over ten times ros/tf_timeout) is no lag that waiting longer mends.
constexpr double kStoppedTransformSeconds = 1.0;

std::string noTransformAdvice(const std::string &why, double tf_timeout) {
  const std::size_t future = why.find("s into the future");
  if (future == std::string::npos) return {};
  // tf2 says "Lookup would require extrapolation 6.04s into the future": how far behind the cloud tf's newest
  // transform is. Odometry lags by tens of milliseconds; seconds mean the transform stopped coming.
  std::size_t start = future;
  while (start > 0 && (std::isdigit(static_cast<unsigned char>(why[start - 1])) || why[start - 1] == '.')) --start;
  const double lag = start < future ? std::strtod(why.c_str() + start, nullptr) : 0.0;
  std::ostringstream s;
  if (lag > std::max(kStoppedTransformSeconds, 10.0 * tf_timeout)) {
    s << "; tf's newest transform is " << lag << " s older than the cloud: the transform has stopped coming "
      << "(its publisher, odometry or a driver, is down or stalled), or the clouds are stamped by another clock "
      << "than tf's";
    return s.str();
  }
  s << "; the transform at the cloud's stamp had not arrived when ros/tf_timeout (" << tf_timeout
    << " s) ran out: if the odometry lags the clouds, raise ros/tf_timeout above that lag, and ros/queue_size to at "
       "least that lag over the sensor period (a worker waits for one frame's transform at a time, and the frames "
       "that arrive meanwhile must queue)";
  return s.str();
}

bool sensorAtMapOrigin(const NodeConfig &config, const std::string &cloud_frame) {
  return config.hpds.mode == hpds::Mode::Map && config.ros.sensor_frame.empty() &&
         tfFrameId(cloud_frame) == config.ros.fixed_frame;
}

ProcessedFrame FrameProcessor::process(const sensor_msgs::PointCloud2 &msg, const Eigen::Isometry3d &sensor_to_target,
                                       const OutputRequest &wants, const Eigen::Vector3d &viewpoint) {
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
  const hpds::NormalConfig &normals = config_.hpds.normals;
  r.fields_not_carried =
      hpds::fieldsNotCarried(frame.points.layout(), normals.enabled, normals.enabled && normals.covariances);
  frame.stamp = msg.header.stamp.toSec();
  if (!target.empty()) frame.sensor_to_fixed = sensor_to_target;
  frame.viewpoint = viewpoint;

  // 2. Insert. The pipeline refuses (before changing anything) a frame whose fields differ from the map's.
  hpds::FrameResult inserted;
  try {
    inserted = pipeline_.addFrame(frame);
  } catch (const std::invalid_argument &e) {
    r.drop = DropReason::LayoutChanged;
    // The node logs this: say the way out that needs no restart.
    r.why = std::string(e.what()) + " (if the stream's fields changed for good, ~clear_map starts a map with them)";
    countDrop(r.drop);
    return r;
  }
  r.processed = true;
  r.counters = inserted.counters;
  r.seconds_normals += inserted.seconds_normals;  // map mode: the normals the map keeps
  if (map_mode) {
    const Eigen::Vector3d sensor = frame.sensor_to_fixed * frame.viewpoint;
    if (last_sensor_) r.pose_jump = hpds::poseJump(last_sensor_->position, last_sensor_->stamp, sensor, frame.stamp);
    if (r.pose_jump) ++stats_.pose_jumps;
    last_sensor_ = SensorAt{sensor, frame.stamp};
  }

  // 3. Outputs, in the target frame (or the input frame), stamped with the input stamp.
  std_msgs::Header header;
  header.stamp = msg.header.stamp;
  header.frame_id = target.empty() ? msg.header.frame_id : target;
  const hpds::Hierarchy &h = pipeline_.hierarchy();
  const int L = pipeline_.outputLevel();
  if (wants.output) {
    const auto ids = map_mode ? samplesHit(0, L, 2.0 * h.radius(L))
                              : pipeline_.outputSamples();
    toMsg(ids, header, r.output, &r.position_rounding, &r.seconds_normals);
    r.has_output = true;
  }
  if (map_mode && wants.new_samples) {
    toMsg(pipeline_.atOutputLevels(inserted.new_samples), header, r.new_samples, &r.position_rounding,
          &r.seconds_normals);
    r.has_new_samples = true;
  }
  for (std::size_t i = 0; i < config_.ros.publish_levels.size(); ++i) {
    if (i < wants.levels.size() && !wants.levels[i]) continue;
    const int d = config_.ros.publish_levels[i];
    std::vector<hpds::SampleId> ids;
    if (map_mode) {
      ids = samplesHit(d, d, 2.0 * h.radius(d));
    } else {
      for (hpds::SampleId id : h.samplesUpTo(d))
        if (h.level(id) == d) ids.push_back(id);
    }
    r.levels.emplace_back(d, sensor_msgs::PointCloud2());
    toMsg(ids, header, r.levels.back().second, &r.position_rounding, &r.seconds_normals);
  }
  if (map_mode && config_.ros.local_map_rate > 0.0) {
    // Driven by frame stamps, not a wall/ROS timer, so that the replay emits exactly what the node does; the map
    // only changes when a frame arrives anyway.
    // Clouds stamped 0 (a broken driver) never advance the stamp: they are scheduled by the steady clock instead,
    // or ~local_map would come out once and never again.
    const double now = frame.stamp != 0.0 ? frame.stamp
                                          : std::chrono::duration<double>(
                                                std::chrono::steady_clock::now().time_since_epoch())
                                                .count();
    const bool due = !local_map_sent_ || now < last_local_map_stamp_ ||
                     now - last_local_map_stamp_ >= 1.0 / config_.ros.local_map_rate - 1e-9;
    if (due && wants.local_map) {
      const Eigen::Vector3d c = frame.sensor_to_fixed * frame.viewpoint;  // the sensor, in the map
      const double center[3] = {c.x(), c.y(), c.z()};
      toMsg(pipeline_.outputSamplesNear(center, config_.ros.local_map_radius), header, r.local_map,
            &r.position_rounding, &r.seconds_normals);
      r.has_local_map = true;
    }
    if (due) {
      local_map_sent_ = true;
      last_local_map_stamp_ = now;
    }
  }

  // Only where the outputs' rounding would be warned about: a pass over the frame's points otherwise spent for
  // nothing.
  if (hpds::roundingMatters(r.position_rounding, pipeline_.outputResolution().radius))
    r.input_rounding = hpds::positionRounding(frame.points);

  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++stats_.processed;
  // Empty: none of its points could be inserted (zero-size, or every point NaN/Inf, a no-return, outside the range
  // limits or the exact key range), so its outputs hold nothing new.
  const hpds::FrameCounters &c = r.counters;
  if (c.skipped_invalid + c.skipped_zero + c.skipped_range + c.out_of_range >= c.input) ++stats_.empty;
  stats_.seconds_sum += r.seconds;
  stats_.seconds_max = std::max(stats_.seconds_max, r.seconds);
  stats_.points += r.counters;
  return r;
}

void FrameProcessor::toMsg(const std::vector<hpds::SampleId> &ids, const std_msgs::Header &header,
                           sensor_msgs::PointCloud2 &out, double *rounding, double *seconds_normals) const {
  double normals = 0.0;
  const hpds::PointBuffer cloud = pipeline_.makeCloud(ids, /*with_frame_field=*/false, &normals);
  *seconds_normals += normals;
  *rounding = std::max(*rounding, hpds::positionRounding(cloud));
  toRosCloud(cloud, header, out);
}

std::vector<hpds::SampleId> FrameProcessor::samplesHit(int min_level, int max_level, double hit_radius) const {
  // The pipeline still holds the frame it just inserted (its points after the skip rules, in the map frame).
  return pipeline_.samplesHitByLastFrame(min_level, max_level, hit_radius);
}

}  // namespace hpds_node
