// FrameProcessor: what happens to one PointCloud2, shared by the node/nodelet and `hpds replay` so that both give
// the same samples from the same messages.
//
// Contract
// - check(): validation only (CloudConversion rules); a refused message is counted and changes nothing.
// - targetFrame(): the frame the caller must look up a transform into before process(): ros.fixed_frame in map
//   mode, ros.output_frame in scan mode, or "" (scan mode without output_frame: no transform, input frame kept).
// - process(msg, sensor_to_target, wants): converts, runs hpds::Pipeline::addFrame with Frame.sensor_to_fixed =
//   sensor_to_target and builds the requested outputs, each stamped with the input stamp and in the target frame
//   (or the input frame):
//     output      scan: every sample of levels 0..L of this frame.
//                 map: the samples of levels 0..L "hit" by this frame: those with at least one of the frame's
//                 accepted points within 2 r_L (the hierarchy's coverage radius, so every accepted point has at
//                 least one such sample). Old samples count as well as new ones: it is the map as this sweep saw it.
//     new_samples map: samples accepted from this frame at levels 0..L.
//     levels      one cloud per ros.publish_levels entry D: samples of exactly level D (scan: all of them; map:
//                 those hit by the frame with radius 2 r_D).
//     local_map   map: samples of levels 0..L within ros.local_map_radius of the sensor, when the frame's stamp is
//                 at least 1 / ros.local_map_rate after the last local map (or went backwards: a looped bag);
//                 clouds stamped 0 go by the steady clock.
//   Clouds use the OutputCloud layout: x y z float32 first, [normal_x/y/z curvature], level uint8 and the input
//   fields, every field aligned to its element size and point_step a multiple of 4 (OutputCloud.hpp).
// - Drops: a message whose fields differ from the map's (map mode) is dropped and counted (LayoutChanged).
// - Pose jumps (map mode): a processed frame whose sensor moved implausibly fast since the previous processed one
//   (hpds::poseJump) is processed as any, and marked and counted (ProcessedFrame::pose_jump, stats().pose_jumps);
//   loadMap and clearMap forget the previous position.
// - Persistence (map mode): saveMap writes the map and the frame counter (hpds::saveMap, atomic); loadMap replaces
//   them with a file's (hpds::loadMap: on any error nothing changes) and restarts the local-map clock, so the next
//   frame continues exactly as it would have after the frames that built the file (same frame index, same
//   samples, a ~local_map on that frame). ProcessorStats count messages over the processor's life and are kept.
// - Deterministic: same config and same sequence of (message, transform) give byte-identical outputs.
// - Not thread-safe: one thread drives a FrameProcessor; stats() copies are safe to hand to other threads.
#pragma once

#include <sensor_msgs/PointCloud2.h>
#include <tf2/buffer_core.h>

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/pipeline/PoseJump.hpp"
#include "hpds_node/CloudConversion.hpp"
#include "hpds_node/NodeConfig.hpp"

namespace hpds_node {

/// Why a frame was not processed, beyond malformed messages (which are counted per CloudError). InternalError: the
/// processing threw (a bug or an exhausted resource); LostUpstream: never received, known from a header.seq gap
/// (SequenceGaps.hpp).
enum class DropReason { NoTransform = 0, LayoutChanged, Overload, NoSubscribers, InternalError, LostUpstream };
inline constexpr int kDropReasonCount = 6;
[[nodiscard]] const char *toString(DropReason reason);

/// Which outputs to build for this frame (the node asks only for topics with subscribers).
struct OutputRequest {
  bool output = true;
  bool new_samples = true;
  bool local_map = true;
  std::vector<bool> levels;  ///< parallel to ros.publish_levels; missing entries mean true

  [[nodiscard]] bool any() const;
  [[nodiscard]] static OutputRequest all() { return {}; }
  [[nodiscard]] static OutputRequest none(std::size_t level_count);
};

struct ProcessedFrame {
  bool processed = false;  ///< false: dropped (see `malformed` / `drop`)
  CloudError malformed = CloudError::None;
  DropReason drop = DropReason::NoTransform;
  std::string why;  ///< reason text for the log when not processed

  hpds::FrameCounters counters;
  /// Input fields the outputs do not carry, their names being hpds's own (hpds::fieldsNotCarried): to be said.
  std::vector<std::string> fields_not_carried;
  bool has_output = false, has_new_samples = false, has_local_map = false;
  sensor_msgs::PointCloud2 output, new_samples, local_map;
  std::vector<std::pair<int, sensor_msgs::PointCloud2>> levels;  ///< (D, cloud) for the requested levels
  double seconds = 0.0;                                          ///< conversion + pipeline + outputs
  double seconds_normals = 0.0;  ///< of `seconds`: the outputs' normals (and covariances), and those a map keeps
  /// [m] How far the outputs' float32 x y z may round positions (hpds::positionRounding; 0: float64).
  double position_rounding = 0.0;
  /// [m] The input's own positionRounding (its float32 x y z as received), measured only when position_rounding
  /// matters (hpds::roundingMatters), else 0: where it matters too, float64 output cannot restore the positions.
  double input_rounding = 0.0;
  /// Map mode: the sensor moved implausibly fast since the previous processed frame (hpds::poseJump).
  std::optional<hpds::PoseJump> pose_jump;
};

/// Running totals for diagnostics and --stats.
struct ProcessorStats {
  std::uint64_t received = 0;   ///< messages offered to the processor (or the node's queue)
  std::uint64_t processed = 0;  ///< frames inserted
  std::uint64_t empty = 0;      ///< processed frames none of whose points could be inserted (zero-size, all skipped)
  std::array<std::uint64_t, kCloudErrorCount> malformed{};  ///< indexed by CloudError
  std::array<std::uint64_t, kDropReasonCount> dropped{};    ///< indexed by DropReason
  double seconds_sum = 0.0, seconds_max = 0.0;              ///< processing time of processed frames
  hpds::FrameCounters points;                               ///< pipeline point counters, all frames
  std::uint64_t pose_jumps = 0;  ///< map mode: processed frames whose sensor jumped (ProcessedFrame::pose_jump)

  [[nodiscard]] std::uint64_t malformedTotal() const;
  [[nodiscard]] std::uint64_t droppedTotal() const;  ///< malformed + every DropReason
  /// Totals of two processors (the node's scan-mode workers): counts and times add, seconds_max is the larger.
  ProcessorStats &operator+=(const ProcessorStats &o);
};

class FrameProcessor {
 public:
  /// Validates the config (std::invalid_argument naming the key).
  explicit FrameProcessor(const NodeConfig &config);

  [[nodiscard]] std::string targetFrame() const;
  /// What the start-up log says about the sampling: mode, how the output level, radius and cell were chosen (and
  /// why), the levels built and whether normals are on.
  [[nodiscard]] std::string samplingSummary() const;

  /// Counts a received message and validates it; a refused message is counted as malformed.
  [[nodiscard]] CloudError check(const sensor_msgs::PointCloud2 &msg, std::string *why = nullptr);

  /// See the contract. `msg` must have passed check(). sensor_to_target is ignored when targetFrame() is empty.
  /// `viewpoint`: the sensor's origin in the message's frame (lookupViewpoint; ros/sensor_frame).
  ProcessedFrame process(const sensor_msgs::PointCloud2 &msg, const Eigen::Isometry3d &sensor_to_target,
                         const OutputRequest &wants, const Eigen::Vector3d &viewpoint = Eigen::Vector3d::Zero());

  /// Counts a frame dropped before or instead of process() (no transform, overload, nobody listening, an internal
  /// error, lost upstream).
  void countDrop(DropReason reason, std::uint64_t frames = 1);

  /// Map mode: writes the map to `path` (see contract). Throws std::invalid_argument in scan mode and
  /// std::runtime_error ("<path>: <problem>") when the file cannot be written; the map is never changed.
  void saveMap(const std::string &path) const;
  /// Map mode: replaces the map with the one in `path` (see contract). Throws std::invalid_argument in scan mode and
  /// std::runtime_error ("<path>: <problem>") for a missing, corrupt, truncated or incompatible file, leaving the
  /// processor unchanged. Returns hpds::loadMap's warning (kept normals of other settings, dropped), or empty.
  std::string loadMap(const std::string &path);
  /// Map mode: an empty map whose fields the next frame sets (hpds::Pipeline::clearMap); returns the samples it held.
  std::size_t clearMap();
  /// Map mode, after a loadMap: what a save would lose (hpds::shallowSaveWarning: this run builds fewer levels than
  /// the loaded map held, so its deeper levels would not cover the frames since), or empty.
  [[nodiscard]] std::string shallowSaveWarning() const;

  /// Scan mode with several workers: the index (and with it the insertion-order seed) of the next frame, so that a
  /// frame's output depends on its place in the stream, not on which worker's processor runs it.
  void setNextFrameIndex(std::uint32_t index) { pipeline_.setNextFrameIndex(index); }

  [[nodiscard]] const ProcessorStats &stats() const { return stats_; }
  [[nodiscard]] const hpds::Pipeline &pipeline() const { return pipeline_; }
  [[nodiscard]] const NodeConfig &config() const { return config_; }

 private:
  [[nodiscard]] std::vector<hpds::SampleId> samplesHit(int min_level, int max_level, double hit_radius) const;
  /// The output cloud of ids into `out`; raises *rounding to its position rounding, adds its normals' time to
  /// *seconds_normals.
  void toMsg(const std::vector<hpds::SampleId> &ids, const std_msgs::Header &header, sensor_msgs::PointCloud2 &out,
             double *rounding, double *seconds_normals) const;

  NodeConfig config_;
  hpds::Pipeline pipeline_;
  ProcessorStats stats_;
  bool local_map_sent_ = false;
  int loaded_deepest_ = -1;       ///< deepest populated level of the last map loaded (-1: none)
  std::uint32_t loaded_frames_ = 0;  ///< its frame counter
  double last_local_map_stamp_ = 0.0;
  // The previous processed frame's sensor position in the map and its stamp, for pose jumps (map mode); none after
  // a load or clear.
  struct SensorAt {
    Eigen::Vector3d position;
    double stamp;
  };
  std::optional<SensorAt> last_sensor_;
};

/// A message's frame_id as tf2 takes it: ROS 1 drivers and old bags still write "/velodyne", which tf2 refuses (and
/// warns about on every lookup); its transforms are stored without the slash.
[[nodiscard]] std::string tfFrameId(const std::string &frame_id);

/// Pose of frame `source` (the sensor) in `target` at `stamp` from any tf2 buffer (the node's listener buffer or
/// the replay's, filled from the bag); false with `why` set when the buffer cannot answer. The pose is rounded
/// (rotation to float32 quaternion precision, translation to 2^-20 m) so that it does not depend on whether the
/// buffer already holds later transforms, which changes the last bits of tf2's result.
bool lookupSensorPose(const tf2::BufferCore &buffer, const std::string &target, const std::string &source,
                      const ros::Time &stamp, Eigen::Isometry3d &pose, std::string *why = nullptr);

/// Whether the viewpoint of a cloud in `cloud_frame` needs `sensor_frame` (ros/sensor_frame) looked up in tf: it is
/// set and not the cloud's own frame.
[[nodiscard]] bool viewpointNeedsLookup(const std::string &cloud_frame, const std::string &sensor_frame);

/// The viewpoint of a cloud in `cloud_frame` taken by the sensor in `sensor_frame` (ros/sensor_frame): that frame's
/// origin in the cloud's frame at `stamp` (lookupSensorPose's rounding), or (0,0,0) when no lookup is needed
/// (viewpointNeedsLookup). False with `why` set when the buffer cannot answer.
bool lookupViewpoint(const tf2::BufferCore &buffer, const std::string &cloud_frame, const std::string &sensor_frame,
                     const ros::Time &stamp, Eigen::Vector3d &viewpoint, std::string *why = nullptr);

/// What to set when a frame was dropped for want of a transform (`why`: lookupSensorPose's reason): a transform that
/// tf can only extrapolate into the future arrived later than ros/tf_timeout (`tf_timeout` seconds) waited, which a
/// user fixes by raising it, not by looking for a missing frame; unless tf's newest transform is over 1 s (and ten
/// times `tf_timeout`) behind the cloud: then the transform stopped coming, which no timeout mends, and it says so.
/// Empty for other reasons.
[[nodiscard]] std::string noTransformAdvice(const std::string &why, double tf_timeout);

/// Whether a cloud in `cloud_frame` has no known sensor position in map mode: it arrives in the fixed frame itself and
/// no ros/sensor_frame says where the sensor was, so the viewpoint is the map's origin.
[[nodiscard]] bool sensorAtMapOrigin(const NodeConfig &config, const std::string &cloud_frame);

}  // namespace hpds_node
