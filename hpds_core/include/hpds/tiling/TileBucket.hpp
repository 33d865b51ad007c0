// TileBucket: the bucketing pass of a tiled map build. Frames are read once, in order; each point is filed under the
// tile its fixed-frame position falls in, so that a tile later loads only its own points.
//
// Contract
// - A point is filtered and posed by poseFramePoints (FramePoints.hpp), the function Pipeline::addFrame uses, and
//   filed under grid.tileOf of that position: the tile's pipeline re-poses the same record with the same pose and
//   gets the same bits, so it inserts exactly the points of its own tile. Skipped points and points with no tile
//   (beyond the exact key range, counted as out_of_range) are counted, never filed.
// - A bucket keeps, per frame with points in the tile, the frame index, its pose, its viewpoint (in the frame's own
//   coordinates, as Frame::viewpoint) and the kept points' input records (bytes as read) in input order.
// - TileBucketer holds what its frames file (a bucketing task's frames); frames are added in increasing frame
//   index and must share one point layout, as map mode requires (std::invalid_argument otherwise).
// - Bucket file (version 2, little-endian): magic "HPDSBKT\0", u32 version, the layout (u32 point_step, u32 field
//   count, per field u32 name length, name, u32 offset, u8 datatype, u32 count), u32 frame count, per frame u32 frame
//   index, f64[12] pose (row-major 3x4), f64[3] viewpoint, u64 point count, the records; then the CRC-32 of all bytes
//   before it. Version 1 (no viewpoint: the origin) is read too.
//   writeTileBucket writes atomically (AtomicFile.hpp). readTileBucket checks size,
//   structure and checksum before returning anything: std::runtime_error "<path>: <problem>" otherwise.
// - Not thread-safe for mutation; the file functions are reentrant.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/points/Frame.hpp"
#include "hpds/tiling/TileGrid.hpp"

namespace hpds {

/// One frame's points in one tile.
struct BucketFrame {
  std::uint32_t frame_index = 0;
  alignas(kPoseMemberAlignment) Eigen::Isometry3d sensor_to_fixed = Eigen::Isometry3d::Identity();  ///< see Frame
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();  ///< the sensor's position in the records' frame (Frame::viewpoint)
  PointBuffer points;  ///< input records, input order
};

class TileBucketer {
 public:
  TileBucketer(const HpdsConfig &config, const TileGrid &grid);

  /// Files the frame's points under their tiles; returns input, skipped_* and out_of_range counts.
  FrameCounters addFrame(const Frame &frame, std::uint32_t frame_index);

  /// Tiles holding points, row-major, with their point counts.
  [[nodiscard]] std::vector<std::pair<TileKey, std::uint64_t>> tiles() const;
  /// The bucket of `key` (empty when it holds no points).
  [[nodiscard]] const std::vector<BucketFrame> &framesOf(const TileKey &key) const;
  /// Layout of every filed record: the first frame with points'; frames without points may have any (they file
  /// nothing). Empty before such a frame (hasLayout() false).
  [[nodiscard]] const PointLayout &layout() const { return layout_; }
  [[nodiscard]] bool hasLayout() const { return have_layout_; }
  /// Bytes of filed records.
  [[nodiscard]] std::size_t memUsage() const { return bytes_; }

 private:
  HpdsConfig config_;
  TileGrid grid_;
  PointLayout layout_;
  bool have_layout_ = false;
  bool have_frame_ = false;
  std::uint32_t last_frame_ = 0;
  std::map<TileKey, std::vector<BucketFrame>> buckets_;
  std::size_t bytes_ = 0;
  // Per-frame scratch.
  std::vector<double> xyz_;
  std::vector<std::uint32_t> candidates_;
};

/// Writes one tile's bucket (see the contract); every frame's points must have `layout`.
void writeTileBucket(const std::string &path, const PointLayout &layout, const std::vector<BucketFrame> &frames);

/// Reads a file written by writeTileBucket.
[[nodiscard]] std::vector<BucketFrame> readTileBucket(const std::string &path);

}  // namespace hpds
