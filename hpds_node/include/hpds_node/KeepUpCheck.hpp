// KeepUpCheck: says once, early, that frames take longer to process than they take to arrive, and what to set.
//
// Contract
// - arrived(t) takes the wall-clock time [s] of every received message; processed(seconds, waited) the time a worker
//   spent processing every processed frame (conversion, pipeline, outputs) and before that waiting for its
//   transform, and for a frame dropped for want of a transform only the wait (seconds 0); dropped() every frame
//   dropped because the queue was full. Only the last 64 gaps and times are kept. The verdict weighs processing
//   only: a wait for a lagging transform shrinks as the worker falls behind, so it is no cost of its own.
// - Period: the median gap between arrivals since the input last changed rate. A change is `workers + queue_size +
//   1` gaps in a row all shorter than 2/3 of the median of the gaps before them, or all longer than 3/2 of it (the
//   input sped up or slowed down, also after a pause); only those gaps are then kept. Frames that a stalled
//   connection delivers back to back overflow the queue by then, so the drop they cause is judged against the usual
//   rate. A pause that ends at the old rate is one long gap, which the median ignores.
// - Verdict: with the `judge_after`-th processed frame after the first (the first pays for allocations and is left
//   out), the cost is the median processing time. When cost > workers * period the queue must drop frames:
//   processed() returns the warning. The verdict is taken once.
// - An overload drop is said whatever the verdict (a load spike, a frame larger than the first ones), with the
//   current period and costs, once there are as many costs as a verdict takes (`judge_after`): dropped() then
//   returns the warning at once; a drop before that is said by processed() with the `judge_after`-th cost, so that
//   no share of lost frames is quoted from one or two frames. A transform wait that matters is said at once.
// - Drops while the first frame runs (it pays for the node's allocations: several times the later frames' cost)
//   are the start-up's: warmingUp() is true for them. When every drop was one of those and the frames since keep
//   up, nothing is said (the caller logs those drops as start-up, not as overload).
// - Each returns a non-empty text at most once over both: the warning names the measured period and cost, the share
//   of frames lost and the settings that lower the cost, with their current values; when frames wait for their
//   transforms for more than half the input period (10 ms while no period is known), it says that too (a missing
//   or late transform, ros/tf_timeout). No period before two arrivals at different times.
// - Not thread-safe: the caller serialises the calls.
#pragma once

#include <cstddef>
#include <deque>
#include <string>

#include "hpds/config/Config.hpp"

namespace hpds_node {

class KeepUpCheck {
 public:
  /// `config`: what the frames run with (for the advice); `workers`: frames processed at once; `tf_timeout`: the
  /// longest wait for a transform [s] (ros/tf_timeout, for the advice); `queue_size`: frames waiting for a worker
  /// (ros/queue_size).
  KeepUpCheck(const hpds::HpdsConfig &config, std::size_t workers, std::size_t judge_after = 8,
              double tf_timeout = 0.0, std::size_t queue_size = 1);

  void arrived(double wall_seconds);
  /// The warning when this frame completes a failed verdict (see contract), else "".
  [[nodiscard]] std::string processed(double seconds, double waited = 0.0);
  /// The warning at the first overload drop (see contract), else "".
  [[nodiscard]] std::string dropped();

  /// No frame has been processed (or dropped after its wait for a transform) yet: a drop now is the start-up's
  /// (see contract).
  [[nodiscard]] bool warmingUp() const { return !first_done_; }
  [[nodiscard]] bool judged() const { return judged_; }
  [[nodiscard]] bool warned() const { return warned_; }

 private:
  [[nodiscard]] std::string warning(bool on_drop) const;
  /// The waits for transforms are worth naming: their median is over half the period (over 10 ms before any period).
  [[nodiscard]] bool waitsMatter() const;

  hpds::HpdsConfig config_;
  std::size_t workers_;
  std::size_t judge_after_;
  std::size_t rate_change_gaps_;
  double tf_timeout_;
  std::size_t queue_size_;
  bool judged_ = false, warned_ = false, first_skipped_ = false, first_done_ = false, drop_pending_ = false,
       dropped_after_start_ = false;
  std::size_t costs_seen_ = 0;
  double last_arrival_ = -1.0;
  std::deque<double> gaps_, costs_, waits_;
};

}  // namespace hpds_node
