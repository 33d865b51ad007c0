// FramePoints: a frame's points filtered in their own frame and moved into the fixed frame. Step 2 of
// Pipeline::addFrame, shared with the tiled map build's bucketing pass (tiling/TileBucket.hpp), so that a point is
// placed in the same tile that the tile's pipeline later inserts it into: both compute it with this one function.
//
// Contract
// - Skips, counting each reason: NaN/Inf coordinates (also a finite point that a huge pose sends to Inf), exact
//   (0,0,0) no-returns (input.skip_zero_points), points outside input.min_range/max_range (their distance to
//   frame.viewpoint, in the points' own frame).
// - `xyz` is resized to 3 doubles per input point and receives the fixed-frame position of every kept point (the
//   entries of skipped points are unspecified); `candidates` receives the indices of the kept points, in input order.
// - Deterministic to the bit: one thread, one formula (R p + t in double precision, from the field values).
// - The frame must have numeric x/y/z fields of count 1 (Pipeline::addFrame checks this first); the pose must be
//   finite.
#pragma once

#include <cstdint>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/points/Frame.hpp"

namespace hpds {

struct SkippedPoints {
  std::uint64_t invalid = 0;  ///< NaN/Inf coordinates
  std::uint64_t zero = 0;     ///< exact (0,0,0) no-returns
  std::uint64_t range = 0;    ///< outside input.min_range / input.max_range
};

/// See the contract. Throws std::invalid_argument when the frame lacks x/y/z fields.
void poseFramePoints(const Frame &frame, const InputConfig &input, std::vector<double> &xyz,
                     std::vector<std::uint32_t> &candidates, SkippedPoints &skipped);

}  // namespace hpds
