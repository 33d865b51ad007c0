// Binary PLY writer for PointBuffer (no PCL).
//
// Contract
// - Writes `format binary_little_endian 1.0` with one `element vertex N` and one property per field, in layout order,
//   typed char uchar short ushort int uint float double after the field's datatype. A field with count > 1 becomes
//   properties name_0 ... name_{count-1}. Only the fields' bytes are written: padding inside a record is skipped.
// - PCL's packed colour, a 4-byte float/uint field `rgb` or `rgba`, is written as `uchar red green blue` (and `alpha`
//   for rgba), as PCL's own writer does, so that viewers show colours; `rgb`'s fourth byte is not written. (Not when
//   the cloud also has a field named red, green, blue or alpha: then every field is written as it is.)
// - An organised cloud (height > 1) also gets `obj_info num_cols W` / `obj_info num_rows H`, which PCL's reader uses to
//   restore width/height.
// - Read back through readPointCloud the values are identical, with PCL's naming conventions applied by its reader:
//   adjacent uchar red, green, blue(, alpha) fields are packed into one `rgb`/`rgba` field (float32 rgb, uint32
//   rgba: the colour bytes come back, a uint32 rgb or float32 rgba changes type) and nx/ny/nz are renamed
//   normal_x/y/z. Any other uchar colour arrangement (a lone `red`, another order) comes back field by field as
//   written (readPointCloud reads such files itself).
// - Errors: std::runtime_error whose message starts with the path: I/O failure, a field name that cannot be a PLY
//   property name (empty, whitespace) or that collides once count > 1 fields are expanded, a field count above 2^20
//   (refused at once, whatever the count: the time spent is bounded), more than 8192 properties or a header beyond
//   1 MiB (both refused by the readers). A failed write removes the partial file.
// - Thread-safety: reentrant; concurrent calls on different paths are safe.
#pragma once

#include <string>

#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/SamplingRecord.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds {

/// What a file holds, for the header's comment line: a sampling's output (the tool's `sample` and `replay`, the
/// tiles of a map build) carries kPlySamplesComment, third after `ply` and `format`, so that the command-line tool
/// and the map build leave it out of an input folder; points (a frame, anything else) carry no comment.
enum class PlyContent { kPoints, kSamples };
inline constexpr const char *kPlySamplesComment = "comment written by hpds";

void writePly(const std::string &path, const PointBuffer &cloud, PlyContent content = PlyContent::kPoints);
/// The same bytes into `file` (its target names the file in messages), without committing it: a program writing
/// several outputs commits them only once all are written, so that a failure leaves every previous output as it was.
void writePly(AtomicFile &file, const PointBuffer &cloud, PlyContent content = PlyContent::kPoints);
/// A sampling's output (PlyContent::kSamples) whose header also records the sampling it was made with
/// (SamplingRecord.hpp), so that `hpds verify` and `hpds analyze` read the cell and depth from the file.
void writePly(const std::string &path, const PointBuffer &cloud, const SamplingRecord &record);
void writePly(AtomicFile &file, const PointBuffer &cloud, const SamplingRecord &record);

}  // namespace hpds
