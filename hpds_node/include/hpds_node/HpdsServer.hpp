// HpdsServer: the ROS side of hpds, one class behind both entry points (node main, nodelet onInit).
//
// Contract
// - Construction reads the private parameters (config_file, then the config keys and `ros/*`, see NodeConfig.hpp,
//   and diagnostic_period) and throws std::invalid_argument naming the parameter when one is invalid: the node must
//   not start with a half-understood configuration.
// - Topics (private, remap them): ~input (sensor_msgs/PointCloud2) in; ~output, and in map mode ~new_samples and
//   ~local_map, plus ~level_<D> for each ros.publish_levels entry, out. Diagnostics on /diagnostics.
// - Every frame is processed or counted as dropped, with its reason, in the diagnostics, and logged (throttled):
//   - the subscriber callback only queues the message (OrderedWorkerPool, ros.queue_size deep; when full the oldest
//     is dropped: overload) and counts gaps in header.seq per publisher ("frames lost upstream": frames that never
//     arrived, dropped by a publisher's or roscpp's queue or skipped by a throttle upstream; logged, but no drop
//     of the node's);
//   - a worker validates (malformed <reason>), waits for tf (at most ros.tf_timeout of wall time: no_transform),
//     runs its FrameProcessor (layout_changed) and publishes; anything the processing throws is counted
//     (internal_error) and logged with its message, and the worker carries on.
//   Map mode has one worker. Scan mode has `threads` workers (0 = all cores), each with its own processor running
//   one thread: frames are taken in arrival order, get their frame index (the insertion-order seed) in that order
//   after the checks that may drop them, and are published in that order, so the output is the same for any number
//   of workers.
// - Work is skipped when nobody listens: scan mode drops the frame (counted as no_subscribers) before converting;
//   map mode still inserts it (the map must stay complete) but builds only the clouds that have subscribers.
// - Services (private, std_srvs/Trigger) are served by their own callback queue and thread, so a long save never
//   holds up the subscriber: ~save_map writes the map to ros.map_file, ~load_map replaces the map with that file's.
//   Both run on the worker between two frames (a frame is never half-inserted when the map is saved or replaced)
//   and take priority over queued frames; the caller waits for the result. Response: success with the path and the
//   sample count, or success=false with the exact error (scan mode, ros.map_file unset, a missing/corrupt/
//   truncated/incompatible file, a failed write). A failed load leaves the map untouched. Parameters are read at
//   start: a ros/map_file set later is not used, and the response says so.
// - ros.load_map_on_start (map mode): the constructor loads ros.map_file before subscribing. A missing file starts
//   an empty map (ROS_WARN); any other load error throws std::runtime_error naming the file: the node must not
//   start on an unreadable map (and, with ros.save_map_on_shutdown, overwrite it with an empty one).
// - shutdown() (also called by the destructor) stops the input, answers pending service calls, stops the workers
//   after their current frame (queued frames are discarded and logged) and then, with ros.save_map_on_shutdown,
//   saves the map to ros.map_file, logging the outcome (ROS_ERROR on failure), unless no frame was processed since
//   the start or the last load or save (the file is then left as it is). It returns false when that save failed.
//   Call it while roscpp's logging still works (before ros::shutdown()), or the outcome goes unseen.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <ros/callback_queue.h>
#include <ros/spinner.h>

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "hpds_node/FrameProcessor.hpp"
#include "hpds_node/KeepUpCheck.hpp"
#include "hpds_node/NodeConfig.hpp"
#include "hpds_node/OrderedWorkerPool.hpp"
#include "hpds_node/ParamBridge.hpp"
#include "hpds_node/SequenceGaps.hpp"

namespace hpds_node {

class HpdsServer {
 public:
  /// `name` is the node or nodelet name, used by the diagnostics. Throws std::invalid_argument for a bad parameter
  /// and std::runtime_error for a map file that ros.load_map_on_start cannot load.
  HpdsServer(ros::NodeHandle nh, ros::NodeHandle private_nh, const std::string &name);
  ~HpdsServer();
  HpdsServer(const HpdsServer &) = delete;
  HpdsServer &operator=(const HpdsServer &) = delete;

  /// See the contract; false when the shutdown save failed. Idempotent.
  bool shutdown();

 private:
  void onCloud(const ros::MessageEvent<const sensor_msgs::PointCloud2> &event);
  void handle(const sensor_msgs::PointCloud2::ConstPtr &msg, std::size_t worker, OrderedWorkerPool::Turns &turns);
  void onInternalError(std::size_t worker, const std::string &what);
  /// The cloud's pose in `target` (when not empty) and its viewpoint (lookupViewpoint, ros/sensor_frame), waiting
  /// up to ros/tf_timeout for both; false with `why` when one cannot be had.
  bool waitForPose(const std::string &target, const std_msgs::Header &header, Eigen::Isometry3d &pose,
                   Eigen::Vector3d &viewpoint, std::string *why);
  [[nodiscard]] OutputRequest subscribedOutputs() const;
  void warnFieldNotCarriedOnce(const std::string &name);
  void publish(ProcessedFrame &frame);
  // ServerDiagnostics.cpp
  void takeSnapshot(std::size_t worker, double frame_seconds);
  /// The node's counts so far, for a log line written on `worker`: its own processor's live counts plus the other
  /// workers' as of their last frame (each worker counts only the frames it handled).
  [[nodiscard]] ProcessorStats statsSoFar(std::size_t worker) const;
  /// The throttled WARN line for an overload drop.
  void logOverload(std::uint64_t overload_total);
  /// Feeds a frame's processing time and its wait for a transform to keep_up_ and logs its one warning, if any.
  void checkKeepUp(double frame_seconds, double waited);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper &status);

  // Map persistence.
  bool onMapService(bool save, std_srvs::Trigger::Request &req, std_srvs::Trigger::Response &res);
  bool onClearMap(std_srvs::Trigger::Request &req, std_srvs::Trigger::Response &res);
  /// On the worker (or when no worker runs): performs the save or load.
  [[nodiscard]] std::pair<bool, std::string> runMapCommand(bool save);
  void loadMapOnStart();
  /// ros/map_file's folder exists and is writable (std::invalid_argument naming the parameter otherwise).
  void requireMapFolder() const;
  /// Whether saving now would replace a map file that holds a map with an empty map (which no save may do).
  [[nodiscard]] bool emptySaveWouldReplaceTheFile() const;
  /// False when a line with this key was logged less than 5 s ago: each drop reason gets its own throttle (ROS's
  /// throttles are per call site, so one reason would hide the others).
  bool logAllowed(const std::string &key);
  /// `text` with a leading "hpds: " replaced by tag_.
  [[nodiscard]] std::string tagged(const std::string &text) const;
  /// What the parameter server holds for ros/map_file now, when it differs from what the node started with.
  [[nodiscard]] std::string mapFileSetSinceStart() const;

  ros::NodeHandle nh_, pnh_;
  NodeConfig config_;
  // One per worker, used by that worker only (map mode has one).
  std::vector<std::unique_ptr<FrameProcessor>> processors_;
  std::string target_frame_;
  // Checked before updater_ is built: diagnostic_updater reads it too, and throws on a value ros::Duration cannot hold.
  double diagnostic_period_;
  diagnostic_updater::Updater updater_;
  std::string tag_;  // "hpds <node or nodelet name>": begins every log line, so that each instance is told apart

  tf2_ros::Buffer tf_buffer_;  // holds tfCacheSeconds(config_.ros) of transforms
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;  // set exactly when frames need a transform lookup
  ros::Publisher pub_output_, pub_new_samples_, pub_local_map_;
  std::vector<ros::Publisher> pub_levels_;
  ros::Subscriber sub_;
  ros::WallTimer diagnostics_timer_;

  // Counts of the subscriber callback (guarded by input_mutex_).
  std::mutex input_mutex_;
  std::uint64_t received_ = 0, overload_ = 0, lost_upstream_ = 0;
  SequenceGaps sequence_gaps_;
  std::set<std::string> fields_not_carried_;  // already warned about
  // Said once per instance (not ROS_*_ONCE, whose flag is shared by every nodelet of the process).
  std::atomic<bool> warned_sensor_at_origin_{false}, warned_rounding_{false}, warned_empty_frame_id_{false},
      warned_zero_stamp_{false}, told_evicting_{false};
  // Frames processed in spite of a header the driver must fix, warned about once and counted in /diagnostics.
  std::atomic<std::uint64_t> zero_stamps_{0}, empty_frame_ids_{0};
  std::mutex log_mutex_;
  std::map<std::string, double> last_logged_;  // logAllowed: wall time [s] of the last line per key
  static constexpr double kLogThrottleSeconds = 5.0;

  // Whether the workers keep up with the input: said once, within the first frames.
  std::mutex keep_up_mutex_;
  std::unique_ptr<KeepUpCheck> keep_up_;  // guarded by keep_up_mutex_
  /// Overload drops while the first frame ran, logged when it ends (guarded by keep_up_mutex_): at INFO when it was
  /// processed without waiting for tf (its cost is the node's allocations), else as any overload drop.
  std::uint64_t startup_drops_ = 0;

  // What the diagnostics see: a copy the worker refreshes after every frame.
  struct Snapshot {
    std::vector<ProcessorStats> stats;  // per worker, summed for the report
    std::vector<std::size_t> memory;    // per worker
    std::vector<std::size_t> samples_per_level;
    std::size_t samples_total = 0;
    double seconds_max_window = 0.0;  // reset by each diagnostics report
  };
  mutable std::mutex snapshot_mutex_;
  Snapshot snapshot_;
  // Diagnostics window (diagnostics callback only).
  ros::WallTime window_start_;
  std::uint64_t window_received_ = 0;
  ProcessorStats window_stats_;
  std::uint64_t window_overload_ = 0;

  std::unique_ptr<OrderedWorkerPool> pool_;  // started once everything above exists
  // Services: their own queue and thread, declared after the pool so that they are torn down first.
  ros::CallbackQueue service_queue_;
  std::unique_ptr<ros::AsyncSpinner> service_spinner_;
  ros::ServiceServer srv_save_map_, srv_load_map_, srv_clear_map_;
  bool shut_down_ = false;
  bool shutdown_ok_ = true;
  // The map's frame counter when it was last loaded or saved (0: the empty map of the start). A shutdown with no
  // frame since leaves ros/map_file alone: re-saving a map just loaded would rewrite it under this run's settings
  // (normals of other settings dropped) and an empty start would overwrite a map nobody asked to load.
  std::uint32_t frames_at_last_sync_ = 0;
  std::string last_sync_ = "the start";  ///< what set frames_at_last_sync_, for the shutdown log
};

}  // namespace hpds_node
