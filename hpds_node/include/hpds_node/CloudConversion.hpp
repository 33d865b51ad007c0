// sensor_msgs/PointCloud2 <-> hpds::PointBuffer, with the validation every incoming message goes through.
//
// Contract
// - fromRosCloud checks the message before touching its data and converts only a consistent one:
//   little-endian, every field of a PointCloud2 datatype (1..8) with count >= 1 and inside point_step, no name
//   twice, x/y/z present as scalars (any numeric datatype), row_step >= width * point_step and
//   data.size() == row_step * height, with every product computed without overflow. Anything else returns the
//   reason and leaves `out` untouched: such a message is dropped, never partially used.
// - Accepted clouds keep every field byte for byte (same names, offsets, datatypes, counts, point_step) and their
//   width/height; NaN points stay (the pipeline skips and counts them). Row padding (row_step larger than
//   width * point_step) is removed, since PointBuffer stores records densely.
// - Fields named "_" are PCL's padding placeholders: they are left out of the layout (their bytes stay in the
//   records), as the PCD reader of hpds_core does, so several of them do not count as a repeated name.
// - A zero-size cloud (width * height == 0) with a valid layout converts to an empty buffer; so does a message with
//   no fields and no data (a default-constructed PointCloud2), as an empty x y z float32 buffer.
// - toRosCloud writes the buffer's layout and bytes unchanged; is_dense is true exactly when every floating-point
//   field of every point is finite (PCL's meaning: an invalid normal, NaN, makes the cloud not dense).
// - Reentrant; no ROS runtime (master, node handle) needed.
#pragma once

#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>

#include <string>

#include "hpds/points/PointBuffer.hpp"

namespace hpds_node {

/// Why a PointCloud2 was refused. Values index the per-reason drop counters.
enum class CloudError {
  None = 0,
  BigEndian,          ///< is_bigendian true
  BadDatatype,        ///< a field's datatype outside 1..8
  BadCount,           ///< a field with count 0 or above hpds::kMaxFieldCount
  FieldOutsidePoint,  ///< a field ending beyond point_step
  DuplicateField,     ///< a field name appearing twice
  MissingXyz,         ///< no x, y or z field
  BadXyz,             ///< x, y or z with count != 1
  BadRowStep,         ///< row_step < width * point_step (or the product overflows)
  DataSize,           ///< data.size() != row_step * height (truncated or trailing bytes)
  OverlappingXyz,     ///< two of x, y and z sharing bytes (hpds::xyzOverlap)
};
inline constexpr int kCloudErrorCount = 11;

/// Short snake_case name ("big_endian", "data_size", ...) for logs and diagnostics keys.
[[nodiscard]] const char *toString(CloudError error);

/// Validates `msg` and, when valid, replaces `out` with its points. `why` (optional) receives a sentence naming
/// the offending field or sizes.
[[nodiscard]] CloudError fromRosCloud(const sensor_msgs::PointCloud2 &msg, hpds::PointBuffer &out,
                                      std::string *why = nullptr);

/// Same checks as fromRosCloud without converting.
[[nodiscard]] CloudError validateCloud(const sensor_msgs::PointCloud2 &msg, std::string *why = nullptr);

/// Fills `out` (header included) from `cloud`.
void toRosCloud(const hpds::PointBuffer &cloud, const std_msgs::Header &header, sensor_msgs::PointCloud2 &out);

}  // namespace hpds_node
