// PLY files: the header and body checks that make PCL's PLYReader safe to run (see ReaderSupport.hpp), hpds's own
// vertex reader for the colour arrangements PCL cannot pack, then PCL.
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <limits>
#include <locale.h>
#include <type_traits>

#include "ReaderSupport.hpp"

namespace hpds::pcl_detail {

namespace {

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
      // PCL refuses a repeated name with only "error -1"; "_" is padding and may repeat.
      if (prop.name != "_")
        for (const PlyProperty &p : h.elements.back().properties)
          if (p.name == prop.name)
            lineError("property '" + prop.name + "' declared twice in element '" + h.elements.back().name + "'");
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
  // PCL reads the declared vertices and ignores the rest: with nothing declared after them, a whole vertex more means
  // a header that under-states the count, whose last points would be lost without a word (as in ascii data). Fewer
  // bytes than a vertex (a final newline) are let pass.
  if (exact && !h.elements.empty() && h.elements.back().name == "vertex") {
    std::uint64_t record = 0;
    for (const auto &p : h.elements.back().properties) record += fieldTypeSize(p.type);
    if (record > 0 && data_bytes - need >= record)
      fail(path, "binary data holds " + std::to_string(data_bytes - need) + " bytes (" +
                     std::to_string((data_bytes - need) / record) + " vertices of " + std::to_string(record) +
                     " bytes) beyond the header's " + std::to_string(h.elements.back().count) +
                     " vertices: the header under-states the count (fix 'element vertex')");
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
    fail(path, "truncated: the header declares " + std::to_string(min_values) + " values, at least " +
                   std::to_string(2 * min_values - 1) + " bytes of ascii data, but the file holds only " +
                   std::to_string(data_bytes) + " bytes after its header");

  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open: ") + std::strerror(errno));
  in.seekg(static_cast<std::streamoff>(h.data_offset));
  // One element per line, as the format has it and PCL reads it: a line with a value too many or too few is named
  // here (PCL only said "error -1"), a last line cut short is a truncated file.
  std::string line, token;
  std::istringstream values;
  auto truncated = [&](const PlyElement &e, std::uint64_t index) {
    fail(path,
         "truncated: ascii data ends in " + e.name + " " + std::to_string(index) + " of " + std::to_string(e.count));
  };
  auto nextLine = [&](const PlyElement &e, std::uint64_t index) {
    if (!std::getline(in, line)) truncated(e, index);
    values.clear();
    values.str(line);
  };
  auto declared = [](const PlyElement &e) {
    std::string d = std::to_string(e.properties.size()) + " propert" + (e.properties.size() == 1 ? "y" : "ies");
    for (const auto &p : e.properties)
      if (p.is_list) return d + " (with lists)";
    return d;
  };
  auto nextToken = [&](const PlyElement &e, std::uint64_t index, std::size_t taken) {
    if (values >> token) return;
    if (in.eof()) truncated(e, index);
    fail(path, "ascii " + e.name + " " + std::to_string(index) + ": its line holds only " + std::to_string(taken) +
                   " value" + (taken == 1 ? "" : "s") + " for the header's " + declared(e) + ": " + quote(line));
  };
  // Only elements up to the vertex matter: PCL's result comes from the vertices, and what follows them is merely
  // parsed (their counts were bounded above).
  for (const auto &e : h.elements) {
    const bool is_vertex = e.name == "vertex";
    for (std::uint64_t i = 0; i < e.count; ++i) {
      nextLine(e, i);
      std::size_t taken = 0;
      for (const auto &p : e.properties) {
        nextToken(e, i, taken++);
        if (p.is_list) {
          const auto n = parseInteger<std::uint32_t>(token);
          if (!n) fail(path, "ascii " + e.name + " " + std::to_string(i) + ": list size " + quote(token) + " invalid");
          for (std::uint32_t k = 0; k < *n; ++k) nextToken(e, i, taken++);
        } else if (is_vertex && !parsePlyAsciiValue(token, p.type, nullptr)) {
          fail(path, "ascii vertex " + std::to_string(i) + ": " + quote(token) + " is not a valid " +
                         fieldTypeName(p.type) + " value for property '" + p.name + "'");
        }
      }
      if (values >> token)
        fail(path, "ascii " + e.name + " " + std::to_string(i) + ": its line holds more values than the header's " +
                       declared(e) + " (" + quote(token) + " is one too many): " + quote(line));
    }
    if (!is_vertex) continue;
    // PCL reads the declared count and ignores the rest: with nothing declared after the vertices, more data means a
    // header that under-states the count, whose last points would be lost without a word.
    if (&e == &h.elements.back())
      if (const auto extra = nextNonBlankLine(in))
        fail(path, "ascii data holds more than the header's " + std::to_string(e.count) + " vertices (line " +
                       std::to_string(*extra) + " after the last one is not blank): the header under-states the "
                       "count (fix 'element vertex')");
    break;
  }
}

// ---------------------------------------------------------------------------------------------------------------------
// hpds's own PLY vertex reader, for the colour arrangements PCL cannot pack (see pclPacksColours)


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

// The same bytes under `layout` (same point_step and offsets, other names or types), organisation kept.
void relayout(PointBuffer &cloud, PointLayout layout) {
  const std::uint32_t width = cloud.width(), height = cloud.height();
  PointBuffer out(std::move(layout), 0);
  out.bytes() = std::move(cloud.bytes());
  out.setOrganization(width, height);
  cloud = std::move(out);
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
  if (changed) relayout(cloud, std::move(layout));
}

// PCL's PLY reader names the properties nx ny nz normal_x normal_y normal_z. The file's own names are put back: a
// cloud keeps its fields as they are, and the output's warning about input fields it does not carry named a
// normal_x the file does not have (hpds writes its own normal_x beside the input's nx).
void restorePlyNames(PointBuffer &cloud, const PlyHeader &h) {
  const PlyElement *vertex = findVertex(h);
  if (!vertex) return;
  const auto declared = [&](const std::string &name) {
    for (const auto &p : vertex->properties)
      if (p.name == name) return true;
    return false;
  };
  PointLayout layout = cloud.layout();
  bool changed = false;
  for (const auto &[file_name, pcl_name] : {std::pair<const char *, const char *>{"nx", "normal_x"},
                                            {"ny", "normal_y"}, {"nz", "normal_z"}}) {
    if (!declared(file_name) || declared(pcl_name) || layout.find(file_name)) continue;
    for (auto &f : layout.fields)
      if (f.name == pcl_name) {
        f.name = file_name;
        changed = true;
      }
  }
  if (changed) relayout(cloud, std::move(layout));
}

}  // namespace

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
  PointBuffer cloud = readWithPcl(path, PclFormat::Ply);
  restorePlyTypes(cloud, header);
  restorePlyNames(cloud, header);
  return cloud;
}

}  // namespace hpds::pcl_detail
