#include "hpds_node/HpdsServer.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <system_error>

#include "hpds/util/ParallelFor.hpp"

namespace hpds_node {

namespace {

double mean(double sum, std::uint64_t n) { return n ? sum / double(n) : 0.0; }

}  // namespace

HpdsServer::HpdsServer(ros::NodeHandle nh, ros::NodeHandle private_nh, const std::string &name)
    : nh_(nh),
      pnh_(private_nh),
      config_(loadNodeConfigFromParams(private_nh)),
      updater_(nh, private_nh, name) {
  // Scan mode: frames are independent, so `threads` workers take one frame each, each processor on one thread.
  const std::size_t workers =
      config_.hpds.mode == hpds::Mode::Scan ? static_cast<std::size_t>(hpds::resolveThreads(config_.hpds.threads)) : 1;
  NodeConfig per_worker = config_;
  if (workers > 1) per_worker.hpds.threads = 1;
  for (std::size_t w = 0; w < workers; ++w) processors_.push_back(std::make_unique<FrameProcessor>(per_worker));
  keep_up_ = std::make_unique<KeepUpCheck>(config_.hpds, workers);
  target_frame_ = processors_.front()->targetFrame();
  const bool map_mode = config_.hpds.mode == hpds::Mode::Map;
  // Before anything is advertised: a node that cannot load its map does not appear at all.
  if (config_.ros.load_map_on_start) loadMapOnStart();
  if (!target_frame_.empty()) tf_listener_ = std::make_unique<tf2_ros::TransformListener>(tf_buffer_, nh_);

  pub_output_ = pnh_.advertise<sensor_msgs::PointCloud2>("output", 4);
  if (map_mode) {
    pub_new_samples_ = pnh_.advertise<sensor_msgs::PointCloud2>("new_samples", 4);
    if (config_.ros.local_map_rate > 0.0) pub_local_map_ = pnh_.advertise<sensor_msgs::PointCloud2>("local_map", 1);
  }
  for (int d : config_.ros.publish_levels)
    pub_levels_.push_back(pnh_.advertise<sensor_msgs::PointCloud2>("level_" + std::to_string(d), 4));

  updater_.setHardwareID("none");
  updater_.add("processing", this, &HpdsServer::diagnose);
  window_start_ = ros::WallTime::now();
  // Reported on a wall-clock timer: the updater's own rate limit runs on ROS time, which stops with a bag under
  // use_sim_time, and the final counts of a replay would never be published.
  double period = pnh_.param("diagnostic_period", 1.0);
  if (!(period > 0.0)) period = 1.0;
  diagnostics_timer_ = nh_.createWallTimer(ros::WallDuration(period), [this](const ros::WallTimerEvent &) {
    updater_.force_update();
  });
  snapshot_.stats.resize(processors_.size());
  snapshot_.memory.resize(processors_.size());
  for (std::size_t w = 0; w < processors_.size(); ++w) takeSnapshot(w, 0.0);

  for (std::size_t w = 0; w < processors_.size(); ++w) workers_.emplace_back([this, w] { workerLoop(w); });
  // roscpp's own queue only has to absorb bursts while onCloud runs; the counted dropping happens in queue_.
  sub_ = pnh_.subscribe("input", static_cast<std::uint32_t>(config_.ros.queue_size) + 4, &HpdsServer::onCloud, this);
  // Advertised in scan mode too, so that a call gets a clear answer rather than "service does not exist".
  srv_save_map_ = pnh_.advertiseService<std_srvs::Trigger::Request, std_srvs::Trigger::Response>(
      "save_map", [this](auto &req, auto &res) { return onMapService(true, req, res); });
  srv_load_map_ = pnh_.advertiseService<std_srvs::Trigger::Request, std_srvs::Trigger::Response>(
      "load_map", [this](auto &req, auto &res) { return onMapService(false, req, res); });

  const hpds::Pipeline &pipeline = processors_.front()->pipeline();
  std::ostringstream summary;
  summary << "hpds: " << hpds::toString(config_.hpds.mode) << " mode, " << pipeline.outputResolution().reason
          << "; levels 0.." << pipeline.buildDepth() << " built"
          << (config_.hpds.normals.enabled ? ", normals on" : ", normals off");
  if (!target_frame_.empty()) summary << ", outputs in frame '" << target_frame_ << "'";
  if (processors_.size() > 1) summary << ", " << processors_.size() << " frames in parallel";
  ROS_INFO_STREAM_NAMED("hpds", summary.str() << "; input " << sub_.getTopic() << ", output "
                                              << pub_output_.getTopic());
}

HpdsServer::~HpdsServer() {
  sub_.shutdown();
  // A service call in progress waits for the worker, which is still running: it is answered before this returns.
  srv_save_map_.shutdown();
  srv_load_map_.shutdown();
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    stopping_ = true;
  }
  queue_cv_.notify_all();
  for (std::thread &t : workers_)
    if (t.joinable()) t.join();
  // The worker is gone: the map is complete (no frame half-inserted) and nothing else touches it.
  if (config_.ros.save_map_on_shutdown && config_.hpds.mode == hpds::Mode::Map) {
    const auto [ok, message] = runMapCommand(true);
    if (ok) {
      ROS_INFO_STREAM_NAMED("hpds", "hpds: shutdown: " << message);
    } else {
      ROS_ERROR_STREAM_NAMED("hpds", "hpds: shutdown: the map was not saved: " << message);
    }
  }
}

void HpdsServer::loadMapOnStart() {
  const std::string &path = config_.ros.map_file;
  std::error_code ec;
  if (std::filesystem::status(path, ec).type() == std::filesystem::file_type::not_found) {
    ROS_WARN_STREAM_NAMED("hpds", "hpds: ros/load_map_on_start: map file '"
                                      << path << "' does not exist (yet): starting with an empty map");
    return;
  }
  const auto [ok, message] = runMapCommand(false);
  if (!ok) throw std::runtime_error("ros/load_map_on_start: " + message);
  ROS_INFO_STREAM_NAMED("hpds", "hpds: " << message);
}

std::pair<bool, std::string> HpdsServer::runMapCommand(bool save) {
  const std::string &path = config_.ros.map_file;
  FrameProcessor &processor = *processors_.front();  // map mode's only one
  const hpds::Pipeline &pipeline = processor.pipeline();
  std::ostringstream msg;
  try {
    if (save) {
      processor.saveMap(path);
      msg << "saved " << pipeline.hierarchy().sampleCount() << " samples (next frame index "
          << pipeline.framesProcessed() << ") to '" << path << "'";
    } else {
      processor.loadMap(path);
      msg << "loaded " << pipeline.hierarchy().sampleCount() << " samples (next frame index "
          << pipeline.framesProcessed() << ") from '" << path << "'";
    }
    return {true, msg.str()};
  } catch (const std::exception &e) {
    msg << (save ? "saving the map failed: " : "loading the map failed: ") << e.what();
    if (!save) msg << "; the running map (" << pipeline.hierarchy().sampleCount() << " samples) is unchanged";
    return {false, msg.str()};
  } catch (...) {
    return {false, save ? "saving the map failed: unknown error" : "loading the map failed: unknown error"};
  }
}

bool HpdsServer::onMapService(bool save, std_srvs::Trigger::Request &, std_srvs::Trigger::Response &res) {
  const char *service = save ? "~save_map" : "~load_map";
  res.success = false;
  if (config_.hpds.mode != hpds::Mode::Map) {
    res.message = "this node runs in scan mode, which keeps no map: saving and loading need mode: map";
  } else if (config_.ros.map_file.empty()) {
    res.message = "parameter " + pnh_.getNamespace() + "/ros/map_file is not set (the path of the map file)";
  } else {
    // Run by the worker between two frames; answered there (or refused here when the node is stopping).
    auto command = std::make_shared<MapCommand>();
    command->save = save;
    std::future<std::pair<bool, std::string>> result = command->done.get_future();
    bool queued = false;
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      if (!stopping_) {
        commands_.push_back(command);
        queued = true;
      }
    }
    if (queued) {
      queue_cv_.notify_all();
      std::tie(res.success, res.message) = result.get();
    } else {
      res.message = "the node is shutting down";
    }
  }
  if (res.success) {
    ROS_INFO_STREAM_NAMED("hpds", "hpds: " << service << ": " << res.message);
  } else {
    ROS_ERROR_STREAM_NAMED("hpds", "hpds: " << service << ": " << res.message);
  }
  return true;  // the outcome is in the response: a false return would hide the message from the caller
}

void HpdsServer::onCloud(const sensor_msgs::PointCloud2::ConstPtr &msg) {
  const double now = ros::WallTime::now().toSec();
  bool dropped = false;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    ++received_;
    if (queue_.size() >= static_cast<std::size_t>(config_.ros.queue_size)) {
      queue_.pop_front();
      ++overload_;
      dropped = true;
    }
    queue_.push_back(msg);
  }
  queue_cv_.notify_one();
  std::string warning;
  {
    std::lock_guard<std::mutex> lock(keep_up_mutex_);
    keep_up_->arrived(now);
    if (dropped) warning = keep_up_->dropped();
  }
  if (!warning.empty()) ROS_WARN_STREAM_NAMED("hpds", warning);
}

// Every frame a worker takes passes both turns exactly once, whatever happens to it (the destructor passes what
// is left), so a later frame never waits forever. Its predecessors are all held by running workers, which finish
// their frames before stopping.
class HpdsServer::Turns {
 public:
  Turns(HpdsServer &server, std::uint64_t ticket) : s_(server), ticket_(ticket) {}
  Turns(const Turns &) = delete;
  Turns &operator=(const Turns &) = delete;
  ~Turns() {
    if (!indexed_) passIndexTurn();
    if (!publishing_) waitToPublish();
    {
      std::lock_guard<std::mutex> lock(s_.turn_mutex_);
      ++s_.publish_turn_;
    }
    s_.turn_cv_.notify_all();
  }
  /// The frame's index in the stream of frames that passed the checks.
  std::uint32_t takeIndex() { return indexTurn(/*take=*/true); }
  /// Returns once every earlier frame has been published or dropped.
  void waitToPublish() {
    if (!indexed_) passIndexTurn();
    std::unique_lock<std::mutex> lock(s_.turn_mutex_);
    s_.turn_cv_.wait(lock, [this] { return s_.publish_turn_ == ticket_; });
    publishing_ = true;
  }
  /// A dropped frame: its index turn goes by without an index.
  void passIndexTurn() { indexTurn(/*take=*/false); }

 private:
  std::uint32_t indexTurn(bool take) {
    std::uint32_t index = 0;
    {
      std::unique_lock<std::mutex> lock(s_.turn_mutex_);
      s_.turn_cv_.wait(lock, [this] { return s_.index_turn_ == ticket_; });
      if (take) index = s_.next_frame_index_++;
      ++s_.index_turn_;
    }
    indexed_ = true;
    s_.turn_cv_.notify_all();
    return index;
  }

  HpdsServer &s_;
  std::uint64_t ticket_;
  bool indexed_ = false, publishing_ = false;
};

void HpdsServer::workerLoop(std::size_t worker) {
  for (;;) {
    sensor_msgs::PointCloud2::ConstPtr msg;
    std::shared_ptr<MapCommand> command;
    std::uint64_t ticket = 0;
    {
      std::unique_lock<std::mutex> lock(queue_mutex_);
      queue_cv_.wait(lock, [this] { return stopping_ || !queue_.empty() || !commands_.empty(); });
      // Map commands first, and all of them before stopping: each caller is waiting for its answer.
      if (!commands_.empty()) {
        command = commands_.front();
        commands_.pop_front();
      } else if (stopping_) {
        return;
      } else {
        msg = queue_.front();
        queue_.pop_front();
        ticket = next_ticket_++;
      }
    }
    if (command) {
      command->done.set_value(runMapCommand(command->save));
      takeSnapshot(worker, 0.0);
      continue;
    }
    double seconds = 0.0;
    {
      Turns turns(*this, ticket);
      try {
        seconds = handle(msg, worker, turns);
      } catch (const std::exception &e) {
        // A bug must not take the node down with it; the frame is lost and said so.
        ROS_ERROR_STREAM_THROTTLE_NAMED(5.0, "hpds", "hpds: frame dropped by an internal error: " << e.what());
      }
    }
    takeSnapshot(worker, seconds);
    if (seconds > 0.0) checkKeepUp(seconds);
  }
}

void HpdsServer::checkKeepUp(double frame_seconds) {
  std::string warning;
  {
    std::lock_guard<std::mutex> lock(keep_up_mutex_);
    warning = keep_up_->processed(frame_seconds);
  }
  if (!warning.empty()) ROS_WARN_STREAM_NAMED("hpds", warning);
}

OutputRequest HpdsServer::subscribedOutputs() const {
  OutputRequest r;
  r.output = pub_output_.getNumSubscribers() > 0;
  r.new_samples = pub_new_samples_ && pub_new_samples_.getNumSubscribers() > 0;
  r.local_map = pub_local_map_ && pub_local_map_.getNumSubscribers() > 0;
  for (const ros::Publisher &p : pub_levels_) r.levels.push_back(p.getNumSubscribers() > 0);
  return r;
}

bool HpdsServer::waitForPose(const std::string &target, const std_msgs::Header &header, Eigen::Isometry3d &pose,
                             std::string *why) {
  // Polled against wall time rather than tf2_ros::Buffer::canTransform(timeout): under use_sim_time that timeout
  // runs on the bag clock and never expires once the bag stops, which would wedge the worker.
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(config_.ros.tf_timeout);
  for (;;) {
    if (tf_buffer_.canTransform(target, header.frame_id, header.stamp))
      return lookupSensorPose(tf_buffer_, target, header.frame_id, header.stamp, pose, why);
    if (ros::WallTime::now() >= deadline || !ros::ok()) break;
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      if (stopping_) break;
    }
    ros::WallDuration(0.002).sleep();
  }
  return lookupSensorPose(tf_buffer_, target, header.frame_id, header.stamp, pose, why);
}

double HpdsServer::handle(const sensor_msgs::PointCloud2::ConstPtr &msg, std::size_t worker, Turns &turns) {
  FrameProcessor &processor = *processors_[worker];
  // 1. Validate before any work.
  std::string why;
  const CloudError error = processor.check(*msg, &why);
  if (error != CloudError::None) {
    ROS_ERROR_STREAM_THROTTLE_NAMED(5.0, "hpds", "hpds: dropped malformed PointCloud2 ("
                                                      << toString(error) << "): " << why);
    return 0.0;
  }

  // 2. Nobody listening: scan mode has nothing to keep, map mode still has to grow the map.
  const OutputRequest wants = subscribedOutputs();
  if (config_.hpds.mode == hpds::Mode::Scan && !wants.any()) {
    processor.countDrop(DropReason::NoSubscribers);
    return 0.0;
  }

  // 3. Sensor pose in the target frame at the message stamp.
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  if (!target_frame_.empty() && !waitForPose(target_frame_, msg->header, pose, &why)) {
    processor.countDrop(DropReason::NoTransform);
    ROS_WARN_STREAM_THROTTLE_NAMED(5.0, "hpds", "hpds: dropped frame at " << msg->header.stamp << ": no transform '"
                                                                           << msg->header.frame_id << "' -> '"
                                                                           << target_frame_ << "': " << why);
    return 0.0;
  }

  // 4. Shared per-frame processing, then publish what was built, in arrival order. With one worker its pipeline
  //    counts the frames itself; several take the index of their frame in the stream.
  const std::uint32_t index = turns.takeIndex();
  if (processors_.size() > 1) processor.setNextFrameIndex(index);
  ProcessedFrame frame = processor.process(*msg, pose, wants);
  if (!frame.processed) {
    ROS_ERROR_STREAM_THROTTLE_NAMED(5.0, "hpds", "hpds: dropped frame: " << frame.why);
    return 0.0;
  }
  turns.waitToPublish();
  publish(frame);
  return frame.seconds;
}

void HpdsServer::publish(ProcessedFrame &frame) {
  // Published as shared pointers so that nodelets in the same manager get them without a copy.
  auto send = [](const ros::Publisher &pub, sensor_msgs::PointCloud2 &cloud) {
    auto msg = boost::make_shared<sensor_msgs::PointCloud2>();
    msg->header = cloud.header;
    msg->height = cloud.height;
    msg->width = cloud.width;
    msg->fields.swap(cloud.fields);
    msg->is_bigendian = cloud.is_bigendian;
    msg->point_step = cloud.point_step;
    msg->row_step = cloud.row_step;
    msg->data.swap(cloud.data);
    msg->is_dense = cloud.is_dense;
    pub.publish(msg);
  };
  if (frame.has_output) send(pub_output_, frame.output);
  if (frame.has_new_samples) send(pub_new_samples_, frame.new_samples);
  if (frame.has_local_map) send(pub_local_map_, frame.local_map);
  for (auto &[level, cloud] : frame.levels) {
    for (std::size_t i = 0; i < config_.ros.publish_levels.size(); ++i)
      if (config_.ros.publish_levels[i] == level) send(pub_levels_[i], cloud);
  }
}

void HpdsServer::takeSnapshot(std::size_t worker, double frame_seconds) {
  // Each worker reports its own processor; the hierarchy shown is the one of the frame finished last.
  const FrameProcessor &processor = *processors_[worker];
  const hpds::Hierarchy &h = processor.pipeline().hierarchy();
  std::vector<std::size_t> per_level;
  for (int d = 0; d <= processor.pipeline().buildDepth(); ++d) per_level.push_back(h.countAtLevel(d));
  const ProcessorStats stats = processor.stats();
  const std::size_t total = h.sampleCount(), memory = h.memUsage();
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  snapshot_.stats[worker] = stats;
  snapshot_.memory[worker] = memory;
  snapshot_.samples_per_level = std::move(per_level);
  snapshot_.samples_total = total;
  snapshot_.seconds_max_window = std::max(snapshot_.seconds_max_window, frame_seconds);
}

void HpdsServer::diagnose(diagnostic_updater::DiagnosticStatusWrapper &status) {
  Snapshot s;
  {
    std::lock_guard<std::mutex> lock(snapshot_mutex_);
    s = snapshot_;
    snapshot_.seconds_max_window = 0.0;
  }
  std::uint64_t received, overload;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    received = received_;
    overload = overload_;
  }
  const ros::WallTime now = ros::WallTime::now();
  const double window = std::max(1e-6, (now - window_start_).toSec());
  ProcessorStats t;
  for (const ProcessorStats &one : s.stats) t += one;
  std::size_t memory_bytes = 0;
  for (std::size_t m : s.memory) memory_bytes += m;
  const ProcessorStats &w = window_stats_;
  const std::uint64_t frames_window = t.processed - w.processed;
  const std::uint64_t dropped_window =
      (t.droppedTotal() - w.droppedTotal()) + (overload - window_overload_) -
      (t.dropped[int(DropReason::NoSubscribers)] - w.dropped[int(DropReason::NoSubscribers)]);

  status.add("input rate [Hz]", double(received - window_received_) / window);
  status.add("frames received", received);
  status.add("frames processed", t.processed);
  status.add("frames empty", t.empty);
  status.add("processing time mean [ms]", 1e3 * mean(t.seconds_sum - w.seconds_sum, frames_window));
  status.add("processing time max [ms]", 1e3 * s.seconds_max_window);
  status.add("processing time mean, all frames [ms]", 1e3 * mean(t.seconds_sum, t.processed));
  status.add("processing time max, all frames [ms]", 1e3 * t.seconds_max);
  status.add("dropped total", t.droppedTotal() + overload);
  status.add("dropped malformed", t.malformedTotal());
  for (int e = 1; e < kCloudErrorCount; ++e)
    status.add(std::string("dropped malformed ") + toString(CloudError(e)), t.malformed[e]);
  status.add("dropped overload", overload);
  for (DropReason r : {DropReason::NoTransform, DropReason::LayoutChanged, DropReason::NoSubscribers})
    status.add(std::string("dropped ") + toString(r), t.dropped[int(r)]);
  status.add("points input", t.points.input);
  status.add("points skipped invalid", t.points.skipped_invalid);
  status.add("points skipped zero", t.points.skipped_zero);
  status.add("points skipped range", t.points.skipped_range);
  status.add("points out of key range", t.points.out_of_range);
  status.add("points dropped past the deepest level", t.points.dropped_depth);
  status.add("deepest level built", s.samples_per_level.empty() ? 0 : s.samples_per_level.size() - 1);
  status.add("samples stored", s.samples_total);
  for (std::size_t d = 0; d < s.samples_per_level.size(); ++d)
    status.add("samples level " + std::to_string(d), s.samples_per_level[d]);
  status.add("memory in use [bytes]", memory_bytes);

  if (dropped_window > 0) {
    status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%llu frames dropped in the last %.1f s",
                    static_cast<unsigned long long>(dropped_window), window);
  } else if (received == window_received_) {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "waiting for input");
  } else {
    status.summaryf(diagnostic_msgs::DiagnosticStatus::OK, "%.1f Hz in, %.1f ms per frame",
                    double(received - window_received_) / window,
                    1e3 * mean(t.seconds_sum - w.seconds_sum, frames_window));
  }
  window_start_ = now;
  window_received_ = received;
  window_overload_ = overload;
  window_stats_ = t;
}

}  // namespace hpds_node
