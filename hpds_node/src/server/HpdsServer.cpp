#include "hpds_node/HpdsServer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <system_error>

#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/util/ParallelFor.hpp"

namespace hpds_node {

namespace {

// [s] A first frame that waited longer than this for its transform was slow for want of tf, not for allocations.
constexpr double kStartupWaitSeconds = 0.01;

// diagnostic_period: a wall timer period, which ros::WallDuration must be able to hold. The parameter, else the
// config_file's key (`from_file`, 0 when it has none), else 1 s.
double diagnosticPeriod(const ros::NodeHandle &pnh, double from_file) {
  double period = 1.0;
  XmlRpc::XmlRpcValue value;
  if (!pnh.getParam("diagnostic_period", value)) {
    if (!(from_file > 0.0)) return period;
    // Set as the parameter, which diagnostic_updater reads itself (in its constructor, which runs next, and on
    // every update): the file's value was checked and then ignored, and /diagnostics came every second.
    pnh.setParam("diagnostic_period", from_file);
    return from_file;
  }
  if (value.getType() == XmlRpc::XmlRpcValue::TypeDouble) {
    period = static_cast<double>(value);
  } else if (value.getType() == XmlRpc::XmlRpcValue::TypeInt) {
    period = static_cast<int>(value);
  } else {
    period = NAN;
  }
  try {
    return checkDiagnosticPeriod(period);  // the rule a config file's diagnostic_period is checked by
  } catch (const std::invalid_argument &e) {
    throw std::invalid_argument("parameter " + pnh.getNamespace() + "/" + e.what());
  }
}

}  // namespace

HpdsServer::HpdsServer(ros::NodeHandle nh, ros::NodeHandle private_nh, const std::string &name)
    : nh_(nh),
      pnh_(private_nh),
      config_(loadNodeConfigFromParams(private_nh)),
      diagnostic_period_(diagnosticPeriod(private_nh, config_.diagnostic_period)),
      updater_(nh, private_nh, name),
      tag_("hpds " + name),
      tf_buffer_(ros::Duration(tfCacheSeconds(config_.ros))) {
  // Scan mode: frames are independent, so `threads` workers take one frame each, each processor on one thread.
  const std::size_t workers =
      config_.hpds.mode == hpds::Mode::Scan ? static_cast<std::size_t>(hpds::resolveThreads(config_.hpds.threads)) : 1;
  NodeConfig per_worker = config_;
  if (workers > 1) per_worker.hpds.threads = 1;
  for (std::size_t w = 0; w < workers; ++w) processors_.push_back(std::make_unique<FrameProcessor>(per_worker));
  keep_up_ = std::make_unique<KeepUpCheck>(config_.hpds, workers, 8, config_.ros.tf_timeout,
                                           static_cast<std::size_t>(config_.ros.queue_size));
  target_frame_ = processors_.front()->targetFrame();
  const bool map_mode = config_.hpds.mode == hpds::Mode::Map;
  // Before anything is advertised: a node that cannot load its map, or could not save it at the end of a run,
  // does not appear at all.
  if (config_.ros.load_map_on_start) loadMapOnStart();
  if (config_.ros.save_map_on_shutdown && map_mode) requireMapFolder();
  if (!target_frame_.empty() || !config_.ros.sensor_frame.empty())
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(tf_buffer_, nh_);

  pub_output_ = pnh_.advertise<sensor_msgs::PointCloud2>("output", 4);
  if (map_mode) {
    pub_new_samples_ = pnh_.advertise<sensor_msgs::PointCloud2>("new_samples", 4);
    if (config_.ros.local_map_rate > 0.0) pub_local_map_ = pnh_.advertise<sensor_msgs::PointCloud2>("local_map", 1);
  }
  for (int d : config_.ros.publish_levels)
    pub_levels_.push_back(pnh_.advertise<sensor_msgs::PointCloud2>("level_" + std::to_string(d), 4));

  // The sensor this instance serves, by its input topic: with several instances, what tells their statuses apart
  // besides the node name.
  updater_.setHardwareID(pnh_.resolveName("input"));
  updater_.add("processing", this, &HpdsServer::diagnose);
  window_start_ = ros::WallTime::now();
  // Reported on a wall-clock timer: the updater's own rate limit runs on ROS time, which stops with a bag under
  // use_sim_time, and the final counts of a replay would never be published.
  diagnostics_timer_ = nh_.createWallTimer(ros::WallDuration(diagnostic_period_), [this](const ros::WallTimerEvent &) {
    // The updater re-reads ~diagnostic_period on every update, and a value set at run time that ros::Duration
    // cannot hold makes it throw: that must cost a report, not the node.
    try {
      updater_.force_update();
    } catch (const std::exception &e) {
      if (logAllowed("diagnostics"))
        ROS_ERROR_STREAM_NAMED("hpds", tag_ << ": diagnostics not published: " << e.what());
    }
  });
  snapshot_.stats.resize(processors_.size());
  snapshot_.memory.resize(processors_.size());
  for (std::size_t w = 0; w < processors_.size(); ++w) takeSnapshot(w, 0.0);

  pool_ = std::make_unique<OrderedWorkerPool>(
      processors_.size(), static_cast<std::size_t>(config_.ros.queue_size),
      [this](const sensor_msgs::PointCloud2::ConstPtr &msg, std::size_t worker, OrderedWorkerPool::Turns &turns) {
        handle(msg, worker, turns);
      },
      [this](std::size_t worker, const std::string &what) { onInternalError(worker, what); });
  // roscpp's own queue only has to absorb bursts while onCloud runs; the counted dropping happens in the pool.
  sub_ = pnh_.subscribe("input", static_cast<std::uint32_t>(config_.ros.queue_size) + 4, &HpdsServer::onCloud, this);
  // Advertised in scan mode too, so that a call gets a clear answer rather than "service does not exist". Served
  // on their own thread: a save of a large map must not stop the subscriber callback, or roscpp's queue would drop
  // frames while it runs.
  ros::NodeHandle service_nh(pnh_);
  service_nh.setCallbackQueue(&service_queue_);
  srv_save_map_ = service_nh.advertiseService<std_srvs::Trigger::Request, std_srvs::Trigger::Response>(
      "save_map", [this](auto &req, auto &res) { return onMapService(true, req, res); });
  srv_load_map_ = service_nh.advertiseService<std_srvs::Trigger::Request, std_srvs::Trigger::Response>(
      "load_map", [this](auto &req, auto &res) { return onMapService(false, req, res); });
  srv_clear_map_ = service_nh.advertiseService<std_srvs::Trigger::Request, std_srvs::Trigger::Response>(
      "clear_map", [this](auto &req, auto &res) { return onClearMap(req, res); });
  service_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &service_queue_);
  service_spinner_->start();

  if (const std::string w = hpds::ignoredRosKeysWarning(config_.ros, config_.hpds.mode); !w.empty())
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << w);
  std::ostringstream summary;
  summary << tag_ << ": " << processors_.front()->samplingSummary();
  if (!target_frame_.empty()) summary << ", outputs in frame '" << target_frame_ << "'";
  if (processors_.size() > 1) summary << ", " << processors_.size() << " frames in parallel";
  ROS_INFO_STREAM_NAMED("hpds", summary.str() << "; input " << sub_.getTopic() << ", output "
                                              << pub_output_.getTopic());
}

HpdsServer::~HpdsServer() { shutdown(); }

bool HpdsServer::shutdown() {
  if (shut_down_) return shutdown_ok_;
  shut_down_ = true;
  sub_.shutdown();
  // A service call in progress waits for a worker, which is still running: it is answered before the spinner stops.
  if (service_spinner_) service_spinner_->stop();
  srv_save_map_.shutdown();
  srv_load_map_.shutdown();
  srv_clear_map_.shutdown();
  // hpds_node stops itself while roscpp still runs (node_main.cpp); a nodelet is destroyed after its manager's
  // ros::shutdown(), which has taken rosconsole down: then the lines go to stderr directly, or nobody would learn
  // what became of the map.
  const auto say = [](bool error, const std::string &text) {
    if (ros::isStarted() && !ros::isShuttingDown()) {
      if (error)
        ROS_ERROR_STREAM_NAMED("hpds", text);
      else
        ROS_INFO_STREAM_NAMED("hpds", text);
    } else {
      std::fprintf(stderr, "[%s] [%.6f]: %s\n", error ? "ERROR" : " INFO", ros::WallTime::now().toSec(), text.c_str());
      std::fflush(stderr);
    }
  };
  const std::size_t discarded = pool_ ? pool_->stop() : 0;
  if (discarded > 0)
    say(false, tag_ + ": shutdown: " + std::to_string(discarded) + " received frame(s) were still queued and are not "
               "processed");
  // The workers are gone: the map is complete (no frame half-inserted) and nothing else touches it.
  if (config_.ros.save_map_on_shutdown && config_.hpds.mode == hpds::Mode::Map) {
    if (processors_.front()->pipeline().framesProcessed() == frames_at_last_sync_) {
      say(false, tag_ + ": shutdown: no frame was processed since " + last_sync_ + ": '" + config_.ros.map_file +
                     "' is left as it is");
      return shutdown_ok_;
    }
    if (emptySaveWouldReplaceTheFile()) {
      say(false, tag_ + ": shutdown: the map holds no sample: '" + config_.ros.map_file + "' is left as it is");
      return shutdown_ok_;
    }
    const auto [ok, message] = runMapCommand(true);
    shutdown_ok_ = ok;
    say(!ok, ok ? tag_ + ": shutdown: " + message : tag_ + ": shutdown: the map was not saved: " + message);
  }
  return shutdown_ok_;
}

std::string HpdsServer::tagged(const std::string &text) const {
  // KeepUpCheck's lines start "hpds: "; with several nodelets in one manager each line must say whose it is.
  return text.rfind("hpds: ", 0) == 0 ? tag_ + text.substr(4) : text;
}

bool HpdsServer::logAllowed(const std::string &key) {
  const double now = ros::WallTime::now().toSec();
  std::lock_guard<std::mutex> lock(log_mutex_);
  auto [it, fresh] = last_logged_.try_emplace(key, now);
  if (!fresh && now - it->second < kLogThrottleSeconds) return false;
  it->second = now;
  return true;
}

bool HpdsServer::emptySaveWouldReplaceTheFile() const {
  if (processors_.front()->pipeline().hierarchy().sampleCount() != 0) return false;
  std::error_code ec;
  return std::filesystem::is_regular_file(config_.ros.map_file, ec) &&
         std::filesystem::file_size(config_.ros.map_file, ec) > 0 && !ec;
}

void HpdsServer::requireMapFolder() const {
  // Found saving into a missing folder, or onto a folder: the error came at shutdown, after all the mapping.
  const std::string why = hpds::folderProblem(config_.ros.map_file);
  if (!why.empty())
    throw std::invalid_argument("parameter " + pnh_.getNamespace() + "/ros/map_file: '" + config_.ros.map_file + "' " +
                                why + " (ros/save_map_on_shutdown would fail at the end of the run)");
}

void HpdsServer::loadMapOnStart() {
  const std::string &path = config_.ros.map_file;
  std::error_code ec;
  if (std::filesystem::status(path, ec).type() == std::filesystem::file_type::not_found) {
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": ros/load_map_on_start: map file '"
                                      << path << "' does not exist (yet): starting with an empty map");
    return;
  }
  const auto [ok, message] = runMapCommand(false);
  if (!ok) throw std::runtime_error("ros/load_map_on_start: " + message);
  ROS_INFO_STREAM_NAMED("hpds", tag_ << ": " << message);
}

std::pair<bool, std::string> HpdsServer::runMapCommand(bool save) {
  const std::string &path = config_.ros.map_file;
  FrameProcessor &processor = *processors_.front();  // map mode's only one
  const hpds::Pipeline &pipeline = processor.pipeline();
  std::ostringstream msg;
  try {
    if (save) {
      // An empty map over a file that holds one (a save called before any frame or load, or after ~clear_map) would
      // destroy it: the file stays, and the caller hears why.
      if (emptySaveWouldReplaceTheFile())
        return {false, "the running map holds no sample: '" + path + "' is left as it is (an empty save would replace "
                       "the map it holds; ~load_map takes it up, or remove the file to save an empty map)"};
      processor.saveMap(path);
      msg << "saved " << pipeline.hierarchy().sampleCount() << " samples (next frame index "
          << pipeline.framesProcessed() << ") to '" << path << "'";
      // Saved all the same (it is what the run has), but the caller, the shutdown log and the log all hear why the
      // map is weaker than the one loaded.
      if (const std::string w = processor.shallowSaveWarning(); !w.empty()) {
        ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << w);
        msg << "; warning: " << w;
      }
    } else {
      const std::string normals_warning = processor.loadMap(path);
      msg << "loaded " << pipeline.hierarchy().sampleCount() << " samples (next frame index "
          << pipeline.framesProcessed() << ") from '" << path << "'";
      // As with a weaker save: the caller and the log both hear it.
      for (const std::string &w : {hpds::shallowMapWarning(processor.pipeline()), normals_warning})
        if (!w.empty()) {
          ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << w);
          msg << "; warning: " << w;
        }
    }
    frames_at_last_sync_ = pipeline.framesProcessed();
    last_sync_ = "the map was last loaded or saved";
    return {true, msg.str()};
  } catch (const std::exception &e) {
    msg << (save ? "saving the map failed: " : "loading the map failed: ") << e.what();
    if (!save) msg << "; the running map (" << pipeline.hierarchy().sampleCount() << " samples) is unchanged";
    return {false, msg.str()};
  } catch (...) {
    return {false, save ? "saving the map failed: unknown error" : "loading the map failed: unknown error"};
  }
}

std::string HpdsServer::mapFileSetSinceStart() const {
  std::string now;
  if (!pnh_.getParam("ros/map_file", now) || now == config_.ros.map_file) return "";
  return now;
}

bool HpdsServer::onMapService(bool save, std_srvs::Trigger::Request &, std_srvs::Trigger::Response &res) {
  const char *service = save ? "~save_map" : "~load_map";
  res.success = false;
  const std::string changed = mapFileSetSinceStart();
  const bool refused = config_.hpds.mode != hpds::Mode::Map || config_.ros.map_file.empty();
  if (config_.hpds.mode != hpds::Mode::Map) {
    res.message = "this node runs in scan mode, which keeps no map: saving and loading need mode: map";
  } else if (config_.ros.map_file.empty()) {
    res.message = "parameter " + pnh_.getNamespace() + "/ros/map_file was not set when the node started";
    if (!changed.empty())
      res.message += " (it is '" + changed + "' now, but parameters are read only at start: restart the node)";
  } else {
    // Run by the worker between two frames; answered there (or refused here when the node is stopping).
    std::pair<bool, std::string> result{false, "the node is shutting down"};
    pool_->runBetweenFrames([&](std::size_t worker) {
      result = runMapCommand(save);
      takeSnapshot(worker, 0.0);
    });
    std::tie(res.success, res.message) = result;
    if (!changed.empty())
      res.message += " (ros/map_file is '" + changed + "' now, but parameters are read only at start: this node "
                     "uses '" + config_.ros.map_file + "' until it is restarted)";
  }
  if (res.success) {
    ROS_INFO_STREAM_NAMED("hpds", tag_ << ": " << service << ": " << res.message);
  } else if (refused) {
    // A call this node cannot serve (no map, no file): the caller's mistake, answered; nothing failed here.
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << service << " refused: " << res.message);
  } else {
    ROS_ERROR_STREAM_NAMED("hpds", tag_ << ": " << service << ": " << res.message);
  }
  return true;  // the outcome is in the response: a false return would hide the message from the caller
}

bool HpdsServer::onClearMap(std_srvs::Trigger::Request &, std_srvs::Trigger::Response &res) {
  res.success = false;
  if (config_.hpds.mode != hpds::Mode::Map) {
    res.message = "this node runs in scan mode, which keeps no map to clear";
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": ~clear_map refused: " << res.message);
    return true;
  }
  res.message = "the node is shutting down";
  pool_->runBetweenFrames([&](std::size_t worker) {
    FrameProcessor &processor = *processors_.front();  // map mode's only one
    const std::size_t held = processor.clearMap();
    // A shutdown save with no frame since writes nothing: an empty map must not replace the file.
    frames_at_last_sync_ = processor.pipeline().framesProcessed();
    last_sync_ = "the map was cleared";
    std::ostringstream msg;
    msg << "cleared " << held << " samples; the next frame's point fields become the map's (next frame index "
        << processor.pipeline().framesProcessed() << ")";
    res.message = msg.str();
    res.success = true;
    takeSnapshot(worker, 0.0);
  });
  if (res.success) {
    ROS_INFO_STREAM_NAMED("hpds", tag_ << ": ~clear_map: " << res.message);
  } else {
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": ~clear_map: " << res.message);
  }
  return true;
}

void HpdsServer::onCloud(const ros::MessageEvent<const sensor_msgs::PointCloud2> &event) {
  const sensor_msgs::PointCloud2::ConstPtr &msg = event.getConstMessage();
  const double now = ros::WallTime::now().toSec();
  // Read, not MessageEvent::getPublisherName(), whose operator[] may insert into the connection header roscpp shares.
  std::string publisher;
  if (const auto header = event.getConnectionHeaderPtr()) {
    const auto it = header->find("callerid");
    if (it != header->end()) publisher = it->second;
  }
  std::uint64_t lost = 0, lost_total = 0, overload_total = 0;
  {
    std::lock_guard<std::mutex> lock(input_mutex_);
    ++received_;
    lost = sequence_gaps_.observe(publisher, msg->header.seq);
    lost_upstream_ += lost;
    lost_total = lost_upstream_;
  }
  const bool dropped = pool_->push(msg);
  if (dropped) {
    std::lock_guard<std::mutex> lock(input_mutex_);
    overload_total = ++overload_;
  }
  // Throttled on the wall clock (logAllowed), not ROS time: under use_sim_time without /clock a ROS-time throttle
  // never lets the first line through.
  if (lost > 0 && logAllowed("lost_upstream"))
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << lost << " frame(s) from " << publisher << " never arrived (header.seq "
                                           << "jumped to " << msg->header.seq << "): lost in a publisher's queue or in this "
                                           << "node's roscpp queue (an overloaded machine) before hpds received them ("
                                           << lost_total << " so far, counted in /diagnostics as 'frames lost "
                                           << "upstream'; a throttle, drop or filter upstream skips numbers on "
                                           << "purpose, and then this is expected)");
  std::string warning;
  bool starting = false;
  {
    std::lock_guard<std::mutex> lock(keep_up_mutex_);
    starting = keep_up_->warmingUp();
    if (dropped && starting) ++startup_drops_;  // said when the first frame ends (checkKeepUp)
    keep_up_->arrived(now);
    if (dropped) warning = keep_up_->dropped();
  }
  if (dropped && !starting) logOverload(overload_total);
  if (!warning.empty()) ROS_WARN_STREAM_NAMED("hpds", tagged(warning));
}

void HpdsServer::logOverload(std::uint64_t overload_total) {
  if (logAllowed("overload"))
    ROS_WARN_STREAM_NAMED("hpds", tag_ << ": dropped the oldest queued frame: frames arrive faster than they are "
                                  "processed ("
                                      << overload_total << " so far, counted as overload; ros.queue_size "
                                      << config_.ros.queue_size << ")");
}

void HpdsServer::onInternalError(std::size_t worker, const std::string &what) {
  // A bug or an exhausted resource must not take the node down with it; the frame is lost, counted and said so.
  processors_[worker]->countDrop(DropReason::InternalError);
  if (logAllowed("internal_error"))
    ROS_ERROR_STREAM_NAMED("hpds", tag_ << ": frame dropped by an internal error ("
                                       << statsSoFar(worker).dropped[int(DropReason::InternalError)]
                                       << " so far, counted as internal_error): " << what);
  takeSnapshot(worker, 0.0);
}

void HpdsServer::warnFieldNotCarriedOnce(const std::string &name) {
  {
    std::lock_guard<std::mutex> lock(input_mutex_);
    if (!fields_not_carried_.insert(name).second) return;
  }
  ROS_WARN_STREAM_NAMED("hpds", tag_ << ": input field '" << name << "' is not in the outputs: " << hpds::fieldNotCarriedReason(name)
                                                      << "; rename the field in the input to keep it");
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
                             Eigen::Vector3d &viewpoint, std::string *why) {
  // Polled against wall time rather than tf2_ros::Buffer::canTransform(timeout): under use_sim_time that timeout
  // runs on the bag clock and never expires once the bag stops, which would wedge the worker. One deadline for
  // both transforms (the cloud's into the target frame, the sensor's into the cloud's).
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(config_.ros.tf_timeout);
  const std::string cloud = tfFrameId(header.frame_id), &sensor = config_.ros.sensor_frame;
  const bool needs_pose = !target.empty(), needs_sensor = viewpointNeedsLookup(header.frame_id, sensor);
  for (;;) {
    if ((!needs_pose || tf_buffer_.canTransform(target, cloud, header.stamp)) &&
        (!needs_sensor || tf_buffer_.canTransform(cloud, sensor, header.stamp)))
      break;
    if (ros::WallTime::now() >= deadline || !ros::ok() || pool_->stopping()) break;
    ros::WallDuration(0.002).sleep();
  }
  if (needs_pose && !lookupSensorPose(tf_buffer_, target, header.frame_id, header.stamp, pose, why)) return false;
  if (!lookupViewpoint(tf_buffer_, header.frame_id, sensor, header.stamp, viewpoint, why)) {
    if (why) *why = "the sensor's frame (ros/sensor_frame) '" + sensor + "' in '" + cloud + "': " + *why;
    return false;
  }
  return true;
}

void HpdsServer::handle(const sensor_msgs::PointCloud2::ConstPtr &msg, std::size_t worker,
                        OrderedWorkerPool::Turns &turns) {
  FrameProcessor &processor = *processors_[worker];
  const auto count = [&](DropReason r) { return statsSoFar(worker).dropped[int(r)]; };
  const OutputRequest wants = subscribedOutputs();
  double seconds = 0.0, waited = 0.0;  // processing, and waiting for the frame's transform
  // 1. Validate before any work.
  std::string why;
  const CloudError error = processor.check(*msg, &why);
  if (error != CloudError::None) {
    if (logAllowed(std::string("malformed ") + toString(error)))
      ROS_ERROR_STREAM_NAMED("hpds", tag_ << ": dropped malformed PointCloud2 ("
                                         << toString(error) << ", " << statsSoFar(worker).malformedTotal()
                                         << " malformed so far): " << why);
  } else if (config_.hpds.mode == hpds::Mode::Scan && !wants.any()) {
    // 2. Nobody listening: scan mode has nothing to keep (map mode still has to grow the map).
    processor.countDrop(DropReason::NoSubscribers);
  } else {
    // 3. Sensor pose in the target frame at the message stamp.
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
    // Timed only when a transform is looked up (the node listens to tf exactly then): scan mode without output
    // frame has no wait to report.
    const bool looked_up = tf_listener_ != nullptr;
    const ros::WallTime wait_start = ros::WallTime::now();
    const bool posed = !looked_up || waitForPose(target_frame_, msg->header, pose, viewpoint, &why);
    if (looked_up) waited = (ros::WallTime::now() - wait_start).toSec();
    if (!posed) {
      processor.countDrop(DropReason::NoTransform);
      if (logAllowed("no_transform"))
        ROS_WARN_STREAM_NAMED("hpds", tag_ << ": dropped frame at "
                                          << msg->header.stamp << ": no transform"
                                          << (target_frame_.empty() ? std::string()
                                                                    : " '" + msg->header.frame_id + "' -> '" +
                                                                          target_frame_ + "'")
                                          << " (" << count(DropReason::NoTransform)
                                          << " so far, counted as no_transform): " << why
                                          << hpds_node::noTransformAdvice(why, config_.ros.tf_timeout));
    } else {
      // 4. Shared per-frame processing, then publish what was built, in arrival order. With one worker its
      //    pipeline counts the frames itself; several take the index of their frame in the stream.
      const std::uint32_t index = turns.takeIndex();
      if (processors_.size() > 1) processor.setNextFrameIndex(index);
      if (sensorAtMapOrigin(config_, msg->header.frame_id) && !warned_sensor_at_origin_.exchange(true))
        ROS_WARN_STREAM_NAMED(
            "hpds", tag_ << ": clouds arrive in the fixed frame '"
                        << config_.ros.fixed_frame
                        << "' itself, so where the sensor was is unknown: it is taken as that frame's origin, which "
                           "normals face and map/evict_distance and input ranges measure from (far from it, each "
                           "frame evicts the last). Set ros/sensor_frame to the sensor's tf frame");
      // Processed all the same: tf reads a zero stamp as "latest", which only a sensor at rest gets right.
      // Headers the driver must fix: warned about once, counted for every frame processed with them.
      const bool zero_stamp = msg->header.stamp.isZero();
      const bool no_frame_id = msg->header.frame_id.empty() && target_frame_.empty();
      if (zero_stamp && !warned_zero_stamp_.exchange(true))
        ROS_WARN_STREAM_NAMED("hpds", tag_ << ": input clouds have a zero header.stamp, which the outputs keep"
                                          << (looked_up ? std::string(", and tf gives them its latest transform, not "
                                                                      "the one of their capture (a moving sensor's "
                                                                      "map smears)")
                                                        : std::string())
                                          << " (counted in /diagnostics as 'frames with zero stamp'). Fix the "
                                             "driver's stamps");
      // Processed all the same (the output keeps the input's frame), but tf, RViz and PCL's tools cannot place it.
      if (no_frame_id && !warned_empty_frame_id_.exchange(true))
        ROS_WARN_STREAM_NAMED("hpds", tag_ << ": input clouds have an empty header.frame_id, which the outputs "
                                              "keep: tf and RViz cannot place them (counted in /diagnostics as "
                                              "'frames without frame_id'). Fix the driver's frame_id");
      ProcessedFrame frame = processor.process(*msg, pose, wants, viewpoint);
      if (!frame.processed) {
        if (logAllowed(std::string("dropped ") + toString(frame.drop)))
          ROS_ERROR_STREAM_NAMED("hpds", tag_ << ": dropped frame (" << toString(frame.drop) << ", " << count(frame.drop)
                                                                 << " so far): " << frame.why);
      } else {
        // Map mode forgets samples by design (a local map); said once, so that a map saved or shown later is not
        // taken for the whole drive. Counted in /diagnostics as 'samples evicted'.
        if (frame.counters.evicted > 0 && !told_evicting_.exchange(true))
          ROS_INFO_STREAM_NAMED("hpds", tag_ << ": the map evicts samples from now on ("
                                            << frame.counters.evicted << " at this frame; counted in /diagnostics as "
                                               "'samples evicted'): map/evict_distance ("
                                            << config_.hpds.map.evict_distance
                                            << " m, 0 = off) forgets those farther from the sensor before each frame, "
                                               "map/max_samples ("
                                            << config_.hpds.map.max_samples
                                            << ", 0 = no cap) caps the count; set both to 0 to keep every sample");
        if (frame.pose_jump && logAllowed("pose_jump"))
          ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << hpds::poseJumpWarning(*frame.pose_jump,
                                                                            "call ~clear_map to start a new map")
                                            << " (" << statsSoFar(worker).pose_jumps
                                            << " so far, counted in /diagnostics as 'pose jumps')");
        if (zero_stamp) ++zero_stamps_;
        if (no_frame_id) ++empty_frame_ids_;
        if (frame.counters.out_of_range > 0 && logAllowed("out_of_range"))
          ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << frame.counters.out_of_range << " of the frame's "
                                                                << frame.counters.input
                                                                << " points lie beyond the exact key range and were "
                                                                   "not inserted (counted as 'points out of key "
                                                                   "range'): "
                                                                << hpds::keyRangeAdvice(config_.hpds));
        for (const std::string &name : frame.fields_not_carried) warnFieldNotCarriedOnce(name);
        const double radius = processor.pipeline().outputResolution().radius;
        // The two parameters cannot both be true: advising float64 alone would stop the node at its next start.
        const std::string rounding = hpds::positionRoundingWarning(
            frame.position_rounding, radius,
            config_.hpds.output.float32_xyz ? "the parameter output/float64_xyz true instead of output/float32_xyz true"
                                            : "the parameter output/float64_xyz true",
            frame.input_rounding);
        if (!rounding.empty() && !warned_rounding_.exchange(true)) ROS_WARN_STREAM_NAMED("hpds", tag_ << ": " << rounding);
        turns.waitToPublish();
        publish(frame);
        seconds = frame.seconds;
      }
    }
  }
  takeSnapshot(worker, seconds);
  // A frame dropped for want of a transform still tells how long the worker waited for it.
  if (seconds > 0.0 || waited > 0.0) checkKeepUp(seconds, waited);
}

void HpdsServer::checkKeepUp(double frame_seconds, double waited) {
  std::string warning;
  std::uint64_t startup_drops = 0;
  {
    std::lock_guard<std::mutex> lock(keep_up_mutex_);
    warning = keep_up_->processed(frame_seconds, waited);
    if (!keep_up_->warmingUp()) std::swap(startup_drops, startup_drops_);
  }
  if (startup_drops > 0) {
    std::uint64_t overload_total = 0;
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      overload_total = overload_;
    }
    // The first frame pays for the node's allocations (several times a later frame's cost): the frames dropped
    // behind it are the start-up's, and KeepUpCheck says more only if the frames after it do not keep up. A first
    // frame that waited for its transform (or never got one) is no such cost: those drops are overload as any.
    if (frame_seconds > 0.0 && waited < kStartupWaitSeconds) {
      ROS_INFO_STREAM_NAMED("hpds", tag_ << ": " << startup_drops << " frame(s) dropped while the first frame was "
                                         << "processed (it took " << int(1e3 * frame_seconds + 0.5)
                                         << " ms: the first frame pays for the node's allocations; counted as "
                                         << "overload)");
    } else {
      logOverload(overload_total);
    }
  }
  if (!warning.empty()) ROS_WARN_STREAM_NAMED("hpds", tagged(warning));
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

}  // namespace hpds_node
