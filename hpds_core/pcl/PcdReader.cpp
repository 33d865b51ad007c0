// PCD files: the header and body checks that make PCL's PCDReader safe to run (see ReaderSupport.hpp), then PCL.
#include <pcl/io/lzf.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <utility>

#include "ReaderSupport.hpp"

namespace hpds::pcl_detail {

namespace {

// Sanity limits far above any real sensor record, low enough that products below cannot overflow 64 bits.
constexpr std::uint64_t kMaxFields = 1 << 16;
constexpr std::uint64_t kMaxPointStep = 1 << 24;
// LZF emits at most 264 bytes per 3-byte back-reference; a claimed expansion beyond this factor is corruption.
constexpr std::uint64_t kMaxLzfExpansion = 128;

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
  double viewpoint[3] = {0.0, 0.0, 0.0};  ///< VIEWPOINT's translation: where the sensor was
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
      // Normals are turned toward this position, so it must be a usable one (PCL would orient toward NaN).
      for (int a = 0; a < 3; ++a) {
        const std::optional<double> v = parseNumber(tok[1 + a]);
        if (!v || !std::isfinite(*v)) lineError("VIEWPOINT position " + quote(tok[1 + a]) + " is not a finite number");
        h.viewpoint[a] = *v;
      }
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
    fail(path, width_read ? "bad PCD header: WIDTH 0 x HEIGHT " + std::to_string(h.height) + " != POINTS " +
                                std::to_string(h.points)
                          : std::string("bad PCD header: HEIGHT given but no WIDTH"));
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

bool isIntegerType(FieldType t) { return t != FieldType::Float32 && t != FieldType::Float64; }

std::pair<std::int64_t, std::int64_t> integerRange(FieldType t) {
  switch (t) {
    case FieldType::Int8:
      return {-128, 127};
    case FieldType::UInt8:
      return {0, 255};
    case FieldType::Int16:
      return {-32768, 32767};
    case FieldType::UInt16:
      return {0, 65535};
    case FieldType::Int32:
      return {-2147483648LL, 2147483647LL};
    case FieldType::UInt32:
      return {0, 4294967295LL};
    default:
      return {0, 0};
  }
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
    std::size_t k = 0;
    for (std::size_t f = 0; f < h.types.size(); ++f)
      for (std::uint32_t c = 0; c < h.counts[f]; ++c, ++k) {
        const std::string_view t = tok[k];
        if (!isIntegerType(h.types[f])) {
          if (!isNumber(t) && !iequals(t, "nan")) fail(path, where + ": " + quote(t) + " is not a number");
          continue;
        }
        // PCL reads integer fields with a stream it reuses across values: "1e2" or "1.5" gave 1 on the first line
        // and 100 or 1.5 later, and values beyond the type wrapped. Only plain integers within the type pass.
        const std::optional<std::int64_t> v = parseInteger<std::int64_t>(t);
        const auto [lo, hi] = integerRange(h.types[f]);
        if (!v || *v < lo || *v > hi)
          fail(path, where + ": " + quote(t) + " is not an integer in " + std::to_string(lo) + ".." +
                         std::to_string(hi) + ", as field '" + h.names[f] + "' (TYPE " +
                         (lo < 0 ? "I" : "U") + ", SIZE " + std::to_string(h.sizes[f]) + ") needs");
      }
    ++found;
  }
  if (in.bad()) fail(path, std::string("read failed: ") + std::strerror(errno));
  if (found < h.points)
    fail(path, "truncated: header says " + std::to_string(h.points) + " points but ascii data holds " +
                   std::to_string(found));
  // PCL reads the first POINTS lines and only warns about the rest: a header that under-states the count would lose
  // the points after it without a word.
  if (const auto extra = nextNonBlankLine(in))
    fail(path, "ascii data line " + std::to_string(line_no + *extra) + " holds a point beyond the header's POINTS " +
                   std::to_string(h.points) + ": the header under-states the count (fix POINTS, WIDTH and HEIGHT)");
}

// Bytes of a point without its "_" padding fields.
std::uint64_t unpaddedStep(const PcdHeader &h) {
  std::uint64_t step = 0;
  for (std::size_t f = 0; f < h.names.size(); ++f)
    if (h.names[f] != "_") step += std::uint64_t(h.sizes[f]) * h.counts[f];
  return step;
}

bool hasPadding(const PcdHeader &h) { return unpaddedStep(h) != h.point_step; }

void checkPcdBody(const std::string &path, const FileBytes &file, const PcdHeader &h) {
  const std::uint64_t data_bytes = file.size - std::min(file.size, h.data_offset);
  const std::uint64_t need = h.points * h.point_step;
  switch (h.data) {
    case PcdData::Binary:
      if (data_bytes < need) fail(path, pcdTruncated(h, data_bytes));
      // PCL reads the declared points and ignores the rest: a header that under-states the count would lose the points
      // after it without a word, as in ascii data. Fewer bytes than a point (a final newline) are let pass.
      if (h.point_step > 0 && data_bytes - need >= h.point_step)
        fail(path, "binary data holds " + std::to_string(data_bytes - need) + " bytes (" +
                       std::to_string((data_bytes - need) / h.point_step) + " points of " +
                       std::to_string(h.point_step) + " bytes) beyond the header's POINTS " +
                       std::to_string(h.points) + ": the header under-states the count (fix POINTS, WIDTH and HEIGHT)");
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
      // With "_" padding fields writers differ: the columns hold the padding or leave it out (readPaddedCompressed).
      if (uncompressed != need && uncompressed != h.points * unpaddedStep(h))
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

// The decoded body of a binary_compressed file whose sizes checkPcdBody accepted; fails naming the cause when the
// LZF stream does not decode to the stored size. Also run after PCL refused such a file, which it reports only as
// "error -1": the cause left then is the stream itself.
std::vector<char> decodeLzfBody(const std::string &path, const PcdHeader &h) {
  std::ifstream in(path, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(h.data_offset));
  std::uint32_t sizes[2] = {0, 0};
  if (!in.read(reinterpret_cast<char *>(sizes), sizeof sizes)) fail(path, "cannot read the binary_compressed sizes");
  std::vector<char> packed(sizes[0]), unpacked(sizes[1]);
  if (!in.read(packed.data(), static_cast<std::streamsize>(packed.size())))
    fail(path, "truncated: binary_compressed block of " + std::to_string(sizes[0]) + " bytes");
  const unsigned got = packed.empty() ? 0u : pcl::lzfDecompress(packed.data(), sizes[0], unpacked.data(), sizes[1]);
  if (got != sizes[1])
    fail(path, "corrupt binary_compressed data: its LZF stream of " + std::to_string(sizes[0]) +
                   " bytes does not decode to the " + std::to_string(sizes[1]) + " bytes of the header's " +
                   std::to_string(h.points) + " points");
  return unpacked;
}

// binary_compressed with "_" padding fields. PCL's decoder skips the padding's columns but takes the size stored
// in the file: columns written with the padding (as some writers do) came out shifted into garbage, and columns
// without it made PCL shrink its buffer and copy past it. Both layouts are told apart by that size (checkPcdBody
// accepted only these two) and decoded here, each field's column into its place in the records.
PointBuffer readPaddedCompressed(const std::string &path, const PcdHeader &h) {
  PointLayout layout;
  layout.point_step = static_cast<std::uint32_t>(h.point_step);
  std::vector<std::uint32_t> offsets;  // of every field, padding included
  std::uint32_t offset = 0;
  for (std::size_t f = 0; f < h.names.size(); ++f) {
    offsets.push_back(offset);
    if (h.names[f] != "_") layout.fields.push_back({h.names[f], offset, h.types[f], h.counts[f]});
    offset += h.sizes[f] * h.counts[f];
  }
  checkCloudLayout(path, layout);

  const std::vector<char> unpacked = decodeLzfBody(path, h);
  const bool padding_stored = unpacked.size() == h.points * h.point_step;

  PointBuffer cloud(layout, static_cast<std::size_t>(h.points));
  const char *column = unpacked.data();
  for (std::size_t f = 0; f < h.names.size(); ++f) {
    const bool padding = h.names[f] == "_";
    if (padding && !padding_stored) continue;
    const std::size_t bytes = std::size_t(h.sizes[f]) * h.counts[f];
    if (!padding)
      for (std::size_t i = 0; i < cloud.size(); ++i)
        std::memcpy(cloud.record(i) + offsets[f], column + i * bytes, bytes);
    column += bytes * cloud.size();
  }
  cloud.setOrganization(static_cast<std::uint32_t>(h.width), static_cast<std::uint32_t>(h.height));
  return cloud;
}

}  // namespace

PointBuffer readPcd(const std::string &path, Eigen::Vector3d *viewpoint) {
  const FileBytes file = openForReading(path);
  const PcdHeader header = parsePcdHeader(path, file);
  if (viewpoint) *viewpoint = Eigen::Vector3d(header.viewpoint[0], header.viewpoint[1], header.viewpoint[2]);
  checkPcdBody(path, file, header);
  if (header.data != PcdData::BinaryCompressed) return readWithPcl(path, PclFormat::Pcd);
  if (hasPadding(header)) return readPaddedCompressed(path, header);
  try {
    return readWithPcl(path, PclFormat::Pcd);
  } catch (const std::runtime_error &) {
    (void)decodeLzfBody(path, header);
    throw;
  }
}

}  // namespace hpds::pcl_detail
