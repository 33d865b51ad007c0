#include "hpds_node/KeepUpCheck.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace hpds_node {

namespace {
constexpr std::size_t kKept = 64;

// Gaps this much shorter or longer than the usual one, all in a row, are a new rate.
constexpr double kRateChange = 1.5;

// [s] Before any period is known, a median wait for transforms longer than this is worth a warning of its own.
constexpr double kWaitWithoutPeriod = 0.01;

template <class It>
double median(It begin, It end) {
  std::vector<double> v(begin, end);
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double median(const std::deque<double> &values) { return median(values.begin(), values.end()); }

void keep(std::deque<double> &values, double v) {
  values.push_back(v);
  if (values.size() > kKept) values.pop_front();
}

std::string format(const char *pattern, double a, double b = 0.0, double c = 0.0) {
  char buf[160];
  std::snprintf(buf, sizeof buf, pattern, a, b, c);
  return buf;
}
}  // namespace

KeepUpCheck::KeepUpCheck(const hpds::HpdsConfig &config, std::size_t workers, std::size_t judge_after,
                         double tf_timeout, std::size_t queue_size)
    : config_(config),
      workers_(std::max<std::size_t>(1, workers)),
      judge_after_(std::max<std::size_t>(1, judge_after)),
      // A back-to-back delivery makes the queue overflow by its (workers + queue_size + 1)-th frame at the latest,
      // one gap short of this: its drop is never taken for a new rate.
      rate_change_gaps_(std::max<std::size_t>(1, workers) + std::max<std::size_t>(1, queue_size) + 1),
      tf_timeout_(tf_timeout),
      queue_size_(std::max<std::size_t>(1, queue_size)) {}

void KeepUpCheck::arrived(double wall_seconds) {
  // A burst (several messages at one instant) gives no period: only positive gaps count.
  if (last_arrival_ >= 0.0 && wall_seconds > last_arrival_) keep(gaps_, wall_seconds - last_arrival_);
  last_arrival_ = wall_seconds;
  // Kept across a change of rate, the older gaps would go on setting the median (for up to half the window), and a
  // drop soon after the input sped up would quote the old period and be called a moment behind.
  if (gaps_.size() <= rate_change_gaps_) return;
  const auto recent = gaps_.end() - static_cast<std::ptrdiff_t>(rate_change_gaps_);
  const double usual = median(gaps_.begin(), recent);
  const bool faster = std::all_of(recent, gaps_.end(), [&](double g) { return g < usual / kRateChange; });
  const bool slower = std::all_of(recent, gaps_.end(), [&](double g) { return g > usual * kRateChange; });
  if (faster || slower) gaps_.erase(gaps_.begin(), recent);
}

std::string KeepUpCheck::processed(double seconds, double waited) {
  first_done_ = true;
  if (waited > 0.0) keep(waits_, waited);
  // A drop came before enough was measured: said with a wait that matters, or with the verdict's count of costs;
  // then not at all when only the start-up dropped frames and the frames since keep up.
  auto pendingDrop = [this]() -> std::string {
    if (!drop_pending_ || warned_) return "";
    if (!waitsMatter() && costs_.size() < judge_after_) return "";
    drop_pending_ = false;
    if (!waitsMatter() && !dropped_after_start_ && !gaps_.empty() &&
        !(median(costs_) > double(workers_) * median(gaps_)))
      return "";
    warned_ = true;
    return warning(true);
  };
  if (!(seconds > 0.0)) return pendingDrop();  // dropped after its wait: nothing processed
  if (!first_skipped_) {
    first_skipped_ = true;
    return pendingDrop();
  }
  keep(costs_, seconds);
  ++costs_seen_;
  if (std::string w = pendingDrop(); !w.empty()) return w;
  if (judged_ || costs_seen_ < judge_after_ || gaps_.empty()) return "";
  judged_ = true;
  if (warned_ || !(median(costs_) > double(workers_) * median(gaps_))) return "";
  warned_ = true;
  return warning(false);
}

std::string KeepUpCheck::dropped() {
  if (warned_) return "";
  if (first_done_) dropped_after_start_ = true;
  // Too little measured (the first frame still running, or a few after it): a share of lost frames quoted now
  // could be far off, and it is said once. processed() says it when there is enough.
  if (costs_.size() < judge_after_ && !waitsMatter()) {
    drop_pending_ = true;
    return "";
  }
  warned_ = true;
  return warning(true);
}

bool KeepUpCheck::waitsMatter() const {
  // A lookup that returns at once (a transform already there) still takes microseconds: no measurement to report.
  if (waits_.empty()) return false;
  const double wait = median(waits_);
  return gaps_.empty() ? wait > kWaitWithoutPeriod : wait > 0.5 * median(gaps_);
}

std::string KeepUpCheck::warning(bool on_drop) const {
  const std::string workers = std::to_string(workers_) + (workers_ == 1 ? " worker" : " workers");
  const bool measured = !gaps_.empty() && !costs_.empty();
  // A drop while the usual rate keeps up: a burst of messages (their zero gaps give no period) or one slow frame.
  const bool keeps_up = measured && !(median(costs_) > double(workers_) * median(gaps_));
  std::string text = on_drop && keeps_up ? "hpds: fell behind the input for a moment: "
                                         : "hpds: cannot keep up with the input: ";
  if (on_drop) text += "a frame was dropped because the frames before it were still being processed; ";
  if (measured) {
    const double period = median(gaps_), cost = median(costs_);
    const double worst = *std::max_element(costs_.begin(), costs_.end());
    const double capacity = double(workers_) * period;
    text += "frames arrive every " + format("%.0f ms (%.1f Hz)", 1e3 * period, 1.0 / period) +
            (on_drop ? " and take " : " but take ") + format("%.0f ms each", 1e3 * cost) + " (median of " +
            std::to_string(costs_.size()) + (costs_.size() == 1 ? " frame, " : " frames, ") + format("%.0f ms at most", 1e3 * worst) + ", " + workers + ")";
    if (cost > capacity) text += ", so about " + format("%.0f%%", 100.0 * (1.0 - capacity / cost)) + " of the frames will be dropped";
    if (on_drop && keeps_up)
      text += ", which keeps up: frames came faster than that (a burst) or one took longer. A larger ros/queue_size "
              "absorbs bursts";
  } else if (!gaps_.empty()) {
    text += "frames arrive every " + format("%.0f ms (%.1f Hz)", 1e3 * median(gaps_), 1.0 / median(gaps_)) +
            " and none has been processed yet (" + workers + ")";
  } else {
    text += "no frame has been processed yet (" + workers + ")";
  }
  // A worker waiting for a transform takes no next frame: when that is most of the period (a transform that never
  // comes costs ros/tf_timeout per frame), no sampling setting helps.
  if (waitsMatter()) {
    const double wait = median(waits_);
    text += ". Frames also wait " + format("%.0f ms", 1e3 * wait) +
            " each for their transforms (up to ros/tf_timeout, now " + format("%.3g s", tf_timeout_) +
            "). If tf never has the sensor's frame in the fixed frame at the frames' stamps, check tf (frames without "
            "one are counted as no_transform) or lower ros/tf_timeout. If the transforms come late (odometry lagging "
            "the clouds), the frames that arrive while a worker waits need room in the queue: ";
    // Each worker waits for one frame's transform at a time; the frames of that wait must queue behind it.
    if (!gaps_.empty())
      text += "a ros/queue_size of at least " +
              std::to_string(static_cast<std::size_t>(std::ceil(wait / median(gaps_))) + 1) + " (now " +
              std::to_string(queue_size_) + ")";
    else
      text += "a ros/queue_size above that wait over the input period (now " + std::to_string(queue_size_) + ")";
    text += " keeps them instead of dropping them; no sampling setting shortens that wait";
  }
  const hpds::OutputResolution out = hpds::resolveOutput(config_);
  text += ". Dropped frames are counted in /diagnostics. To keep up, lower the cost of a frame: a larger output.spacing (now " +
          format("%.3g m", out.radius) + ")";
  if (config_.normals.enabled)
    text += ", normals.neighborhood_level_offset 0 (now " + std::to_string(config_.normals.neighborhood_level_offset) +
            // Map mode builds those levels only where it keeps them (map.keep_depth); else, as scan mode, it
            // averages the frame's points per finer cell.
            (config_.mode == hpds::Mode::Map &&
                     config_.map.keep_depth >= out.level + config_.normals.neighborhood_level_offset
                 ? ": levels built below the output for the normals)"
                 : ": finer detail the normals average)") +
            " or normals.enabled false";
  if (!(config_.input.max_range > 0.0)) text += ", an input.max_range (now 0: every point)";
  text += config_.mode == hpds::Mode::Scan
              ? "; or process frames in parallel: threads (now " + std::to_string(config_.threads) + ")"
              : "; map mode processes one frame at a time (threads only speed up the normals)";
  return text + ".";
}

}  // namespace hpds_node
