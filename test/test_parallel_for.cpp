// parallelFor: every index exactly once whatever the thread and chunk counts, errors surface, and one range per
// thread when a caller asks for it (forEachScanFrame keeps a pipeline per range).
#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hpds/util/ParallelFor.hpp"

namespace {

struct Ranges {
  std::mutex mutex;
  std::vector<std::pair<std::size_t, std::size_t>> seen;
  void add(std::size_t b, std::size_t e) {
    std::lock_guard<std::mutex> lock(mutex);
    seen.emplace_back(b, e);
  }
};

TEST(ParallelFor, EveryIndexExactlyOnce) {
  for (std::size_t n : {0u, 1u, 7u, 255u, 256u, 1000u, 4097u})
    for (int threads : {1, 2, 3, 8})
      for (std::size_t grain : {1u, 16u, 256u})
        for (std::size_t chunks : {1u, 4u, 64u}) {
          std::vector<std::atomic<int>> hits(n);
          hpds::parallelFor(
              n, threads,
              [&](std::size_t b, std::size_t e) {
                ASSERT_LE(b, e);
                ASSERT_LE(e, n);
                for (std::size_t i = b; i < e; ++i) hits[i].fetch_add(1);
              },
              grain, chunks);
          for (std::size_t i = 0; i < n; ++i)
            ASSERT_EQ(hits[i].load(), 1) << "n " << n << " threads " << threads << " grain " << grain << " chunks "
                                         << chunks << " index " << i;
        }
}

TEST(ParallelFor, OneRangePerThreadWhenAsked) {
  Ranges r;
  hpds::parallelFor(1000, 4, [&](std::size_t b, std::size_t e) { r.add(b, e); }, 1, 1);
  EXPECT_EQ(r.seen.size(), 4u);
  std::size_t covered = 0;
  for (const auto &[b, e] : r.seen) covered += e - b;
  EXPECT_EQ(covered, 1000u);
}

TEST(ParallelFor, SeveralChunksPerThreadBalanceTheWork) {
  Ranges r;
  hpds::parallelFor(1000, 2, [&](std::size_t b, std::size_t e) { r.add(b, e); }, 1, 8);
  EXPECT_EQ(r.seen.size(), 16u);
}

TEST(ParallelFor, BelowTheGrainRunsOnTheCallingThreadAsOneRange) {
  Ranges r;
  hpds::parallelFor(100, 8, [&](std::size_t b, std::size_t e) { r.add(b, e); }, 256, 4);
  ASSERT_EQ(r.seen.size(), 1u);
  EXPECT_EQ(r.seen[0], std::make_pair(std::size_t{0}, std::size_t{100}));
}

TEST(ParallelFor, AnExceptionInAWorkerIsRethrown) {
  std::atomic<int> calls{0};
  EXPECT_THROW(hpds::parallelFor(
                   10000, 2,
                   [&](std::size_t b, std::size_t) {
                     ++calls;
                     if (b > 0) throw std::runtime_error("range failed");
                   },
                   1, 16),
               std::runtime_error);
  // The others stop taking ranges once one failed: far fewer calls than chunks.
  EXPECT_LT(calls.load(), 32);
}

}  // namespace
