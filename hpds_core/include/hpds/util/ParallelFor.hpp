// Static-chunk parallel loop. Each index is handled by exactly one thread and results are written by index, so
// output never depends on the thread count.
#pragma once

#include <algorithm>
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

/// Calls fn(begin, end) on disjoint ranges covering [0, n); the first exception thrown is rethrown. A thread is
/// started per `grain` items at most (fine-grained loops are not worth a thread below a few hundred items).
template <typename Fn>
void parallelFor(std::size_t n, int threads, Fn &&fn, std::size_t grain = 256) {
  const std::size_t t = std::min<std::size_t>(static_cast<std::size_t>(resolveThreads(threads)),
                                              std::max<std::size_t>(n / std::max<std::size_t>(grain, 1), 1));
  if (t <= 1) {
    fn(std::size_t{0}, n);
    return;
  }
  std::vector<std::thread> pool;
  std::vector<std::exception_ptr> errors(t);
  const std::size_t chunk = (n + t - 1) / t;
  for (std::size_t i = 0; i < t; ++i) {
    const std::size_t b = i * chunk, e = std::min(n, b + chunk);
    pool.emplace_back([&, i, b, e] {
      try {
        if (b < e) fn(b, e);
      } catch (...) {
        errors[i] = std::current_exception();
      }
    });
  }
  for (auto &th : pool) th.join();
  for (auto &err : errors)
    if (err) std::rethrow_exception(err);
}

}  // namespace hpds
