#include "hpds/io/SamplingRecord.hpp"

#include <charconv>
#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <system_error>

#include "FileAccess.hpp"

namespace hpds {

namespace {

constexpr std::string_view kPrefix = "comment hpds sampling";

// Locale-free both ways: a program that set LC_NUMERIC to a decimal comma must still write and read "0.5".
std::string shortest(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 17);
  return std::string(buf, r.ptr);
}

template <typename T>
bool parseWhole(std::string_view text, T &value) {
  const auto r = std::from_chars(text.data(), text.data() + text.size(), value);
  return r.ec == std::errc() && r.ptr == text.data() + text.size();
}

// Empty when `r` is one a reader takes.
std::string rangeProblem(const SamplingRecord &r) {
  if (!(r.cell_size > 0.0 && r.cell_size <= 1e6) || r.max_depth < 0 || r.max_depth > 21 || r.output_level < 0 ||
      r.output_level > r.max_depth)
    return "cell_size must be in (0, 1e6], max_depth in 0..21, output_level in 0..max_depth";
  return {};
}

SamplingRecord parseRecord(const std::string &path, const std::string &line) {
  using io_detail::fail;
  std::istringstream words(line.substr(kPrefix.size()));
  std::string key[3], value[3], extra;
  for (int i = 0; i < 3; ++i) words >> key[i] >> value[i];
  words >> extra;
  SamplingRecord r;
  if (key[0] != "cell_size" || key[1] != "max_depth" || key[2] != "output_level" || !extra.empty() ||
      !parseWhole(value[0], r.cell_size) || !parseWhole(value[1], r.max_depth) ||
      !parseWhole(value[2], r.output_level))
    fail(path, "malformed header line " + io_detail::quote(line) +
                   ": expected 'comment hpds sampling cell_size C max_depth M output_level L'");
  if (const std::string problem = rangeProblem(r); !problem.empty())
    fail(path, "header line " + io_detail::quote(line) + " is out of range: " + problem);
  return r;
}

}  // namespace

std::string samplingRecordLine(const SamplingRecord &record) {
  // What no reader takes is not written.
  if (const std::string problem = rangeProblem(record); !problem.empty())
    throw std::invalid_argument("sampling record (cell_size " + shortest(record.cell_size) + ", max_depth " +
                                std::to_string(record.max_depth) + ", output_level " +
                                std::to_string(record.output_level) + ") is out of range: " + problem);
  return std::string(kPrefix) + " cell_size " + shortest(record.cell_size) + " max_depth " +
         std::to_string(record.max_depth) + " output_level " + std::to_string(record.output_level);
}

std::optional<SamplingRecord> readSamplingRecord(const std::string &path) {
  using io_detail::fail;
  io_detail::requireRegularFile(path);
  const io_detail::FilePtr f(std::fopen(path.c_str(), "rb"));
  if (!f) fail(path, "cannot open for reading");
  std::string line;
  std::size_t read = 0;
  bool first = true;
  std::optional<SamplingRecord> record;
  for (int c; (c = std::fgetc(f.get())) != EOF;) {
    if (++read > io_detail::kMaxHeaderBytes) fail(path, "PLY header does not end within 1 MiB");
    if (c != '\n') {
      line.push_back(static_cast<char>(c));
      if (first && line.size() > 4) return std::nullopt;  // not "ply" (a PCD, a KITTI .bin): no PLY header to read
      continue;
    }
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (first && line != "ply") return std::nullopt;
    first = false;
    if (line == "end_header") return record;
    if (line.compare(0, kPrefix.size(), kPrefix) == 0 &&
        (line.size() == kPrefix.size() || line[kPrefix.size()] == ' ')) {
      if (record) fail(path, "two 'comment hpds sampling' lines in the header");
      record = parseRecord(path, line);
    }
    line.clear();
  }
  if (std::ferror(f.get())) fail(path, "read error");
  // No end_header: not a PLY file the readers take; they say so when it is read as a cloud.
  return std::nullopt;
}

}  // namespace hpds
