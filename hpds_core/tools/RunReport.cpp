#include "RunReport.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "QualityIo.hpp"

namespace hpds::cli {

std::string roundingWarning(const PointBuffer &cloud, double output_radius, const OutputConfig &output,
                            double input_rounding) {
  // The two keys cannot both be set: advising float64 alone would end in a config error.
  const std::string key = output.float32_xyz
                              ? "output.float64_xyz: true instead of output.float32_xyz (--float64-xyz instead of "
                                "--float32-xyz)"
                              : "output.float64_xyz: true (--float64-xyz)";
  const std::string w = positionRoundingWarning(positionRounding(cloud), output_radius, key, input_rounding);
  return w.empty() ? w : "hpds: warning: " + w;
}

std::string evictionWarning(const HpdsConfig &config, std::uint64_t evicted, std::size_t remaining,
                            bool sensor_at_origin) {
  if (config.mode != Mode::Map || evicted == 0) return {};
  std::ostringstream w;
  w << "hpds: warning: " << evicted << " samples were evicted from the map (" << remaining
    << " remain): map.evict_distance (" << config.map.evict_distance
    << " m, 0 = off) drops, before each frame, those farther from its sensor position (the last frame's own "
       "samples stay, as far as the sensor reached) and map.max_samples ("
    << config.map.max_samples << ", 0 = no cap) caps the count, so the map written is what was left around the last "
    << "frame; give --evict-distance 0 --max-samples 0 to keep every sample";
  if (sensor_at_origin)
    w << " (no --poses: every frame's sensor was taken at the origin, so frames farther than map.evict_distance from "
         "it evicted each other; give --poses, or --evict-distance 0 for clouds already in one frame)";
  return w.str();
}

void stageJsonFile(std::optional<AtomicFile> &file, const std::string &path, const RunReport &report) {
  if (path.empty()) return;
  file.emplace(path);
  file->write(toJson(report));
  file->finish();
}

RunReport reportFor(const std::string &command, const Pipeline &pipeline) {
  RunReport r;
  r.command = command;
  r.mode = pipeline.config().mode;
  r.cell_size = pipeline.config().hierarchy.cell_size;
  r.max_depth = pipeline.config().hierarchy.max_depth;
  r.output_level = pipeline.outputLevel();
  r.output_radius = pipeline.outputResolution().radius;
  r.spacing_asked = pipeline.outputResolution().spacing_asked;
  r.output_reason = pipeline.outputResolution().reason;
  r.built_depth = pipeline.buildDepth();
  r.samples_per_level.assign(static_cast<std::size_t>(r.built_depth) + 1, 0);
  return r;
}

std::uint64_t countInvalidNormals(const PointBuffer &cloud) {
  const PointField *nx = cloud.layout().find("normal_x");
  if (!nx) return 0;
  std::uint64_t n = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) n += std::isnan(readAsDouble(cloud.record(i), *nx)) ? 1 : 0;
  return n;
}

std::uint64_t peakMemoryBytes() {
  rusage ru{};
  if (getrusage(RUSAGE_SELF, &ru) != 0) return 0;
  return static_cast<std::uint64_t>(ru.ru_maxrss) * 1024u;  // Linux reports kilobytes
}

std::string toJson(const RunReport &r) {
  std::ostringstream j;
  const FrameCounters &t = r.totals;
  j << "{\n";
  j << "  \"command\": \"" << r.command << "\",\n";
  j << "  \"mode\": \"" << toString(r.mode) << "\",\n";
  j << "  \"frames\": " << r.frames << ",\n";
  j << "  \"cell_size\": " << num(r.cell_size) << ",\n";
  j << "  \"max_depth\": " << r.max_depth << ",\n";
  j << "  \"output_level\": " << r.output_level << ",\n";
  j << "  \"output\": {\"spacing_asked\": " << (r.spacing_asked > 0.0 ? num(r.spacing_asked) : "null")
    << ", \"level\": " << r.output_level << ", \"radius\": " << num(r.output_radius)
    << ", \"cell_size\": " << num(r.cell_size) << ", \"reason\": " << jsonQuoted(r.output_reason) << "},\n";
  j << "  \"built_depth\": " << r.built_depth << ",\n";
  j << "  \"levels\": [";
  for (std::size_t d = 0; d < r.samples_per_level.size(); ++d)
    j << (d ? ", " : "") << "{\"level\": " << d << ", \"radius\": " << num(poissonRadius(r.cell_size, static_cast<int>(d)))
      << ", \"count\": " << r.samples_per_level[d] << "}";
  j << "],\n";
  j << "  \"points\": {\"input\": " << t.input << ", \"skipped_invalid\": " << t.skipped_invalid
    << ", \"skipped_zero\": " << t.skipped_zero << ", \"skipped_range\": " << t.skipped_range
    << ", \"out_of_range\": " << t.out_of_range << ", \"dropped_depth\": " << t.dropped_depth
    << ", \"accepted\": " << t.accepted << ", \"evicted\": " << t.evicted << "},\n";
  j << "  \"output_points\": " << r.output_points << ",\n";
  j << "  \"invalid_normals\": " << r.invalid_normals << ",\n";
  j << "  \"seconds\": {\"read\": " << num(r.seconds.read) << ", \"insert\": " << num(r.seconds.insert)
    << ", \"normals\": " << num(r.seconds.normals) << ", \"write\": " << num(r.seconds.write) << "},\n";
  j << "  \"hierarchy_memory_bytes\": " << r.hierarchy_bytes << ",\n";
  j << "  \"peak_memory_bytes\": " << peakMemoryBytes();
  for (const auto &[name, value] : r.extra) j << ",\n  \"" << name << "\": " << value;
  j << "\n";
  j << "}\n";
  return j.str();
}


std::string levelSummary(const RunReport &r) {
  std::ostringstream s;
  if (!r.output_reason.empty()) s << r.output_reason << "\n";
  s << "level  r_D [m]      samples     levels 0..D\n";
  std::uint64_t cumulative = 0;
  for (std::size_t d = 0; d < r.samples_per_level.size(); ++d) {
    cumulative += r.samples_per_level[d];
    char line[128];
    std::snprintf(line, sizeof line, "%5zu  %-11.6g  %10llu  %12llu%s\n", d,
                  poissonRadius(r.cell_size, static_cast<int>(d)), static_cast<unsigned long long>(r.samples_per_level[d]),
                  static_cast<unsigned long long>(cumulative), static_cast<int>(d) == r.output_level ? "  <- output" : "");
    s << line;
  }
  const FrameCounters &t = r.totals;
  s << "points: " << t.input << " in, " << t.accepted << " accepted, " << t.dropped_depth << " dropped past level "
    << r.built_depth << ", "
    << t.skipped_invalid << " NaN/Inf, " << t.skipped_zero << " no-return (0,0,0), " << t.skipped_range
    << " outside range limits, " << t.out_of_range << " beyond exact key range";
  if (t.evicted) s << ", " << t.evicted << " evicted";
  s << "\n";
  return s.str();
}

Progress::Progress(std::size_t total) : total_(total), tty_(::isatty(STDERR_FILENO) == 1) {}

void Progress::step(std::size_t done, const std::string &what) {
  if (!tty_ || total_ < 2) return;
  std::cerr << "\r\033[K[" << done << "/" << total_ << "] " << what << std::flush;
}

void Progress::finish() {
  if (tty_ && total_ >= 2) std::cerr << "\r\033[K" << std::flush;
}

std::string emptyOutputWarning(std::uint64_t output_points, const FrameCounters &t) {
  if (output_points > 0) return "";
  std::string w = "hpds: warning: the output holds no sample: ";
  if (t.input == 0) return w + "the inputs hold no point";
  w += "of " + std::to_string(t.input) + " input points";
  const std::pair<std::uint64_t, const char *> reasons[] = {
      {t.skipped_invalid, "NaN/Inf"},
      {t.skipped_zero, "no-returns at (0,0,0) (input.skip_zero_points)"},
      {t.skipped_range, "outside input.min_range/max_range"},
      {t.out_of_range, "beyond the exact key range"},
      {t.evicted, "samples evicted from the map (map.evict_distance, map.max_samples)"}};
  const char *sep = ": ";
  for (const auto &[count, what] : reasons)
    if (count > 0) {
      w += sep + std::to_string(count) + " " + what;
      sep = ", ";
    }
  return w;
}

}  // namespace hpds::cli
