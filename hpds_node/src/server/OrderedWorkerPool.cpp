#include "hpds_node/OrderedWorkerPool.hpp"

#include <algorithm>
#include <exception>

namespace hpds_node {

// Every frame a worker takes passes both turns exactly once, whatever happens to it, so a later frame never waits
// forever. Its predecessors are all held by running workers, which finish their frames before stopping.
OrderedWorkerPool::Turns::~Turns() {
  if (!indexed_) indexTurn(/*take=*/false);
  if (!publishing_) waitToPublish();
  {
    std::lock_guard<std::mutex> lock(pool_.turn_mutex_);
    ++pool_.publish_turn_;
  }
  pool_.turn_cv_.notify_all();
}

void OrderedWorkerPool::Turns::waitToPublish() {
  if (!indexed_) indexTurn(/*take=*/false);
  std::unique_lock<std::mutex> lock(pool_.turn_mutex_);
  pool_.turn_cv_.wait(lock, [this] { return pool_.publish_turn_ == ticket_; });
  publishing_ = true;
}

std::uint32_t OrderedWorkerPool::Turns::indexTurn(bool take) {
  std::uint32_t index = 0;
  {
    std::unique_lock<std::mutex> lock(pool_.turn_mutex_);
    pool_.turn_cv_.wait(lock, [this] { return pool_.index_turn_ == ticket_; });
    if (take) index = pool_.next_index_++;
    ++pool_.index_turn_;
  }
  indexed_ = true;
  pool_.turn_cv_.notify_all();
  return index;
}

OrderedWorkerPool::OrderedWorkerPool(std::size_t workers, std::size_t capacity, Handler handler,
                                     ErrorHandler on_error)
    : capacity_(std::max<std::size_t>(capacity, 1)), handler_(std::move(handler)), on_error_(std::move(on_error)) {
  for (std::size_t w = 0; w < std::max<std::size_t>(workers, 1); ++w)
    workers_.emplace_back([this, w] { workerLoop(w); });
}

OrderedWorkerPool::~OrderedWorkerPool() { stop(); }

bool OrderedWorkerPool::push(Frame frame) {
  bool dropped = false;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    if (stopping_) return false;
    if (queue_.size() >= capacity_) {
      queue_.pop_front();
      dropped = true;
    }
    queue_.push_back(std::move(frame));
  }
  queue_cv_.notify_one();
  return dropped;
}

bool OrderedWorkerPool::runBetweenFrames(const std::function<void(std::size_t)> &task) {
  auto queued = std::make_shared<Task>();
  queued->run = task;
  std::future<void> done = queued->done.get_future();
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    if (stopping_) return false;
    tasks_.push_back(queued);
  }
  queue_cv_.notify_all();
  done.get();  // rethrows what the task threw
  return true;
}

std::size_t OrderedWorkerPool::stop() {
  std::size_t discarded = 0;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    stopping_ = true;
    discarded = queue_.size();
    queue_.clear();
  }
  queue_cv_.notify_all();
  for (std::thread &t : workers_)
    if (t.joinable()) t.join();
  return discarded;
}

bool OrderedWorkerPool::stopping() const {
  std::lock_guard<std::mutex> lock(queue_mutex_);
  return stopping_;
}

void OrderedWorkerPool::workerLoop(std::size_t worker) {
  for (;;) {
    Frame frame;
    std::shared_ptr<Task> task;
    std::uint64_t ticket = 0;
    {
      std::unique_lock<std::mutex> lock(queue_mutex_);
      queue_cv_.wait(lock, [this] { return stopping_ || !queue_.empty() || !tasks_.empty(); });
      // Tasks first, and all of them before stopping: each caller is waiting for its answer.
      if (!tasks_.empty()) {
        task = tasks_.front();
        tasks_.pop_front();
      } else if (stopping_) {
        return;
      } else {
        frame = queue_.front();
        queue_.pop_front();
        ticket = next_ticket_++;
      }
    }
    if (task) {
      try {
        task->run(worker);
        task->done.set_value();
      } catch (...) {
        task->done.set_exception(std::current_exception());
      }
      continue;
    }
    Turns turns(*this, ticket);
    try {
      handler_(frame, worker, turns);
    } catch (const std::exception &e) {
      on_error_(worker, e.what());
    } catch (...) {
      on_error_(worker, "an exception that is not a std::exception");
    }
  }
}

}  // namespace hpds_node
