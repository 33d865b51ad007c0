// Parallel loop over disjoint index ranges. Each index is handled by exactly one thread and results are written by
// index, so output never depends on the thread count or on which thread took which range.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace hpds {

/// 0 -> hardware concurrency (at least 1).
[[nodiscard]] inline int resolveThreads(int threads) {
  if (threads > 0) return threads;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw ? static_cast<int>(hw) : 1;
}

/// Calls fn(begin, end) on disjoint ranges covering [0, n), possibly several per thread; the first exception thrown
/// is rethrown. A thread is used per `grain` items at most (fine-grained loops are not worth a thread below a few
/// hundred items). The range is cut into `chunks_per_thread` chunks per thread, taken in turn by whichever thread is
/// free: spatially sorted work (dense cells near the sensor, sparse far ones) would otherwise leave one thread
/// waiting for the other. The calling thread takes chunks too, so t threads cost t - 1 thread starts. A caller
/// whose fn sets up per-call state worth keeping (a pipeline per range of frames) passes 1: one range per thread.
template <typename Fn>
void parallelFor(std::size_t n, int threads, Fn &&fn, std::size_t grain = 256, std::size_t chunks_per_thread = 4) {
  const std::size_t t = std::min<std::size_t>(static_cast<std::size_t>(resolveThreads(threads)),
                                              std::max<std::size_t>(n / std::max<std::size_t>(grain, 1), 1));
  if (t <= 1) {
    fn(std::size_t{0}, n);
    return;
  }
  const std::size_t chunks = std::min(n, t * std::max<std::size_t>(chunks_per_thread, 1));
  const std::size_t chunk = (n + chunks - 1) / chunks;
  std::atomic<std::size_t> next{0};
  std::vector<std::exception_ptr> errors(t);
  auto work = [&](std::size_t worker) {
    try {
      for (;;) {
        const std::size_t b = next.fetch_add(chunk, std::memory_order_relaxed);
        if (b >= n) break;
        fn(b, std::min(n, b + chunk));
      }
    } catch (...) {
      errors[worker] = std::current_exception();
      next.store(n, std::memory_order_relaxed);  // the others stop after their current chunk
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(t - 1);
  for (std::size_t i = 1; i < t; ++i) pool.emplace_back(work, i);
  work(0);
  for (auto &th : pool) th.join();
  for (auto &err : errors)
    if (err) std::rethrow_exception(err);
}

}  // namespace hpds
