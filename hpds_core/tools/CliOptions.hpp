// Sampling options shared by `hpds sample` and `hpds replay`: one set of flags, applied over the config file in
// one place, validated by the same validateConfig as the YAML and the ROS node.
#pragma once

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/io/SamplingRecord.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace hpds::cli {

struct SamplingOptions {
  std::string config_file;
  std::optional<double> cell_size;
  std::optional<int> max_depth;
  std::optional<int> level;
  std::optional<double> spacing;
  std::vector<std::string> normals_flags;  // each --normals / --no-normals given, as CLI11 records it, in order
  bool covariances = false;
  bool float64_xyz = false;
  bool float32_xyz = false;
  std::optional<std::string> order;
  std::optional<std::uint64_t> seed;
  std::optional<std::string> mode;
  std::optional<double> evict_distance;
  std::optional<std::uint64_t> max_samples;
  std::optional<int> threads;
};

/// Flag values that are numbers within bounds: a finite number in [lo, hi]; an integer in [lo, hi]; an unsigned
/// 64-bit integer (a leading '-', which CLI11 would wrap to 2^64 - 1, is refused). Failures are CLI11 validation
/// errors naming the flag and the bound (exit status 2).
[[nodiscard]] CLI::Validator finiteIn(double lo, double hi);
/// A finite number in (0, hi]: a length that cannot be 0.
[[nodiscard]] CLI::Validator positiveUpTo(double hi);
[[nodiscard]] CLI::Validator integerIn(long long lo, long long hi);
[[nodiscard]] CLI::Validator unsigned64();
/// Path flags: an empty path (`-o ""`, an unset shell variable) is refused as a bad command line, not taken for a
/// folder or file named "". A file-name prefix (`render --prefix`) is refused with a path separator in it, so that
/// the files stay in their folder.
[[nodiscard]] CLI::Validator nonEmptyPath();
[[nodiscard]] CLI::Validator fileNamePrefix();

/// Registers --config, --cell-size, --max-depth, --level, --spacing, --normals/--no-normals, --covariances,
/// --float64-xyz, --float32-xyz, --order, --seed, --mode, --evict-distance, --max-samples, --threads.
void addSamplingOptions(CLI::App &app, SamplingOptions &options);

/// Defaults, then --config FILE, then the flags; throws std::invalid_argument naming the key on a bad value, and
/// CLI::ValidationError (a bad command line, exit status 2) on contradictory flags.
[[nodiscard]] HpdsConfig resolveConfig(const SamplingOptions &options);

/// The level-0 cell of a sampling to check: --cell-size C, or --spacing S [--max-depth M] for one written with a
/// derived cell (hierarchy.cell_size 0), derived as `hpds sample` derives it; neither for a sampling whose header
/// records its cell (resolveSamplingCell).
struct CellSizeOptions {
  std::optional<double> cell_size;
  std::optional<double> spacing;
  int max_depth = HierarchyConfig{}.max_depth;
  /// The output level the sampling's header records (resolveSamplingCell), when the cell came from there.
  std::optional<int> recorded_level;
};
/// `depth_bounds_keys`: --max-depth also goes with --cell-size, where it only bounds the coordinates the sampler
/// inserted (verify); else it needs --spacing.
void addCellSizeOptions(CLI::App &app, CellSizeOptions &options, bool depth_bounds_keys = false);
/// With --spacing: the output level its derived cell is made for (the deepest level such a sampling holds); with
/// a cell from the sampling's header: the output level recorded there; with --cell-size: -1 (any level).
[[nodiscard]] int deepestLevelFor(const CellSizeOptions &options);
/// The level-0 cell to check `sampling` with. hpds sample and replay record their cell, max_depth and output level
/// in the output's header (SamplingRecord). Without --cell-size and --spacing, `options` takes them from the header
/// of `sampling` (--max-depth, when `max_depth_given`, stays as given); a file without a record then throws
/// std::invalid_argument asking for --cell-size or --spacing. With either flag the cell is the flags' (--spacing's
/// derived as `hpds sample` derives it), and a record that disagrees is warned about on stderr. Throws
/// std::runtime_error (naming the file) on a malformed record, std::invalid_argument on a bad flag value.
[[nodiscard]] double resolveSamplingCell(CellSizeOptions &options, const std::string &sampling, bool max_depth_given);

/// What `pipeline`'s output was sampled with, for the header of the PLY it is written to.
[[nodiscard]] SamplingRecord samplingRecordOf(const Pipeline &pipeline);

/// The poses of a --poses file (readKittiPoses), its rotation corrections beyond rounding warned about on stderr
/// (poseCorrectionWarning).
[[nodiscard]] std::vector<Eigen::Isometry3d> readPosesOption(const std::string &path);

}  // namespace hpds::cli
