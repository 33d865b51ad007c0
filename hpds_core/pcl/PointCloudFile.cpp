// PCD/PLY reading through PCL, guarded by our own header/body validation.
//
// PCL's readers trust their input: a PCD header's POINTS is multiplied into a vector::resize before anything is
// checked, binary_compressed sizes are taken at face value, ASCII values that are not numbers silently become 0 (or a
// whole malformed line is skipped), and PLY element counts are allocated as declared. So every file is first parsed
// here far enough to prove that what PCL will do is bounded by the file's size and that the values are well formed;
// only then is it handed to PCL, whose result is checked once more while copying it into a PointBuffer.

#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/pcl/PclCloud.hpp"

#include "io/FileAccess.hpp"

#include <pcl/PCLPointCloud2.h>
#include <pcl/console/print.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <locale.h>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;

using io_detail::fail;
// Headers are small (a few hundred bytes); a file with no end of header in kMaxHeaderBytes is not a point cloud.
using io_detail::kMaxFieldCount;
using io_detail::kMaxHeaderBytes;

// Sanity limits far above any real sensor record, low enough that products below cannot overflow 64 bits.
constexpr std::uint64_t kMaxFields = 1 << 16;
constexpr std::uint64_t kMaxPointStep = 1 << 24;
// LZF emits at most 264 bytes per 3-byte back-reference; a claimed expansion beyond this factor is corruption.
constexpr std::uint64_t kMaxLzfExpansion = 128;

std::string lowerExtension(const std::string &path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

// Quotes text taken from a possibly binary file so that messages stay printable and short.
std::string quote(std::string_view text) {
  constexpr std::size_t kMax = 40;
  std::string out = "'";
  for (std::size_t i = 0; i < text.size() && i < kMax; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (text.size() > kMax) out += "...";
  return out + "'";
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

// Tokens separated by runs of spaces and tabs, as boost::split(..., is_any_of("\t "), token_compress_on) gives them
// for a line that does not start with a separator.
std::vector<std::string_view> splitSpaceTab(std::string_view line) {
  std::vector<std::string_view> tokens;
  std::size_t i = 0;
  while (i < line.size()) {
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    tokens.push_back(line.substr(start, i - start));
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
  }
  return tokens;
}

std::vector<std::string_view> splitWhitespace(std::string_view line) {
  std::vector<std::string_view> tokens;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isSpace(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !isSpace(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

template <typename T>
std::optional<T> parseInteger(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  T value{};
  const auto res = std::from_chars(token.data(), token.data() + token.size(), value);
  if (res.ec != std::errc() || res.ptr != token.data() + token.size()) return std::nullopt;
  return value;
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

// Any decimal number, including nan/inf (PCL writes "nan" for invalid points). Locale-independent.
bool isNumber(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  double value = 0.0;
  const auto res = std::from_chars(token.data(), token.data() + token.size(), value);
  // Out-of-range values still are numbers (they saturate); only malformed text is rejected.
  return (res.ec == std::errc() || res.ec == std::errc::result_out_of_range) && res.ptr == token.data() + token.size();
}

// ---------------------------------------------------------------------------------------------------------------------
// Files

struct FileBytes {
  std::uint64_t size = 0;
  std::string prefix;  ///< the first min(size, kMaxHeaderBytes) bytes
};

FileBytes openForReading(const std::string &path) {
  // Also keeps FIFOs and devices out: reading them could block forever.
  io_detail::requireRegularFile(path);
  std::error_code ec;
  FileBytes file;
  file.size = fs::file_size(path, ec);
  if (ec) fail(path, "cannot determine file size: " + ec.message());
  if (file.size == 0) fail(path, "empty file (0 bytes)");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open: ") + std::strerror(errno));
  file.prefix.resize(static_cast<std::size_t>(std::min<std::uint64_t>(file.size, kMaxHeaderBytes)));
  in.read(file.prefix.data(), static_cast<std::streamsize>(file.prefix.size()));
  file.prefix.resize(static_cast<std::size_t>(in.gcount()));
  if (file.prefix.empty()) fail(path, "cannot read: " + std::string(std::strerror(errno)));
  return file;
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
// PCD validation

enum class PcdData { Ascii, Binary, BinaryCompressed };

struct PcdHeader {
  std::vector<std::string> names;
  std::vector<std::uint32_t> sizes;
  std::vector<FieldType> types;
  std::vector<std::uint32_t> counts;
  std::uint64_t width = 0, height = 0, points = 0;
  std::uint64_t point_step = 0;
  PcdData data = PcdData::Ascii;
  std::uint64_t data_offset = 0;  ///< byte offset of the data section in the file
};

std::optional<FieldType> pcdFieldType(std::uint32_t size, char type) {
  switch (type) {
    case 'I':
      return size == 1   ? FieldType::Int8
             : size == 2 ? FieldType::Int16
             : size == 4 ? FieldType::Int32
                         : std::optional<FieldType>{};
    case 'U':
      return size == 1   ? FieldType::UInt8
             : size == 2 ? FieldType::UInt16
             : size == 4 ? FieldType::UInt32
                         : std::optional<FieldType>{};
    case 'F':
      return size == 4 ? FieldType::Float32 : size == 8 ? FieldType::Float64 : std::optional<FieldType>{};
    default:
      return std::nullopt;
  }
}

PcdHeader parsePcdHeader(const std::string &path, const FileBytes &file) {
  PcdHeader h;
  LineCursor lines(file.prefix);
  bool have_fields = false, have_size = false, have_type = false, have_points = false, have_data = false;
  bool width_read = false, height_read = false;
  bool seen_keyword = false;

  auto lineError = [&](const std::string &what) {
    fail(path, "bad PCD header, line " + std::to_string(lines.lineNo()) + ": " + what);
  };
  auto notPcd = [&](std::string_view found) {
    fail(path, "not a PCD file (line " + std::to_string(lines.lineNo()) + " starts with " + quote(found) + ")");
  };
  auto expectValues = [&](const std::vector<std::string_view> &tok, const char *key) {
    if (tok.size() - 1 != h.names.size())
      lineError(std::string(key) + " has " + std::to_string(tok.size() - 1) + " values for " +
                std::to_string(h.names.size()) + " FIELDS");
  };
  auto singleValue = [&](const std::vector<std::string_view> &tok, const char *key) -> std::uint64_t {
    if (tok.size() != 2) lineError(std::string(key) + " needs exactly one value");
    const auto v = parseInteger<std::uint64_t>(tok[1]);
    if (!v) lineError(std::string(key) + " value " + quote(tok[1]) + " is not a non-negative integer");
    return *v;
  };

  while (!have_data) {
    bool complete = false;
    const auto line = lines.next(&complete);
    if (!line) {
      if (file.size > file.prefix.size())
        fail(path, "not a PCD file (no DATA line in the first " + std::to_string(kMaxHeaderBytes) + " bytes)");
      if (!seen_keyword) fail(path, "not a PCD file (no header)");
      fail(path, "truncated PCD header: no DATA line");
    }
    if (line->empty()) continue;  // PCL skips empty lines too
    const auto tok = splitWhitespace(*line);
    // PCL ends its header parse at a whitespace-only line and would then read the header itself as data.
    if (tok.empty()) {
      if (!seen_keyword) notPcd(*line);
      lineError("blank line inside the header");
    }
    const std::string_view key = tok[0];
    if (key.front() == '#') continue;
    if (key == "VERSION") {
      seen_keyword = true;
    } else if (key == "FIELDS" || key == "COLUMNS") {
      if (tok.size() < 2) lineError("FIELDS lists no fields");
      if (tok.size() - 1 > kMaxFields) lineError("too many fields (" + std::to_string(tok.size() - 1) + ")");
      h.names.assign(tok.begin() + 1, tok.end());
      h.sizes.clear();
      h.types.clear();
      h.counts.assign(h.names.size(), 1);
      have_fields = true;
      have_size = have_type = false;
    } else if (key == "SIZE") {
      if (!have_fields) lineError("SIZE before FIELDS");
      expectValues(tok, "SIZE");
      h.sizes.clear();
      for (std::size_t i = 1; i < tok.size(); ++i) {
        const auto v = parseInteger<std::uint32_t>(tok[i]);
        if (!v || (*v != 1 && *v != 2 && *v != 4 && *v != 8))
          lineError("field '" + h.names[i - 1] + "' has SIZE " + quote(tok[i]) + " (expected 1, 2, 4 or 8)");
        h.sizes.push_back(*v);
      }
      have_size = true;
    } else if (key == "TYPE") {
      if (!have_size) lineError("TYPE before SIZE");
      expectValues(tok, "TYPE");
      h.types.clear();
      for (std::size_t i = 1; i < tok.size(); ++i) {
        const std::optional<FieldType> t =
            tok[i].size() == 1 ? pcdFieldType(h.sizes[i - 1], tok[i][0]) : std::optional<FieldType>{};
        if (!t)
          lineError("field '" + h.names[i - 1] + "' has TYPE " + quote(tok[i]) + " with SIZE " +
                    std::to_string(h.sizes[i - 1]) +
                    ", which is not supported (I1 I2 I4 U1 U2 U4 F4 F8; no 64-bit integers)");
        h.types.push_back(*t);
      }
      have_type = true;
    } else if (key == "COUNT") {
      if (!have_size || !have_type) lineError("COUNT before SIZE or TYPE");
      expectValues(tok, "COUNT");
      for (std::size_t i = 1; i < tok.size(); ++i) {
        const auto v = parseInteger<std::uint32_t>(tok[i]);
        if (!v || *v == 0 || *v > kMaxFieldCount)
          lineError("field '" + h.names[i - 1] + "' has COUNT " + quote(tok[i]) + " (expected 1.." +
                    std::to_string(kMaxFieldCount) + ")");
        h.counts[i - 1] = *v;
      }
    } else if (key == "WIDTH") {
      h.width = singleValue(tok, "WIDTH");
      width_read = true;
    } else if (key == "HEIGHT") {
      h.height = singleValue(tok, "HEIGHT");
      height_read = true;
    } else if (key == "VIEWPOINT") {
      if (tok.size() != 8) lineError("VIEWPOINT needs 7 values (tx ty tz qw qx qy qz)");
      for (std::size_t i = 1; i < tok.size(); ++i)
        if (!isNumber(tok[i])) lineError("VIEWPOINT value " + quote(tok[i]) + " is not a number");
    } else if (key == "POINTS") {
      if (!have_fields) lineError("POINTS before FIELDS");
      h.points = singleValue(tok, "POINTS");
      have_points = true;
    } else if (key == "DATA") {
      if (tok.size() != 2) lineError("DATA needs exactly one value (ascii, binary or binary_compressed)");
      if (tok[1] == "ascii")
        h.data = PcdData::Ascii;
      else if (tok[1] == "binary")
        h.data = PcdData::Binary;
      else if (tok[1] == "binary_compressed")
        h.data = PcdData::BinaryCompressed;
      else
        lineError("unknown DATA format " + quote(tok[1]));
      // The data section starts right after this line; a header cut after "DATA x" has an empty one.
      h.data_offset = complete ? lines.pos() : file.size;
      have_data = true;
    } else {
      if (!seen_keyword) notPcd(key);
      lineError("unknown keyword " + quote(key));
    }
    seen_keyword = true;
  }

  if (!have_fields || !have_size || !have_type) fail(path, "bad PCD header: FIELDS, SIZE and TYPE are required");
  if (!have_points) fail(path, "bad PCD header: no POINTS line");

  // PCL's defaulting of missing WIDTH/HEIGHT, so that the organisation we check is the one PCL will produce.
  if (!width_read && !height_read) {
    h.width = h.points;
    h.height = 1;
  }
  if (!height_read) {
    h.height = 1;
    if (h.width == 0) h.width = h.points;
  } else if (h.width == 0 && h.points != 0) {
    fail(path, "bad PCD header: HEIGHT given but no WIDTH");
  }
  constexpr std::uint64_t kU32 = std::numeric_limits<std::uint32_t>::max();
  if (h.width > kU32 || h.height > kU32 || h.points > kU32)
    fail(path, "bad PCD header: WIDTH/HEIGHT/POINTS beyond 2^32-1");
  if (h.width * h.height != h.points)
    fail(path, "bad PCD header: WIDTH " + std::to_string(h.width) + " x HEIGHT " + std::to_string(h.height) +
                   " != POINTS " + std::to_string(h.points));

  for (std::size_t i = 0; i < h.names.size(); ++i) h.point_step += std::uint64_t(h.sizes[i]) * h.counts[i];
  if (h.point_step > kMaxPointStep)
    fail(path, "bad PCD header: a point of " + std::to_string(h.point_step) + " bytes is implausible");

  // PCL keeps parsing header keywords after DATA until a line it does not recognise. If the data section happened to
  // start with one (binary bytes spelling "POINTS ..."), PCL would re-size the cloud from it; refuse such files.
  LineCursor after(file.prefix, static_cast<std::size_t>(std::min<std::uint64_t>(h.data_offset, file.prefix.size())));
  while (const auto line = after.next()) {
    if (line->empty()) continue;
    const auto tok = splitWhitespace(*line);
    if (tok.empty()) break;
    const std::string_view key = tok[0];
    if (key.front() == '#' || key.substr(0, 7) == "VERSION") continue;
    for (const char *kw :
         {"FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"})
      if (key.substr(0, std::strlen(kw)) == kw)
        fail(path,
             "bad PCD file: the data section starts with a header keyword " + quote(key) + " (PCL would misread it)");
    break;
  }
  return h;
}

std::string pcdTruncated(const PcdHeader &h, std::uint64_t data_bytes) {
  return "truncated: header says " + std::to_string(h.points) + " points of " + std::to_string(h.point_step) +
         " bytes but data holds " + std::to_string(data_bytes) + " bytes";
}

void checkPcdAscii(const std::string &path, const PcdHeader &h) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open: ") + std::strerror(errno));
  in.seekg(static_cast<std::streamoff>(h.data_offset));
  std::uint64_t elements_per_line = 0;
  for (std::uint32_t c : h.counts) elements_per_line += c;

  std::uint64_t found = 0;
  std::uint64_t line_no = 0;
  std::string line;
  while (found < h.points && std::getline(in, line)) {
    ++line_no;
    if (line.empty()) continue;  // as PCL
    const auto tok = splitWhitespace(line);
    const std::string where = "ascii data line " + std::to_string(line_no) + " (point " + std::to_string(found) + ")";
    if (tok.size() != elements_per_line)
      fail(path,
           where + " has " + std::to_string(tok.size()) + " values, expected " + std::to_string(elements_per_line));
    for (const auto &t : tok)
      if (!isNumber(t) && !iequals(t, "nan")) fail(path, where + ": " + quote(t) + " is not a number");
    ++found;
  }
  if (in.bad()) fail(path, std::string("read failed: ") + std::strerror(errno));
  if (found < h.points)
    fail(path, "truncated: header says " + std::to_string(h.points) + " points but ascii data holds " +
                   std::to_string(found));
}

void checkPcdBody(const std::string &path, const FileBytes &file, const PcdHeader &h) {
  const std::uint64_t data_bytes = file.size - std::min(file.size, h.data_offset);
  const std::uint64_t need = h.points * h.point_step;
  switch (h.data) {
    case PcdData::Binary:
      if (data_bytes < need) fail(path, pcdTruncated(h, data_bytes));
      return;
    case PcdData::BinaryCompressed: {
      if (data_bytes < 8)
        fail(path, "truncated: binary_compressed data holds " + std::to_string(data_bytes) +
                       " bytes, less than its 8-byte size prefix");
      std::array<char, 8> sizes{};
      std::ifstream in(path, std::ios::binary);
      in.seekg(static_cast<std::streamoff>(h.data_offset));
      if (!in.read(sizes.data(), sizes.size())) fail(path, "cannot read the binary_compressed size prefix");
      std::uint32_t compressed = 0, uncompressed = 0;
      std::memcpy(&compressed, sizes.data(), 4);
      std::memcpy(&uncompressed, sizes.data() + 4, 4);
      if (uncompressed != need)
        fail(path, "corrupt binary_compressed data: uncompressed size " + std::to_string(uncompressed) +
                       " does not match the header's " + std::to_string(h.points) + " points of " +
                       std::to_string(h.point_step) + " bytes");
      if (std::uint64_t(compressed) + 8 > data_bytes)
        fail(path, "truncated: binary_compressed block of " + std::to_string(compressed) + " bytes but data holds " +
                       std::to_string(data_bytes - 8) + " bytes");
      if (need > 0 && (compressed == 0 || need > kMaxLzfExpansion * std::uint64_t(compressed) + 64))
        fail(path, "corrupt binary_compressed data: " + std::to_string(compressed) + " compressed bytes cannot hold " +
                       std::to_string(need) + " bytes");
      return;
    }
    case PcdData::Ascii:
      checkPcdAscii(path, h);
      return;
  }
}

// ---------------------------------------------------------------------------------------------------------------------
// PLY validation

enum class PlyFormat { Ascii, BinaryLE, BinaryBE };

struct PlyProperty {
  std::string name;
  FieldType type = FieldType::Float32;  ///< scalar type, or the list's item type
  bool is_list = false;
  FieldType list_size_type = FieldType::UInt8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::Ascii;
  std::vector<PlyElement> elements;
  std::uint64_t data_offset = 0;
  /// The cloud size PCL's reader will allocate for, replayed in header order: obj_info num_cols/num_rows set width and
  /// height (atoi, wrapped to 32 bits) wherever they stand; the vertex element sets count x 1 unless both are
  /// non-zero by then.
  std::uint32_t pcl_width = 0, pcl_height = 0;
};

std::optional<FieldType> plyType(std::string_view name) {
  static const std::array<std::pair<std::string_view, FieldType>, 16> kTypes{{
      {"char", FieldType::Int8},
      {"int8", FieldType::Int8},
      {"uchar", FieldType::UInt8},
      {"uint8", FieldType::UInt8},
      {"short", FieldType::Int16},
      {"int16", FieldType::Int16},
      {"ushort", FieldType::UInt16},
      {"uint16", FieldType::UInt16},
      {"int", FieldType::Int32},
      {"int32", FieldType::Int32},
      {"uint", FieldType::UInt32},
      {"uint32", FieldType::UInt32},
      {"float", FieldType::Float32},
      {"float32", FieldType::Float32},
      {"double", FieldType::Float64},
      {"float64", FieldType::Float64},
  }};
  for (const auto &[n, t] : kTypes)
    if (n == name) return t;
  return std::nullopt;
}

// atoi as glibc applies it to obj_info values: strtol's leading integer (0 when there is none, saturated to the
// 64-bit range), which the caller wraps to 32 bits as PCL's int-to-uint32 assignment does.
std::int64_t atoiLike(std::string_view token) {
  std::int64_t value = 0;
  const char *begin = token.data();
  if (!token.empty() && token.front() == '+') ++begin;
  const auto res = std::from_chars(begin, token.data() + token.size(), value);
  if (res.ec == std::errc::result_out_of_range)
    return *begin == '-' ? std::numeric_limits<std::int64_t>::min() : std::numeric_limits<std::int64_t>::max();
  return res.ec == std::errc() ? value : 0;
}

// PCL packs uchar red/green/blue into one 4-byte "rgb" field by position: it reserves the field at "red", keeps
// writing the following properties from where "red" stood, and writes the packed value and moves on at "blue"; a uchar
// "alpha" renames the last "rgb" field to "rgba" (asserting when there is none) and ORs itself into it. That is right
// only for a run red, green, blue (plain or diffuse_) with nothing between, optionally followed by alpha, and no
// property of its own called rgb/rgba. Anything else (a lone channel, another order, an alpha without colours)
// misplaces bytes, writes past the cloud or aborts inside PCL, so such files go to readPlyVertices instead.
bool pclPacksColours(const PlyElement &vertex) {
  // What PCL makes of a vertex property: 0 red, 1 green, 2 blue, 3 alpha, -1 an ordinary property.
  auto role = [](const PlyProperty &p) {
    if (p.is_list || p.type != FieldType::UInt8) return -1;
    if (p.name == "red" || p.name == "diffuse_red") return 0;
    if (p.name == "green" || p.name == "diffuse_green") return 1;
    if (p.name == "blue" || p.name == "diffuse_blue") return 2;
    return p.name == "alpha" ? 3 : -1;
  };
  const auto &props = vertex.properties;
  std::size_t first = props.size(), seen = 0;
  bool packed_name = false;
  for (std::size_t i = 0; i < props.size(); ++i) {
    packed_name = packed_name || props[i].name == "rgb" || props[i].name == "rgba";
    const int r = role(props[i]);
    if (r < 0) continue;
    if (seen == 0) first = i;
    // The k-th colour property must be the k-th of red, green, blue, alpha and stand right after the previous one.
    if (r != static_cast<int>(seen) || i != first + seen) return false;
    ++seen;
  }
  return seen == 0 || (seen >= 3 && !packed_name);
}

PlyHeader parsePlyHeader(const std::string &path, const FileBytes &file) {
  PlyHeader h;
  LineCursor lines(file.prefix);
  auto lineError = [&](const std::string &what) {
    fail(path, "bad PLY header, line " + std::to_string(lines.lineNo()) + ": " + what);
  };

  const auto magic = lines.next();
  if (!magic || (*magic != "ply" && *magic != "ply\r")) fail(path, "not a PLY file (no 'ply' magic line)");

  bool have_format = false, done = false;
  std::size_t properties = 0;
  while (!done) {
    bool complete = false;
    const auto line = lines.next(&complete);
    if (!line) {
      if (file.size > file.prefix.size())
        fail(path, "not a PLY file (no end_header in the first " + std::to_string(kMaxHeaderBytes) + " bytes)");
      fail(path, "truncated PLY header: no end_header");
    }
    // A PLY header is ASCII text. Other bytes (binary garbage in a name or an obj_info value) make PCL's tokenizer
    // disagree with this one about the layout, which ends in an assert inside PCL's reader (fuzz_ply found one).
    for (const char c : *line)
      if (!((c >= 0x20 && c <= 0x7E) || c == '\t' || c == '\r'))
        lineError("byte 0x" + std::string(1, "0123456789abcdef"[(static_cast<unsigned char>(c) >> 4) & 15]) +
                  std::string(1, "0123456789abcdef"[static_cast<unsigned char>(c) & 15]) +
                  " is not ASCII text");
    const auto tok = splitWhitespace(*line);
    if (tok.empty()) continue;
    const std::string_view key = tok[0];
    if (key == "comment") continue;
    if (key == "format") {
      if (tok.size() != 3 || tok[2] != "1.0") lineError("expected 'format <ascii|binary_*> 1.0'");
      if (tok[1] == "ascii")
        h.format = PlyFormat::Ascii;
      else if (tok[1] == "binary_little_endian")
        h.format = PlyFormat::BinaryLE;
      else if (tok[1] == "binary_big_endian")
        h.format = PlyFormat::BinaryBE;
      else
        lineError("unknown format " + quote(tok[1]));
      have_format = true;
    } else if (key == "obj_info") {
      // PCL asserts (aborting the process) when the raw line does not start with the keyword.
      if (line->substr(0, 8) != "obj_info") lineError("obj_info must start the line");
      // PCL splits this line on spaces and tabs only (boost::split), not on other white space.
      const auto st = splitSpaceTab(*line);
      if (st.size() >= 3 && st[1] == "num_cols") h.pcl_width = static_cast<std::uint32_t>(atoiLike(st[2]));
      if (st.size() >= 3 && st[1] == "num_rows") h.pcl_height = static_cast<std::uint32_t>(atoiLike(st[2]));
    } else if (key == "element") {
      if (tok.size() != 3) lineError("expected 'element <name> <count>'");
      const auto count = parseInteger<std::uint64_t>(tok[2]);
      if (!count) lineError("element count " + quote(tok[2]) + " is not a non-negative integer");
      for (const auto &e : h.elements)
        if (e.name == tok[1]) lineError("element '" + std::string(tok[1]) + "' declared twice");
      h.elements.push_back({std::string(tok[1]), *count, {}});
      if (tok[1] == "vertex" && (h.pcl_width == 0 || h.pcl_height == 0)) {
        h.pcl_width = static_cast<std::uint32_t>(*count);
        h.pcl_height = 1;
      }
    } else if (key == "property") {
      if (h.elements.empty()) lineError("property before any element");
      if (++properties > io_detail::kMaxPlyProperties)
        lineError("more than " + std::to_string(io_detail::kMaxPlyProperties) + " properties");
      PlyProperty prop;
      if (tok.size() == 5 && tok[1] == "list") {
        const auto size_type = plyType(tok[2]);
        const auto item_type = plyType(tok[3]);
        if (!size_type || !item_type || *size_type == FieldType::Float32 || *size_type == FieldType::Float64)
          lineError("bad list property types " + quote(tok[2]) + " " + quote(tok[3]));
        prop.is_list = true;
        prop.list_size_type = *size_type;
        prop.type = *item_type;
        prop.name = std::string(tok[4]);
      } else if (tok.size() == 3) {
        const auto type = plyType(tok[1]);
        if (!type) lineError("unknown property type " + quote(tok[1]));
        prop.type = *type;
        prop.name = std::string(tok[2]);
      } else {
        lineError("expected 'property <type> <name>' or 'property list <size type> <type> <name>'");
      }
      h.elements.back().properties.push_back(std::move(prop));
    } else if (key == "end_header") {
      h.data_offset = complete ? lines.pos() : file.size;
      done = true;
    } else {
      lineError("unknown keyword " + quote(key));
    }
  }
  if (!have_format) fail(path, "bad PLY header: no format line");

  for (const auto &e : h.elements) {
    if (e.count > std::numeric_limits<std::uint32_t>::max())
      fail(path, "bad PLY header: element '" + e.name + "' count " + std::to_string(e.count) + " beyond 2^32-1");
    // PCL reserves memory per declared instance; an instance without properties occupies no bytes, so only an
    // explicit rule can bound it.
    if (e.count > 0 && e.properties.empty())
      fail(path,
           "bad PLY header: element '" + e.name + "' has " + std::to_string(e.count) + " instances but no properties");
    if (e.name == "vertex") {
      for (const auto &p : e.properties)
        if (p.is_list)
          fail(path,
               "unsupported PLY: vertex property '" + p.name + "' is a list (PCL sizes it from the first vertex only)");
    }
  }
  return h;
}

const PlyElement *findVertex(const PlyHeader &h) {
  for (const auto &e : h.elements)
    if (e.name == "vertex") return &e;
  return nullptr;
}

// PCL allocates width x height points and then writes one per vertex: a size that differs from the vertex count
// (obj_info num_cols/num_rows, also after the vertex element, as fuzz_ply found) makes it allocate what the file
// does not justify (num_cols 299999999999 wraps to 3.6e9 points) or write past the cloud.
void checkPlyObjInfo(const std::string &path, const PlyHeader &h) {
  const PlyElement *vertex = findVertex(h);
  if (!vertex) return;  // nothing is allocated per point without one
  if (std::uint64_t(h.pcl_width) * h.pcl_height != vertex->count)
    fail(path, "bad PLY header: obj_info num_cols/num_rows make the cloud " + std::to_string(h.pcl_width) + " x " +
                   std::to_string(h.pcl_height) + " points, but element vertex has " + std::to_string(vertex->count));
}

void checkPlyBinary(const std::string &path, const FileBytes &file, const PlyHeader &h) {
  const std::uint64_t data_bytes = file.size - std::min(file.size, h.data_offset);
  // Bytes each element needs at least (exactly, without list properties); their sum bounds every allocation.
  std::uint64_t need = 0;
  bool exact = true;
  for (const auto &e : h.elements) {
    std::uint64_t record = 0;
    for (const auto &p : e.properties) {
      record += p.is_list ? fieldTypeSize(p.list_size_type) : fieldTypeSize(p.type);
      exact = exact && !p.is_list;
    }
    need += e.count * record;
    if (need > data_bytes) {
      if (e.name == "vertex" && exact)
        fail(path, "truncated: header says " + std::to_string(e.count) + " points of " + std::to_string(record) +
                       " bytes but data holds " + std::to_string(data_bytes - (need - e.count * record)) + " bytes");
      fail(path, "truncated: header declares elements needing at least " + std::to_string(need) +
                     " bytes but data holds " + std::to_string(data_bytes) + " bytes");
    }
  }
}

// A float or double parsed from text, locale-independently: from_chars, and for values beyond the type's range
// (which from_chars reports without a value) strtod/strtof in the C locale, which give +-inf or +-0 as appropriate.
template <typename T>
T parseReal(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  T value{};
  const auto res = std::from_chars(token.data(), token.data() + token.size(), value);
  if (res.ec == std::errc()) return value;
  static const locale_t c_locale = newlocale(LC_ALL_MASK, "C", static_cast<locale_t>(nullptr));
  const std::string text(token);
  if constexpr (std::is_same_v<T, float>)
    return strtof_l(text.c_str(), nullptr, c_locale);
  else
    return strtod_l(text.c_str(), nullptr, c_locale);
}

template <typename T>
bool parseIntegerInto(std::string_view token, std::uint8_t *out) {
  const auto v = parseInteger<std::int64_t>(token);
  if (!v || *v < std::int64_t(std::numeric_limits<T>::min()) || *v > std::int64_t(std::numeric_limits<T>::max()))
    return false;
  const T value = static_cast<T>(*v);
  if (out) std::memcpy(out, &value, sizeof value);
  return true;
}

// Parses a token of an ASCII PLY as a value of `type` and, when `out` is given, stores its bytes there. PCL's reader
// turns unparsable text (and "1.0" for an int property) into NaN or 0 without a word, so the check is strict.
bool parsePlyAsciiValue(std::string_view token, FieldType type, std::uint8_t *out) {
  switch (type) {
    case FieldType::Int8:
      return parseIntegerInto<std::int8_t>(token, out);
    case FieldType::UInt8:
      return parseIntegerInto<std::uint8_t>(token, out);
    case FieldType::Int16:
      return parseIntegerInto<std::int16_t>(token, out);
    case FieldType::UInt16:
      return parseIntegerInto<std::uint16_t>(token, out);
    case FieldType::Int32:
      return parseIntegerInto<std::int32_t>(token, out);
    case FieldType::UInt32:
      return parseIntegerInto<std::uint32_t>(token, out);
    case FieldType::Float32:
    case FieldType::Float64:
      if (!isNumber(token)) return false;
      if (out && type == FieldType::Float32) {
        const float value = parseReal<float>(token);
        std::memcpy(out, &value, sizeof value);
      } else if (out) {
        const double value = parseReal<double>(token);
        std::memcpy(out, &value, sizeof value);
      }
      return true;
  }
  return false;
}

void checkPlyAscii(const std::string &path, const FileBytes &file, const PlyHeader &h) {
  const std::uint64_t data_bytes = file.size - std::min(file.size, h.data_offset);
  // Every value takes at least one character and a separator: bounds what PCL reserves before reading.
  std::uint64_t min_values = 0;
  for (const auto &e : h.elements) min_values += e.count * e.properties.size();
  if (min_values > data_bytes / 2 + 1)
    fail(path, "truncated: header declares " + std::to_string(min_values) + " values but ascii data holds only " +
                   std::to_string(data_bytes) + " bytes");

  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open: ") + std::strerror(errno));
  in.seekg(static_cast<std::streamoff>(h.data_offset));
  std::string token;
  auto nextToken = [&](const PlyElement &e, std::uint64_t index) {
    if (!(in >> token))
      fail(path,
           "truncated: ascii data ends in " + e.name + " " + std::to_string(index) + " of " + std::to_string(e.count));
  };
  // Only elements up to the vertex matter: PCL's result comes from the vertices, and what follows them is merely
  // parsed (their counts were bounded above).
  for (const auto &e : h.elements) {
    const bool is_vertex = e.name == "vertex";
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (const auto &p : e.properties) {
        nextToken(e, i);
        if (p.is_list) {
          const auto n = parseInteger<std::uint32_t>(token);
          if (!n) fail(path, "ascii " + e.name + " " + std::to_string(i) + ": list size " + quote(token) + " invalid");
          for (std::uint32_t k = 0; k < *n; ++k) nextToken(e, i);
        } else if (is_vertex && !parsePlyAsciiValue(token, p.type, nullptr)) {
          fail(path, "ascii vertex " + std::to_string(i) + ": " + quote(token) + " is not a valid " +
                         fieldTypeName(p.type) + " value for property '" + p.name + "'");
        }
      }
    }
    if (is_vertex) break;
  }
}

// ---------------------------------------------------------------------------------------------------------------------
// hpds's own PLY vertex reader, for the colour arrangements PCL cannot pack (see pclPacksColours)

void checkCloudLayout(const std::string &path, const PointLayout &layout);

// Sequential reads of the data section with every read checked against what is left of the file.
class PlyDataStream {
 public:
  PlyDataStream(const std::string &path, const PlyHeader &h) : path_(path), format_(h.format), in_(path, std::ios::binary) {
    if (!in_) fail(path, std::string("cannot open: ") + std::strerror(errno));
    in_.seekg(static_cast<std::streamoff>(h.data_offset));
    if (!in_) fail(path, "cannot seek to the PLY data");
  }

  /// Reads `n` bytes into `out` (binary), failing with "truncated" when the file ends first.
  void read(std::uint8_t *out, std::uint64_t n, const std::string &where) {
    in_.read(reinterpret_cast<char *>(out), static_cast<std::streamsize>(n));
    if (static_cast<std::uint64_t>(in_.gcount()) != n) fail(path_, "truncated: binary data ends in " + where);
  }
  /// Skips `n` bytes (binary).
  void skip(std::uint64_t n, const std::string &where) {
    in_.ignore(static_cast<std::streamsize>(n));
    if (static_cast<std::uint64_t>(in_.gcount()) != n) fail(path_, "truncated: binary data ends in " + where);
  }
  /// Next whitespace-separated token (ascii), or nullptr at the end of the file.
  const std::string *next() { return (in_ >> token_) ? &token_ : nullptr; }
  const std::string &token(const std::string &where) {
    if (!next()) fail(path_, "truncated: ascii data ends in " + where);
    return token_;
  }
  /// A list's element count, whatever its declared integer type.
  std::uint64_t listSize(FieldType type, const std::string &where) {
    if (format_ == PlyFormat::Ascii) {
      const auto n = parseInteger<std::uint32_t>(token(where));
      if (!n) fail(path_, where + ": list size " + quote(token_) + " invalid");
      return *n;
    }
    std::uint8_t bytes[8] = {};
    const PointField f{"", 0, type, 1};
    read(bytes, f.byteSize(), where);
    if (format_ == PlyFormat::BinaryBE) std::reverse(bytes, bytes + f.byteSize());
    const double n = readAsDouble(bytes, f);
    if (n < 0) fail(path_, where + ": negative list size " + std::to_string(static_cast<std::int64_t>(n)));
    return static_cast<std::uint64_t>(n);
  }
  /// Moves past one element's instances without storing them.
  void skipElement(const PlyElement &e) {
    const std::string where = "element '" + e.name + "'";
    if (format_ != PlyFormat::Ascii) {
      std::uint64_t record = 0;
      bool fixed = true;
      for (const auto &p : e.properties) {
        record += fieldTypeSize(p.type);
        fixed = fixed && !p.is_list;
      }
      // Every instance takes at least one byte (elements without properties are refused), so the loop below is
      // bounded by the file's size.
      if (fixed) return skip(e.count * record, where);
    }
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (const auto &p : e.properties) {
        const std::uint64_t n = p.is_list ? listSize(p.list_size_type, where) : 1;
        if (format_ != PlyFormat::Ascii) {
          skip(n * fieldTypeSize(p.type), where);
        } else {
          for (std::uint64_t k = 0; k < n; ++k) token(where);
        }
      }
    }
  }

 private:
  const std::string &path_;
  PlyFormat format_;
  std::ifstream in_;
  std::string token_;
};

// Reads the vertex element as it is declared: one field per property, in order, with the property's name and type
// (no packing, widening or renaming), organised by obj_info num_cols/num_rows as PCL would. Elements before the vertex
// are walked past; those after it are not read. Expects the header checks (parsePlyHeader, checkPlyObjInfo) done.
PointBuffer readPlyVertices(const std::string &path, const FileBytes &file, const PlyHeader &h) {
  const PlyElement *vertex = findVertex(h);
  if (!vertex) fail(path, "no x/y/z fields (no vertex element)");
  // The header is at most kMaxHeaderBytes, so point_step stays far below 2^32 and n * point_step below 2^64.
  PointLayout layout;
  std::vector<std::uint32_t> offsets;
  for (const PlyProperty &p : vertex->properties) {
    offsets.push_back(layout.point_step);
    if (p.name != "_") layout.fields.push_back({p.name, layout.point_step, p.type, 1});  // "_": padding, as from PCL
    layout.point_step += static_cast<std::uint32_t>(fieldTypeSize(p.type));
  }
  checkCloudLayout(path, layout);

  // Nothing is allocated beyond what the file can hold: binary records are stored whole, ascii values take at least
  // two bytes each (a character and a separator).
  const std::uint64_t n = vertex->count;
  const std::uint64_t data_bytes = file.size - std::min(file.size, h.data_offset);
  const bool ascii = h.format == PlyFormat::Ascii;
  if (ascii ? n * vertex->properties.size() > data_bytes / 2 + 1 : n * layout.point_step > data_bytes)
    fail(path, "truncated: header says " + std::to_string(n) + " points but the data holds only " +
                   std::to_string(data_bytes) + " bytes");

  PointBuffer cloud(layout, static_cast<std::size_t>(n));
  PlyDataStream data(path, h);
  for (const PlyElement &e : h.elements) {
    if (&e == vertex) break;
    data.skipElement(e);
  }
  if (!ascii) {
    data.read(cloud.bytes().data(), cloud.bytes().size(), "the vertex element");
    if (h.format == PlyFormat::BinaryBE)
      for (std::size_t i = 0; i < cloud.size(); ++i)
        for (std::size_t k = 0; k < offsets.size(); ++k) {
          std::uint8_t *value = cloud.record(i) + offsets[k];
          std::reverse(value, value + fieldTypeSize(vertex->properties[k].type));
        }
  } else {
    for (std::size_t i = 0; i < cloud.size(); ++i)
      for (std::size_t k = 0; k < offsets.size(); ++k) {
        const PlyProperty &p = vertex->properties[k];
        const std::string *token = data.next();
        if (!token)
          fail(path, "truncated: ascii data ends in vertex " + std::to_string(i) + " of " + std::to_string(n));
        if (!parsePlyAsciiValue(*token, p.type, cloud.record(i) + offsets[k]))
          fail(path, "ascii vertex " + std::to_string(i) + ": " + quote(*token) + " is not a valid " +
                         fieldTypeName(p.type) + " value for property '" + p.name + "'");
      }
  }

  if (std::uint64_t(h.pcl_width) * h.pcl_height == n) cloud.setOrganization(h.pcl_width, h.pcl_height);
  return cloud;
}

// ---------------------------------------------------------------------------------------------------------------------
// PCL

// PCL's console verbosity is process-global. Nested/concurrent readers share one "quiet" period; the level in force
// before the first one entered is restored when the last one leaves.
class QuietPcl {
 public:
  QuietPcl() {
    std::lock_guard<std::mutex> lock(mutex());
    if (depth()++ == 0) {
      saved() = pcl::console::getVerbosityLevel();
      pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
    }
  }
  ~QuietPcl() {
    std::lock_guard<std::mutex> lock(mutex());
    if (--depth() == 0) pcl::console::setVerbosityLevel(saved());
  }
  QuietPcl(const QuietPcl &) = delete;
  QuietPcl &operator=(const QuietPcl &) = delete;

 private:
  static std::mutex &mutex() {
    static std::mutex m;
    return m;
  }
  static int &depth() {
    static int d = 0;
    return d;
  }
  static pcl::console::VERBOSITY_LEVEL &saved() {
    static pcl::console::VERBOSITY_LEVEL level = pcl::console::L_INFO;
    return level;
  }
};

// What every cloud a reader returns must satisfy: a valid layout with single-valued x, y and z.
void checkCloudLayout(const std::string &path, const PointLayout &layout) {
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(path, std::string("invalid point layout: ") + e.what());
  }
  if (!layout.find("x") || !layout.find("y") || !layout.find("z")) {
    std::string names;
    for (const auto &f : layout.fields) names += (names.empty() ? "" : " ") + f.name;
    fail(path, "no x/y/z fields (fields: " + (names.empty() ? std::string("none") : names) + ")");
  }
  // The pipeline reads one coordinate per axis; a vector-valued x would be sampled by its first element and lost on
  // writing (fuzz_pcd found it), so it is refused here, where the file can still be named.
  for (const char *axis : {"x", "y", "z"}) {
    const PointField &f = *layout.find(axis);
    if (f.count != 1)
      fail(path, "field '" + f.name + "' has count " + std::to_string(f.count) + ": x, y and z must be single values");
  }
}

PointBuffer fromPcl(const std::string &path, const pcl::PCLPointCloud2 &pc) {
  if (pc.is_bigendian) fail(path, "big-endian point data is not supported");
  PointLayout layout;
  layout.point_step = pc.point_step;
  for (const auto &f : pc.fields) {
    if (f.name == "_") continue;  // PCL's padding
    if (!isValidFieldType(f.datatype))
      fail(path, "field '" + f.name + "' has datatype " + std::to_string(int(f.datatype)) +
                     " (64-bit integer or bool), which hpds cannot represent");
    if (f.count == 0) fail(path, "field '" + f.name + "' has count 0");
    PointField field;
    field.name = f.name;
    field.offset = f.offset;
    field.type = static_cast<FieldType>(f.datatype);
    field.count = f.count;
    layout.fields.push_back(std::move(field));
  }
  checkCloudLayout(path, layout);

  // Sizes are checked against the bytes PCL actually produced before anything is allocated: width/height can come
  // from file content PCL applies after sizing its buffer (a PLY "camera" element's viewport).
  const std::uint64_t n = std::uint64_t(pc.width) * pc.height;
  const std::uint64_t dense_row = std::uint64_t(pc.width) * pc.point_step;
  const bool dense = pc.data.size() == n * pc.point_step;
  const bool strided = !dense && pc.row_step > dense_row && pc.height > 0 &&
                       pc.data.size() >= std::uint64_t(pc.height - 1) * pc.row_step + dense_row;
  if (!dense && !strided)
    fail(path, "inconsistent cloud: " + std::to_string(pc.data.size()) + " bytes for " + std::to_string(pc.width) +
                   "x" + std::to_string(pc.height) + " points of " + std::to_string(pc.point_step) + " bytes");
  PointBuffer cloud(layout, static_cast<std::size_t>(n));
  if (dense) {
    if (!pc.data.empty()) std::memcpy(cloud.bytes().data(), pc.data.data(), pc.data.size());
  } else {
    for (std::uint32_t row = 0; row < pc.height; ++row)
      std::memcpy(cloud.bytes().data() + row * dense_row, pc.data.data() + std::uint64_t(row) * pc.row_step,
                  static_cast<std::size_t>(dense_row));
  }
  cloud.setOrganization(pc.width, pc.height);
  return cloud;
}

// PCL's PLY reader widens a uchar "intensity" to float32; put the declared type back (in place: the offsets PCL
// chose stay, the freed bytes become padding) so that PLY round trips keep datatypes.
void restorePlyTypes(PointBuffer &cloud, const PlyHeader &h) {
  const PlyElement *vertex = findVertex(h);
  if (!vertex) return;
  PointLayout layout = cloud.layout();
  bool changed = false;
  for (const auto &p : vertex->properties) {
    if (p.is_list || p.name != "intensity" || p.type != FieldType::UInt8) continue;
    for (auto &f : layout.fields) {
      if (f.name != p.name || f.count != 1 || f.type != FieldType::Float32) continue;
      const PointField wide = f;
      f.type = p.type;
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        std::uint8_t *rec = cloud.record(i);
        const double value = readAsDouble(rec, wide);
        std::memset(rec + wide.offset, 0, wide.byteSize());
        writeFromDouble(rec, f, value);
      }
      changed = true;
    }
  }
  if (!changed) return;
  const std::uint32_t width = cloud.width(), height = cloud.height();
  PointBuffer out(layout, 0);
  out.bytes() = std::move(cloud.bytes());
  out.setOrganization(width, height);
  cloud = std::move(out);
}

// Runs PCL's reader of `format` ("PCD" or "PLY") on a file the checks above have passed, quietly, with PCL's
// failures (exceptions, negative results) turned into our errors, and copies the result into a PointBuffer.
template <typename PclReader>
PointBuffer readWithPcl(const std::string &path, const char *format) {
  pcl::PCLPointCloud2 pc;
  int result = -1;
  {
    QuietPcl quiet;
    try {
      PclReader reader;
      Eigen::Vector4f origin;
      Eigen::Quaternionf orientation;
      int version = 0;
      result = reader.read(path, pc, origin, orientation, version);
    } catch (const std::exception &e) {
      fail(path, std::string("PCL's ") + format + " reader failed: " + e.what());
    } catch (...) {
      fail(path, std::string("PCL's ") + format + " reader failed with an unknown exception");
    }
  }
  if (result < 0)
    fail(path, std::string("PCL's ") + format + " reader rejected the file (error " + std::to_string(result) + ")");
  return fromPcl(path, pc);
}

PointBuffer readPcd(const std::string &path) {
  const FileBytes file = openForReading(path);
  const PcdHeader header = parsePcdHeader(path, file);
  checkPcdBody(path, file, header);
  return readWithPcl<pcl::PCDReader>(path, "PCD");
}

PointBuffer readPly(const std::string &path) {
  const FileBytes file = openForReading(path);
  const PlyHeader header = parsePlyHeader(path, file);
  checkPlyObjInfo(path, header);
  if (header.format == PlyFormat::Ascii)
    checkPlyAscii(path, file, header);
  else
    checkPlyBinary(path, file, header);
  const PlyElement *vertex = findVertex(header);
  if (vertex && !pclPacksColours(*vertex)) return readPlyVertices(path, file, header);
  PointBuffer cloud = readWithPcl<pcl::PLYReader>(path, "PLY");
  restorePlyTypes(cloud, header);
  return cloud;
}

bool isValidPcdFieldName(const std::string &name) {
  if (name.empty()) return false;
  for (unsigned char c : name)
    if (c <= ' ' || c == 0x7f) return false;
  return true;
}

}  // namespace

PointBuffer readPointCloud(const std::string &path) {
  const std::string ext = lowerExtension(path);
  if (ext == ".pcd") return readPcd(path);
  if (ext == ".ply") return readPly(path);
  if (ext == ".bin") return readKittiBin(path);
  fail(path, "unsupported extension " + quote(ext.empty() ? "(none)" : ext) + " (expected .pcd, .ply or .bin)");
}

pcl::PCLPointCloud2 toPclCloud2(const PointBuffer &cloud) {
  const PointLayout &layout = cloud.layout();
  // PCL's header writer assumes fields in offset order and derives "_" padding from the gaps between them.
  std::vector<PointField> fields = layout.fields;
  std::stable_sort(fields.begin(), fields.end(),
                   [](const PointField &a, const PointField &b) { return a.offset < b.offset; });
  bool overlapping = false;
  for (std::size_t i = 1; i < fields.size(); ++i)
    overlapping = overlapping || fields[i].offset < fields[i - 1].offset + fields[i - 1].byteSize();

  pcl::PCLPointCloud2 pc;
  pc.is_bigendian = false;
  pc.is_dense = false;
  const std::size_t n = cloud.size();
  const bool organised = std::uint64_t(cloud.width()) * cloud.height() == n;
  pc.width = organised ? cloud.width() : static_cast<std::uint32_t>(n);
  pc.height = organised ? cloud.height() : 1;
  if (!overlapping) {
    for (const auto &f : fields) {
      pcl::PCLPointField pf;
      pf.name = f.name;
      pf.offset = f.offset;
      pf.datatype = static_cast<std::uint8_t>(f.type);
      pf.count = f.count;
      pc.fields.push_back(pf);
    }
    pc.point_step = layout.point_step;
    pc.data = cloud.bytes();
  } else {
    // PCL fields cannot alias each other: repack each into its own bytes.
    std::uint32_t offset = 0;
    for (const auto &f : layout.fields) {
      pcl::PCLPointField pf;
      pf.name = f.name;
      pf.offset = offset;
      pf.datatype = static_cast<std::uint8_t>(f.type);
      pf.count = f.count;
      pc.fields.push_back(pf);
      offset += static_cast<std::uint32_t>(f.byteSize());
    }
    pc.point_step = offset;
    pc.data.resize(n * offset);
    for (std::size_t i = 0; i < n; ++i) {
      std::uint8_t *dst = pc.data.data() + i * offset;
      for (std::size_t k = 0; k < layout.fields.size(); ++k)
        std::memcpy(dst + pc.fields[k].offset, cloud.record(i) + layout.fields[k].offset, layout.fields[k].byteSize());
    }
  }
  pc.row_step = pc.width * pc.point_step;
  return pc;
}

void writePcd(const std::string &path, const PointBuffer &cloud) {
  const PointLayout &layout = cloud.layout();
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(path, std::string("cannot write PCD: invalid layout: ") + e.what());
  }
  if (layout.fields.empty()) fail(path, "cannot write PCD: the cloud has no fields");
  for (const auto &f : layout.fields) {
    if (!isValidPcdFieldName(f.name)) fail(path, "cannot write PCD: field name " + quote(f.name) + " is invalid");
    if (f.count > kMaxFieldCount)
      fail(path, "cannot write PCD: field '" + f.name + "' has count " + std::to_string(f.count) +
                     ", more than the " + std::to_string(kMaxFieldCount) + " elements a field may have");
  }

  const pcl::PCLPointCloud2 pc = toPclCloud2(cloud);

  const fs::path parent = fs::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty() && !fs::is_directory(parent, ec)) fail(path, "cannot write PCD: directory does not exist");

  // PCL formats the header (field list, "_" padding fields, organisation). The file itself is written here:
  // PCDWriter::writeBinary stretches the file to one memory page plus the data, which leaves up to 4 KiB of zeros
  // after the points and, once the header outgrows a page (many fields), writes past the end of its mapping (SIGBUS).
  std::string header;
  {
    QuietPcl quiet;
    try {
      pcl::PCDWriter writer;
      header = writer.generateHeaderBinary(pc, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity());
    } catch (const std::exception &e) {
      fail(path, std::string("cannot write PCD: ") + e.what());
    }
  }
  if (header.empty()) fail(path, "cannot write PCD: PCL could not describe the point layout");
  header += "DATA binary\n";

  io_detail::OutputFile file(path);
  file.write(header.data(), header.size());
  file.write(pc.data.data(), pc.data.size());
  file.close();
}

void writePointCloud(const std::string &path, const PointBuffer &cloud) {
  const std::string ext = lowerExtension(path);
  if (ext == ".pcd") return writePcd(path, cloud);
  if (ext == ".ply") return writePly(path, cloud);
  if (ext == ".bin") return writeKittiBin(path, cloud);
  fail(path, "unsupported extension " + quote(ext.empty() ? "(none)" : ext) + " (expected .pcd, .ply or .bin)");
}

}  // namespace hpds
