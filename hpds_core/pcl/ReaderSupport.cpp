#include "ReaderSupport.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <system_error>

namespace hpds::pcl_detail {

namespace fs = std::filesystem;

std::string lowerExtension(const std::string &path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

std::optional<std::uint64_t> nextNonBlankLine(std::istream &in) {
  std::string line;
  for (std::uint64_t n = 1; std::getline(in, line); ++n)
    if (std::any_of(line.begin(), line.end(), [](char c) { return !isSpace(c); })) return n;
  return std::nullopt;
}

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


bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

// Any decimal number, including nan/inf (PCL writes "nan" for invalid points). Locale-independent.
std::optional<double> parseNumber(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return std::nullopt;
  double value = 0.0;
  const auto res = std::from_chars(token.data(), token.data() + token.size(), value);
  if (res.ptr != token.data() + token.size()) return std::nullopt;
  if (res.ec == std::errc::result_out_of_range)  // saturates: still a number, as the readers take it
    return token.front() == '-' ? -INFINITY : INFINITY;
  if (res.ec != std::errc()) return std::nullopt;
  return value;
}

bool isNumber(std::string_view token) { return parseNumber(token).has_value(); }

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

}  // namespace hpds::pcl_detail
