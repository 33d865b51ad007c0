// Internal to hpds::pcl: what the PCD reader, the PLY reader and the PCL adapter share. Not installed.
//
// PCL's readers trust their input: a PCD header's POINTS is multiplied into a vector::resize before anything is
// checked, binary_compressed sizes are taken at face value, ASCII values that are not numbers silently become 0 (or a
// whole malformed line is skipped), and PLY element counts are allocated as declared. So every file is first parsed
// here far enough to prove that what PCL will do is bounded by the file's size and that the values are well formed
// (PcdReader.cpp, PlyReader.cpp); only then is it handed to PCL (PclAdapter.cpp), whose result is checked once more
// while copying it into a PointBuffer.
#pragma once

#include <pcl/PCLPointCloud2.h>

#include <Eigen/Core>

#include <charconv>
#include <cstdint>
#include <istream>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hpds/points/PointBuffer.hpp"
#include "io/FileAccess.hpp"

namespace hpds::pcl_detail {

using io_detail::fail;
using io_detail::kMaxFieldCount;
using io_detail::kMaxHeaderBytes;
using io_detail::quote;

// ---------------------------------------------------------------------------------------------------------------------
// Text of a possibly malformed file

/// Lower-case extension with its dot (".pcd"), "" when there is none.
[[nodiscard]] std::string lowerExtension(const std::string &path);
[[nodiscard]] bool isSpace(char c);
/// Reads `in` on to the first line holding more than white space and returns its number counted from where `in`
/// stood (1 = the next line), or nothing at the end of the file: what ascii data holds beyond its header's count.
[[nodiscard]] std::optional<std::uint64_t> nextNonBlankLine(std::istream &in);
/// Tokens separated by runs of spaces and tabs, as boost::split(..., is_any_of("\t "), token_compress_on) gives them
/// for a line that does not start with a separator.
[[nodiscard]] std::vector<std::string_view> splitSpaceTab(std::string_view line);
[[nodiscard]] std::vector<std::string_view> splitWhitespace(std::string_view line);
[[nodiscard]] bool iequals(std::string_view a, std::string_view b);
/// Any decimal number, including nan/inf (PCL writes "nan" for invalid points). Locale-independent.
[[nodiscard]] bool isNumber(std::string_view token);
/// The value of such a token (a leading '+' allowed, as PCL's readers take it; beyond double's range: +-inf), or
/// nothing when it is not a number.
[[nodiscard]] std::optional<double> parseNumber(std::string_view token);

template <typename T>
std::optional<T> parseInteger(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  T value{};
  const auto res = std::from_chars(token.data(), token.data() + token.size(), value);
  if (res.ec != std::errc() || res.ptr != token.data() + token.size()) return std::nullopt;
  return value;
}

// Walks the lines of a byte buffer; a line's end is its '\n' (excluded) or the end of the buffer.
class LineCursor {
 public:
  explicit LineCursor(std::string_view text, std::size_t pos = 0) : text_(text), pos_(pos) {}
  /// Next line, or nullopt at the end. `complete` tells whether it was terminated by '\n'.
  std::optional<std::string_view> next(bool *complete = nullptr) {
    if (pos_ >= text_.size()) return std::nullopt;
    const std::size_t nl = text_.find('\n', pos_);
    const std::size_t end = nl == std::string_view::npos ? text_.size() : nl;
    std::string_view line = text_.substr(pos_, end - pos_);
    if (complete) *complete = nl != std::string_view::npos;
    pos_ = nl == std::string_view::npos ? text_.size() : nl + 1;
    ++line_no_;
    return line;
  }
  std::size_t pos() const { return pos_; }
  std::size_t lineNo() const { return line_no_; }

 private:
  std::string_view text_;
  std::size_t pos_;
  std::size_t line_no_ = 0;
};

// ---------------------------------------------------------------------------------------------------------------------
// Files

struct FileBytes {
  std::uint64_t size = 0;
  std::string prefix;  ///< the first min(size, kMaxHeaderBytes) bytes
};

/// The file's size and its first kMaxHeaderBytes; refuses what is not a non-empty regular file.
[[nodiscard]] FileBytes openForReading(const std::string &path);

// ---------------------------------------------------------------------------------------------------------------------
// Readers and the PCL side

/// PCD through PCL after PcdReader.cpp's checks.
[[nodiscard]] PointBuffer readPcd(const std::string &path, Eigen::Vector3d *viewpoint = nullptr);
/// PLY through PCL (or hpds's own vertex reader for colour arrangements PCL cannot pack) after PlyReader.cpp's checks.
[[nodiscard]] PointBuffer readPly(const std::string &path);

enum class PclFormat { Pcd, Ply };
/// Runs PCL's reader of `format` on a file the checks have passed, quietly, with PCL's failures (exceptions,
/// negative results) turned into our errors, and copies the result into a PointBuffer (checkCloudLayout applied).
[[nodiscard]] PointBuffer readWithPcl(const std::string &path, PclFormat format);
/// What every cloud a reader returns must satisfy: a valid layout with single-valued x, y and z.
void checkCloudLayout(const std::string &path, const PointLayout &layout);

}  // namespace hpds::pcl_detail
