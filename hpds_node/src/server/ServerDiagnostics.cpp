// The server's diagnostics: a snapshot the workers refresh after every frame, reported on a wall-clock timer.
#include <algorithm>

#include "hpds_node/HpdsServer.hpp"

namespace hpds_node {

namespace {

double mean(double sum, std::uint64_t n) { return n ? sum / double(n) : 0.0; }

}  // namespace

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

ProcessorStats HpdsServer::statsSoFar(std::size_t worker) const {
  ProcessorStats total = processors_[worker]->stats();
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  for (std::size_t w = 0; w < snapshot_.stats.size(); ++w)
    if (w != worker) total += snapshot_.stats[w];
  return total;
}

void HpdsServer::diagnose(diagnostic_updater::DiagnosticStatusWrapper &status) {
  Snapshot s;
  {
    std::lock_guard<std::mutex> lock(snapshot_mutex_);
    s = snapshot_;
    snapshot_.seconds_max_window = 0.0;
  }
  std::uint64_t received, overload, lost_upstream;
  {
    std::lock_guard<std::mutex> lock(input_mutex_);
    received = received_;
    overload = overload_;
    lost_upstream = lost_upstream_;
  }
  const ros::WallTime now = ros::WallTime::now();
  const double window = std::max(1e-6, (now - window_start_).toSec());
  ProcessorStats t;
  for (const ProcessorStats &one : s.stats) t += one;
  std::size_t memory_bytes = 0;
  for (std::size_t m : s.memory) memory_bytes += m;
  const ProcessorStats &w = window_stats_;
  const std::uint64_t frames_window = t.processed - w.processed;
  // Frames nobody listens to are not a problem worth a warning; every other drop of a received frame is. Frames
  // lost upstream never reached the node, and a throttle or filter upstream (topic_tools throttle/drop, rosbag
  // filter) skips header.seq numbers on purpose: they are counted and logged, but do not make the node WARN.
  const std::uint64_t dropped_window =
      (t.droppedTotal() - w.droppedTotal()) + (overload - window_overload_) -
      (t.dropped[int(DropReason::NoSubscribers)] - w.dropped[int(DropReason::NoSubscribers)]);

  status.add("input rate [Hz]", double(received - window_received_) / window);
  status.add("frames received", received);
  status.add("frames processed", t.processed);
  status.add("frames empty", t.empty);
  status.add("frames with zero stamp", zero_stamps_.load());
  status.add("frames without frame_id", empty_frame_ids_.load());
  status.add("pose jumps", t.pose_jumps);
  status.add("processing time mean [ms]", 1e3 * mean(t.seconds_sum - w.seconds_sum, frames_window));
  status.add("processing time max [ms]", 1e3 * s.seconds_max_window);
  status.add("processing time mean, all frames [ms]", 1e3 * mean(t.seconds_sum, t.processed));
  status.add("processing time max, all frames [ms]", 1e3 * t.seconds_max);
  status.add("dropped total", t.droppedTotal() + overload);
  status.add("dropped malformed", t.malformedTotal());
  for (int e = 1; e < kCloudErrorCount; ++e)
    status.add(std::string("dropped malformed ") + toString(CloudError(e)), t.malformed[e]);
  status.add("dropped overload", overload);
  status.add("frames lost upstream", lost_upstream);
  for (DropReason r : {DropReason::NoTransform, DropReason::LayoutChanged, DropReason::NoSubscribers,
                       DropReason::InternalError})
    status.add(std::string("dropped ") + toString(r), t.dropped[int(r)]);
  status.add("points input", t.points.input);
  status.add("points skipped invalid", t.points.skipped_invalid);
  status.add("points skipped zero", t.points.skipped_zero);
  status.add("points skipped range", t.points.skipped_range);
  status.add("points out of key range", t.points.out_of_range);
  status.add("points dropped past the deepest level", t.points.dropped_depth);
  status.add("deepest level built", s.samples_per_level.empty() ? 0 : s.samples_per_level.size() - 1);
  status.add("samples stored", s.samples_total);
  status.add("samples evicted", t.points.evicted);
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
