// OrderedWorkerPool: the node's frame queue and the workers that empty it, in arrival order whatever their number.
//
// Contract
// - push(): queues a frame. When `capacity` frames already wait, the oldest is dropped to make room (the newest frame
//   wins) and push() returns true so that the caller counts it; nothing is dropped silently.
// - Each worker takes the oldest waiting frame and calls handler(frame, worker, turns). Turns order the frames by
//   arrival: takeIndex() hands out consecutive indices (0, 1, 2 ... over the frames that take one) and
//   waitToPublish() returns once every earlier frame has published or been dropped, so results leave in arrival
//   order. A frame that takes neither turn (dropped early) passes both when its handler returns.
// - A handler that throws does not stop its worker: on_error(worker, what) is called on that worker's thread (the
//   caller counts and logs the lost frame) and the worker takes the next frame.
// - runBetweenFrames(task): runs task(worker) on a worker between two frames, before any waiting frame, and returns
//   once it has run (true), or at once with false when the pool is stopping. With one worker (map mode) no frame is
//   being handled while the task runs.
// - stop() (also by the destructor): no frame is taken after it, waiting frames are discarded (their number is
//   returned, for the caller to say so), tasks already queued still run (their callers are waiting), then the
//   workers are joined.
// - Thread-safety: push, runBetweenFrames, stop and stopping may be called from any thread.
#pragma once

#include <sensor_msgs/PointCloud2.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace hpds_node {

class OrderedWorkerPool {
 public:
  using Frame = sensor_msgs::PointCloud2::ConstPtr;

  /// A frame's place in the stream: the index and publish turns it must take (or pass) in arrival order.
  class Turns {
   public:
    Turns(OrderedWorkerPool &pool, std::uint64_t ticket) : pool_(pool), ticket_(ticket) {}
    Turns(const Turns &) = delete;
    Turns &operator=(const Turns &) = delete;
    ~Turns();
    /// The frame's index among the frames that take one.
    std::uint32_t takeIndex() { return indexTurn(/*take=*/true); }
    /// Returns once every earlier frame has been published or dropped.
    void waitToPublish();

   private:
    std::uint32_t indexTurn(bool take);
    OrderedWorkerPool &pool_;
    std::uint64_t ticket_;
    bool indexed_ = false, publishing_ = false;
  };

  using Handler = std::function<void(const Frame &frame, std::size_t worker, Turns &turns)>;
  using ErrorHandler = std::function<void(std::size_t worker, const std::string &what)>;

  /// Starts `workers` threads (at least one); `capacity` >= 1 frames may wait.
  OrderedWorkerPool(std::size_t workers, std::size_t capacity, Handler handler, ErrorHandler on_error);
  ~OrderedWorkerPool();
  OrderedWorkerPool(const OrderedWorkerPool &) = delete;
  OrderedWorkerPool &operator=(const OrderedWorkerPool &) = delete;

  /// Queues `frame`; true when the oldest waiting frame was dropped for it.
  bool push(Frame frame);
  /// See contract; blocks until the task has run.
  bool runBetweenFrames(const std::function<void(std::size_t worker)> &task);
  /// Returns the number of waiting frames discarded (0 after the first call).
  std::size_t stop();
  [[nodiscard]] bool stopping() const;
  [[nodiscard]] std::size_t workerCount() const { return workers_.size(); }

 private:
  struct Task {
    std::function<void(std::size_t)> run;
    std::promise<void> done;
  };
  void workerLoop(std::size_t worker);

  const std::size_t capacity_;
  const Handler handler_;
  const ErrorHandler on_error_;

  mutable std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<Frame> queue_;
  std::deque<std::shared_ptr<Task>> tasks_;  // run before queue_; every one is run
  bool stopping_ = false;
  std::uint64_t next_ticket_ = 0;  // arrival order of the frames taken by the workers

  // Turns, in ticket order: a frame's index is handed out, and its results published, only after every earlier
  // frame's (a dropped frame passes both turns without using them).
  std::mutex turn_mutex_;
  std::condition_variable turn_cv_;
  std::uint64_t index_turn_ = 0, publish_turn_ = 0;
  std::uint32_t next_index_ = 0;

  std::vector<std::thread> workers_;  // last: started once everything above exists
};

}  // namespace hpds_node
