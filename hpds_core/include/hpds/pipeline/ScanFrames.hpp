// Frame-parallel scan mode: independent frames of one stream on several threads, with the single-threaded output.
//
// Contract
// - In scan mode every frame starts on an empty hierarchy, so frames are independent. forEachScanFrame calls
//   fn(Pipeline &, std::size_t i) once for every i in [0, n), each worker driving its own scan-mode pipeline
//   (config.threads forced to 1 inside) whose next frame index is set to i first: what fn computes for frame i
//   depends on i only, never on `threads` or on which worker ran it.
// - threads: 0 = all cores. Workers take contiguous ranges of frames. The first exception thrown by fn is
//   rethrown after all workers stop.
// - fn runs concurrently on different i: it must only write state owned by index i.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "hpds/util/ParallelFor.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds {

template <typename Fn>
void forEachScanFrame(const HpdsConfig &config, std::size_t n, int threads, Fn &&fn) {
  if (config.mode != Mode::Scan) throw std::invalid_argument("forEachScanFrame: needs scan mode");
  HpdsConfig inner = config;
  inner.threads = 1;
  parallelFor(
      n, threads,
      [&](std::size_t b, std::size_t e) {
        Pipeline p(inner);
        for (std::size_t i = b; i < e; ++i) {
          p.setNextFrameIndex(static_cast<std::uint32_t>(i));
          fn(p, i);
        }
      },
      /*grain=*/1, /*chunks_per_thread=*/1);
}

}  // namespace hpds
