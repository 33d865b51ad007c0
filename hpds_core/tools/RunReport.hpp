// What a run reports: the --stats JSON and the per-level summary printed on stdout, plus terminal progress.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hpds/io/AtomicFile.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds::cli {

struct StageSeconds {
  double read = 0.0, insert = 0.0, normals = 0.0, write = 0.0;
};

struct RunReport {
  std::string command;  ///< "sample", "replay"
  Mode mode = Mode::Scan;
  std::size_t frames = 0;
  double cell_size = 0.0;
  int max_depth = 0;
  int output_level = 0;
  double output_radius = 0.0;  ///< [m] r of the output level
  double spacing_asked = 0.0;  ///< [m] output.spacing as given (0 = none)
  std::string output_reason;   ///< how the output level and cell were chosen (OutputResolution::reason)
  int built_depth = 0;  ///< deepest level built (Pipeline::buildDepth)
  std::vector<std::uint64_t> samples_per_level;  ///< levels 0..built_depth (map: in the map; scan: summed over frames)
  FrameCounters totals;
  std::uint64_t output_points = 0;
  std::uint64_t invalid_normals = 0;
  std::uint64_t hierarchy_bytes = 0;
  StageSeconds seconds;
  /// Further top-level members a command adds (name, JSON value text), e.g. replay's message counts.
  std::vector<std::pair<std::string, std::string>> extra;
};

/// A report on a run of `pipeline` (command "sample", "replay"): its mode, hierarchy, output level and built depth,
/// and a zero count for each level built.
[[nodiscard]] RunReport reportFor(const std::string &command, const Pipeline &pipeline);

/// Points of `cloud` whose normal_x is NaN (no valid normal); 0 when it has no normals.
[[nodiscard]] std::uint64_t countInvalidNormals(const PointBuffer &cloud);

/// Peak resident set size of this process in bytes (getrusage), 0 if unknown.
[[nodiscard]] std::uint64_t peakMemoryBytes();

/// A warning line (empty when there is nothing to say) when `cloud`'s float32 x y z round its positions by more than
/// 1 % of the output radius: georeferenced coordinates, which want output.float64_xyz (`output` says whether the
/// run asked for float32), unless the inputs' own float32 x y z (`input_rounding`, positionRounding of the inputs,
/// 0 when unknown) already lost those digits: see positionRoundingWarning.
[[nodiscard]] std::string roundingWarning(const PointBuffer &cloud, double output_radius, const OutputConfig &output,
                                          double input_rounding = 0.0);

/// A warning line (empty when `output_points` > 0) for a run that wrote no sample: why its input points gave none
/// (all NaN, no-returns, out of range), which exit code 0 and a count of 0 would not say.
[[nodiscard]] std::string emptyOutputWarning(std::uint64_t output_points, const FrameCounters &totals);

/// A warning line (empty when nothing was evicted) for a map-mode run whose map lost samples to map.evict_distance
/// or map.max_samples: the map it writes is then only what was left around the last frame, which a run that wanted
/// the whole map would otherwise learn from a count at the end of the summary. `sensor_at_origin`: the frames had no
/// poses, so the distance was measured from the fixed frame's origin.
[[nodiscard]] std::string evictionWarning(const HpdsConfig &config, std::uint64_t evicted, std::size_t remaining,
                                          bool sensor_at_origin);

/// With `path` set: `file` holds the report's JSON (toJson) written and synced under its temporary name, to be
/// committed with the run's other outputs once all are written; with `path` empty, `file` stays empty.
void stageJsonFile(std::optional<AtomicFile> &file, const std::string &path, const RunReport &report);

/// JSON text of the report (per-level counts, skipped/dropped counts, "seconds": {read, insert, normals, write},
/// peak memory).
[[nodiscard]] std::string toJson(const RunReport &report);

/// The text printed after a run: how the output level was chosen, then a table of level, r_D, samples, cumulative
/// union count.
[[nodiscard]] std::string levelSummary(const RunReport &report);

/// "\r[3/10] name" on stderr when stderr is a terminal; silent otherwise (logs and pipes stay clean).
class Progress {
 public:
  explicit Progress(std::size_t total);
  void step(std::size_t done, const std::string &what);
  void finish();

 private:
  std::size_t total_;
  bool tty_;
};

}  // namespace hpds::cli
