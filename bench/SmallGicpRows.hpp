// perf_benchmark's rows against small_gicp (voxel-grid downsampling + k-d tree + k-NN PCA normals, the fastest widely
// used lidar preprocessing code): downsampling alone and the node's frame path with valid normals, on 1 thread and on
// 2 threads each. Compiled only when CMake found the peer's headers (../shared/peers/small_gicp, benchmark only,
// never a dependency of hpds); otherwise smallGicpAvailable() is false and the rows are skipped with a message.
#pragma once

#include <string>
#include <vector>

#include "FramePath.hpp"
#include "hpds/points/Frame.hpp"

namespace bench {

[[nodiscard]] bool smallGicpAvailable();

/// The rows for one frame (the same bytes on both sides), and the same over a stream of frames (summed per round).
void benchSmallGicp(const LevelSetting &setting, int repeats, const std::string &name,
                    const std::vector<hpds::Frame> &frames);

}  // namespace bench
