// OrderedWorkerPool, without a master: results leave in arrival order for any number of workers, indices are
// consecutive over the frames that take one, a throwing handler costs one frame (reported) and not the worker,
// a full queue drops the oldest frame and says so, tasks run between frames and before waiting frames.
#include <gtest/gtest.h>

#include <boost/make_shared.hpp>

#include <atomic>
#include <chrono>
#include <random>
#include <stdexcept>
#include <thread>

#include "hpds_node/OrderedWorkerPool.hpp"

namespace {

using hpds_node::OrderedWorkerPool;
using Frame = OrderedWorkerPool::Frame;

Frame frame(std::uint32_t seq) {
  auto m = boost::make_shared<sensor_msgs::PointCloud2>();
  m->header.seq = seq;
  return m;
}

bool waitUntil(const std::function<bool()> &pred, double seconds = 30.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!pred()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

TEST(OrderedWorkerPool, ResultsLeaveInArrivalOrderWithConsecutiveIndices) {
  for (std::size_t workers : {1u, 2u, 4u}) {
    SCOPED_TRACE(workers);
    std::mutex mutex;
    std::vector<std::uint32_t> published, indexed_seqs;
    std::vector<std::uint32_t> indices;
    std::atomic<int> handled{0};
    std::mt19937 rng(1);
    std::vector<int> delay_us(200);
    for (int &d : delay_us) d = int(rng() % 2000);
    {
      OrderedWorkerPool pool(
          workers, 1000,
          [&](const Frame &f, std::size_t, OrderedWorkerPool::Turns &turns) {
            const std::uint32_t seq = f->header.seq;
            std::this_thread::sleep_for(std::chrono::microseconds(delay_us[seq]));
            if (seq % 3 != 2) {  // every third frame is "dropped" before it takes an index
              const std::uint32_t index = turns.takeIndex();
              std::this_thread::sleep_for(std::chrono::microseconds(delay_us[199 - seq]));
              turns.waitToPublish();
              std::lock_guard<std::mutex> lock(mutex);
              published.push_back(seq);
              indices.push_back(index);
            }
            ++handled;
          },
          [](std::size_t, const std::string &what) { ADD_FAILURE() << what; });
      for (std::uint32_t i = 0; i < 200; ++i) EXPECT_FALSE(pool.push(frame(i)));
      ASSERT_TRUE(waitUntil([&] { return handled == 200; }));
    }
    std::vector<std::uint32_t> expected;
    for (std::uint32_t i = 0; i < 200; ++i)
      if (i % 3 != 2) expected.push_back(i);
    EXPECT_EQ(published, expected);
    for (std::size_t i = 0; i < indices.size(); ++i) EXPECT_EQ(indices[i], i);
  }
}

TEST(OrderedWorkerPool, AThrowingHandlerCostsOneFrameReportedNotTheWorker) {
  for (std::size_t workers : {1u, 3u}) {
    SCOPED_TRACE(workers);
    std::mutex mutex;
    std::vector<std::uint32_t> published;
    std::vector<std::string> errors;
    std::atomic<int> done{0};
    OrderedWorkerPool pool(
        workers, 1000,
        [&](const Frame &f, std::size_t, OrderedWorkerPool::Turns &turns) {
          const std::uint32_t seq = f->header.seq;
          if (seq == 3) throw std::runtime_error("Duration is out of dual 32-bit range");
          if (seq == 5) {
            (void)turns.takeIndex();  // after its index: the later frames must still get theirs and publish
            throw std::bad_alloc();
          }
          if (seq == 7) throw 42;
          turns.waitToPublish();
          std::lock_guard<std::mutex> lock(mutex);
          published.push_back(seq);
          ++done;
        },
        [&](std::size_t worker, const std::string &what) {
          EXPECT_LT(worker, workers);
          std::lock_guard<std::mutex> lock(mutex);
          errors.push_back(what);
          ++done;
        });
    for (std::uint32_t i = 0; i < 10; ++i) pool.push(frame(i));
    ASSERT_TRUE(waitUntil([&] { return done == 10; }));
    pool.stop();
    EXPECT_EQ(published, (std::vector<std::uint32_t>{0, 1, 2, 4, 6, 8, 9}));
    ASSERT_EQ(errors.size(), 3u);
    std::sort(errors.begin(), errors.end());
    EXPECT_EQ(errors[0], "Duration is out of dual 32-bit range");
    EXPECT_EQ(errors[1], "an exception that is not a std::exception");
    EXPECT_EQ(errors[2], "std::bad_alloc");
  }
}

TEST(OrderedWorkerPool, AFullQueueDropsTheOldestAndSaysSo) {
  std::atomic<bool> release{false};
  std::atomic<int> started{0};
  std::mutex mutex;
  std::vector<std::uint32_t> handled;
  OrderedWorkerPool pool(
      1, 2,
      [&](const Frame &f, std::size_t, OrderedWorkerPool::Turns &) {
        ++started;
        while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
        std::lock_guard<std::mutex> lock(mutex);
        handled.push_back(f->header.seq);
      },
      [](std::size_t, const std::string &what) { ADD_FAILURE() << what; });
  EXPECT_FALSE(pool.push(frame(0)));
  ASSERT_TRUE(waitUntil([&] { return started == 1; }));  // frame 0 is being handled, the queue is empty
  EXPECT_FALSE(pool.push(frame(1)));
  EXPECT_FALSE(pool.push(frame(2)));
  EXPECT_TRUE(pool.push(frame(3)));  // drops 1
  EXPECT_TRUE(pool.push(frame(4)));  // drops 2
  release = true;
  ASSERT_TRUE(waitUntil([&] {
    std::lock_guard<std::mutex> lock(mutex);
    return handled.size() == 3;
  }));
  EXPECT_EQ(handled, (std::vector<std::uint32_t>{0, 3, 4}));
}

TEST(OrderedWorkerPool, TasksRunBetweenFramesBeforeWaitingOnesAndStopAnswersEveryone) {
  std::atomic<bool> release{false};
  std::atomic<int> started{0};
  std::mutex mutex;
  std::vector<std::string> events;
  auto log = [&](const std::string &e) {
    std::lock_guard<std::mutex> lock(mutex);
    events.push_back(e);
  };
  OrderedWorkerPool pool(
      1, 10,
      [&](const Frame &f, std::size_t, OrderedWorkerPool::Turns &) {
        ++started;
        while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
        log("frame " + std::to_string(f->header.seq));
      },
      [](std::size_t, const std::string &what) { ADD_FAILURE() << what; });
  pool.push(frame(0));
  ASSERT_TRUE(waitUntil([&] { return started == 1; }));
  pool.push(frame(1));
  pool.push(frame(2));
  std::thread caller([&] { EXPECT_TRUE(pool.runBetweenFrames([&](std::size_t) { log("task"); })); });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  release = true;
  caller.join();
  ASSERT_TRUE(waitUntil([&] {
    std::lock_guard<std::mutex> lock(mutex);
    return events.size() == 4;
  }));
  EXPECT_EQ(events, (std::vector<std::string>{"frame 0", "task", "frame 1", "frame 2"}));
  // A task's exception reaches its caller.
  EXPECT_THROW(pool.runBetweenFrames([](std::size_t) { throw std::runtime_error("save failed"); }),
               std::runtime_error);

  // Stop: the waiting frames are discarded and counted; a task asked for later is refused.
  release = false;
  started = 0;
  pool.push(frame(3));
  ASSERT_TRUE(waitUntil([&] { return started == 1; }));
  pool.push(frame(4));
  pool.push(frame(5));
  std::thread stopper([&] { EXPECT_EQ(pool.stop(), 2u); });
  ASSERT_TRUE(waitUntil([&] { return pool.stopping(); }));
  EXPECT_FALSE(pool.runBetweenFrames([&](std::size_t) { log("late task"); }));
  EXPECT_FALSE(pool.push(frame(6)));
  release = true;
  stopper.join();
  EXPECT_EQ(events.back(), "frame 3");
}

}  // namespace
