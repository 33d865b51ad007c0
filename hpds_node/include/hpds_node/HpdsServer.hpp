// HpdsServer: the ROS side of hpds, one class behind both entry points (node main, nodelet onInit).
//
// Contract
// - Construction reads the private parameters (config_file, then the config keys and `ros/*`, see NodeConfig.hpp)
//   and throws std::invalid_argument naming the parameter when one is invalid: the node must not start with a
//   half-understood configuration.
// - Topics (private, remap them): ~input (sensor_msgs/PointCloud2) in; ~output, and in map mode ~new_samples and
//   ~local_map, plus ~level_<D> for each ros.publish_levels entry, out. Diagnostics on /diagnostics.
// - Threads: the subscriber callback only queues the message (ros.queue_size deep; when full the oldest is
//   dropped and counted as overload, so the newest frame wins); a worker thread validates, waits for tf (at most
//   ros.tf_timeout of wall time, then drops and counts), runs its FrameProcessor and publishes. Map mode has one
//   worker. Scan mode has `threads` workers (0 = all cores), each with its own processor running one thread: frames
//   are taken in arrival order, get their frame index (the insertion-order seed) in that order after the checks
//   that may drop them, and are published in that order, so the output is the same for any number of workers.
// - Work is skipped when nobody listens: scan mode drops the frame (counted as no_subscribers) before converting;
//   map mode still inserts it (the map must stay complete) but builds only the clouds that have subscribers.
// - Services (private, std_srvs/Trigger): ~save_map writes the map to ros.map_file, ~load_map replaces the map
//   with that file's. Both run on the worker thread between two frames (a frame is never half-inserted when the
//   map is saved or replaced) and take priority over queued frames; the caller waits for the result. Response:
//   success with the path and the sample count, or success=false with the exact error (scan mode, ros.map_file
//   unset, a missing/corrupt/truncated/incompatible file, a failed write). A failed load leaves the map untouched.
// - ros.load_map_on_start (map mode): the constructor loads ros.map_file before subscribing. A missing file starts
//   an empty map (ROS_WARN); any other load error throws std::runtime_error naming the file: the node must not
//   start on an unreadable map (and, with ros.save_map_on_shutdown, overwrite it with an empty one).
// - Destruction stops the worker after its current frame (queued frames are lost) and then, with
//   ros.save_map_on_shutdown, saves the map to ros.map_file (a failure is logged: nothing else can be done).
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <condition_variable>
#include <deque>
#include <future>
#include <memory>
#include <mutex>
#include <thread>

#include "hpds_node/FrameProcessor.hpp"
#include "hpds_node/KeepUpCheck.hpp"
#include "hpds_node/NodeConfig.hpp"
#include "hpds_node/ParamBridge.hpp"

namespace hpds_node {

class HpdsServer {
 public:
  /// `name` is the node or nodelet name, used by the diagnostics. Throws std::invalid_argument for a bad parameter
  /// and std::runtime_error for a map file that ros.load_map_on_start cannot load.
  HpdsServer(ros::NodeHandle nh, ros::NodeHandle private_nh, const std::string &name);
  ~HpdsServer();
  HpdsServer(const HpdsServer &) = delete;
  HpdsServer &operator=(const HpdsServer &) = delete;

 private:
  void onCloud(const sensor_msgs::PointCloud2::ConstPtr &msg);
  // A frame's place in the stream: the index and publish turns it must take (or pass) in arrival order.
  class Turns;
  void workerLoop(std::size_t worker);
  /// Returns the processing time of the frame, 0 when it was dropped.
  double handle(const sensor_msgs::PointCloud2::ConstPtr &msg, std::size_t worker, Turns &turns);
  bool waitForPose(const std::string &target, const std_msgs::Header &header, Eigen::Isometry3d &pose,
                   std::string *why);
  [[nodiscard]] OutputRequest subscribedOutputs() const;
  void publish(ProcessedFrame &frame);
  void takeSnapshot(std::size_t worker, double frame_seconds);
  /// Feeds a processed frame's time to keep_up_ and logs its one warning, if any.
  void checkKeepUp(double frame_seconds);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper &status);

  // Map persistence: a save or load request waiting for the worker.
  struct MapCommand {
    bool save = false;
    std::promise<std::pair<bool, std::string>> done;  // (success, message)
  };
  bool onMapService(bool save, std_srvs::Trigger::Request &req, std_srvs::Trigger::Response &res);
  /// Worker thread (or the constructor/destructor, when no worker runs): performs the save or load.
  [[nodiscard]] std::pair<bool, std::string> runMapCommand(bool save);
  void loadMapOnStart();

  ros::NodeHandle nh_, pnh_;
  NodeConfig config_;
  // One per worker, used by that worker only (map mode has one).
  std::vector<std::unique_ptr<FrameProcessor>> processors_;
  std::string target_frame_;

  tf2_ros::Buffer tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Publisher pub_output_, pub_new_samples_, pub_local_map_;
  std::vector<ros::Publisher> pub_levels_;
  ros::Subscriber sub_;
  ros::ServiceServer srv_save_map_, srv_load_map_;
  diagnostic_updater::Updater updater_;
  ros::WallTimer diagnostics_timer_;

  // Queue between the subscriber callback and the worker.
  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<sensor_msgs::PointCloud2::ConstPtr> queue_;
  std::deque<std::shared_ptr<MapCommand>> commands_;  // run before queue_; every one is answered
  bool stopping_ = false;
  std::uint64_t received_ = 0;  // guarded by queue_mutex_
  std::uint64_t overload_ = 0;  // guarded by queue_mutex_
  std::uint64_t next_ticket_ = 0;  // guarded by queue_mutex_: arrival order of the frames taken by the workers

  // Whether the workers keep up with the input: said once, within the first frames.
  std::mutex keep_up_mutex_;
  std::unique_ptr<KeepUpCheck> keep_up_;  // guarded by keep_up_mutex_

  // Turns, in ticket order: a frame's index is handed out, and its clouds published, only after every earlier
  // frame's (a dropped frame passes both turns without using them).
  std::mutex turn_mutex_;
  std::condition_variable turn_cv_;
  std::uint64_t index_turn_ = 0, publish_turn_ = 0;  // guarded by turn_mutex_
  std::uint32_t next_frame_index_ = 0;               // guarded by turn_mutex_

  // What the diagnostics see: a copy the worker refreshes after every frame.
  struct Snapshot {
    std::vector<ProcessorStats> stats;  // per worker, summed for the report
    std::vector<std::size_t> memory;    // per worker
    std::vector<std::size_t> samples_per_level;
    std::size_t samples_total = 0;
    double seconds_max_window = 0.0;  // reset by each diagnostics report
  };
  std::mutex snapshot_mutex_;
  Snapshot snapshot_;
  // Diagnostics window (diagnostics callback only).
  ros::WallTime window_start_;
  std::uint64_t window_received_ = 0;
  ProcessorStats window_stats_;
  std::uint64_t window_overload_ = 0;

  std::vector<std::thread> workers_;  // last: started once everything above exists
};

}  // namespace hpds_node
