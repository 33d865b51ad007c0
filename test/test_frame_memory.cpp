// keepFreedFrameMemory: dense frames, one after the other as the node runs them, stop costing page faults.
#include <gtest/gtest.h>

#include <sys/resource.h>

#include <cstdio>

#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/util/FrameMemory.hpp"

namespace {

long minorFaults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

}  // namespace

TEST(FrameMemory, DenseFramesInARowFaultNoMemoryInAgain) {
  if (!hpds::kFreedFrameMemoryCanBeKept)
    GTEST_SKIP() << "this build's malloc is not glibc's (a sanitizer's allocator, or another C library): "
                    "keepFreedFrameMemory cannot take here";
  ASSERT_TRUE(hpds::keepFreedFrameMemory());
  // A dense frame (128 beams x 1800 columns, 230 k rays) again and again, as from a sensor standing still, at the
  // shipped defaults (scan mode, 0.1 m, normals). Without the setting glibc gave part of each frame's scratch back to
  // the kernel and faulted it in again on the next frame: here about 4 200 pages per frame (the VLS-128 frame of
  // ../shared/data: 5 400); with it, about 40.
  hpds::SyntheticLidarConfig lc;
  lc.beams = 128;
  const hpds::SyntheticLidar lidar(lc);
  const hpds::Frame frame = lidar.frame(0).frame;
  hpds::Pipeline pipeline{hpds::HpdsConfig{}};
  auto run = [&] {
    (void)pipeline.addFrame(frame);
    const hpds::PointBuffer out = pipeline.makeCloud(pipeline.outputSamples(), false);
    ASSERT_GT(out.size(), 10000u);
  };
  // The first frames grow the heap to what a frame needs.
  for (int i = 0; i < 3; ++i) run();
  const long before = minorFaults();
  constexpr int kMeasured = 5;
  for (int i = 0; i < kMeasured; ++i) run();
  const long per_frame = (minorFaults() - before) / kMeasured;
  std::printf("minor page faults per frame after the first three: %ld\n", per_frame);
  EXPECT_LT(per_frame, 200) << "freed frame memory went back to the kernel";
}
