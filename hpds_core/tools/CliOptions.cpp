#include "CliOptions.hpp"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <sstream>

#include "hpds/config/ConfigYaml.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/io/SamplingRecord.hpp"

namespace hpds::cli {

namespace {

std::string text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace

CLI::Validator finiteIn(double lo, double hi) {
  const std::string range = "a finite number in [" + text(lo) + ", " + text(hi) + "]";
  return CLI::Validator(
      [=](std::string &value) -> std::string {
        double v = 0.0;
        const char *begin = value.c_str();
        char *end = nullptr;
        v = std::strtod(begin, &end);
        if (end == begin || *end != '\0' || !std::isfinite(v) || v < lo || v > hi)
          return "must be " + range + ", got '" + value + "'";
        return "";
      },
      range);
}

CLI::Validator positiveUpTo(double hi) {
  // The help said [0, 1e6] for lengths that 0 cannot be; refused here, 0 is a usage error like any other bad value.
  const std::string range = "a finite number in (0, " + text(hi) + "]";
  return CLI::Validator(
      [=](std::string &value) -> std::string {
        const char *begin = value.c_str();
        char *end = nullptr;
        const double v = std::strtod(begin, &end);
        if (end == begin || *end != '\0' || !std::isfinite(v) || !(v > 0.0) || v > hi)
          return "must be " + range + ", got '" + value + "'";
        return "";
      },
      range);
}

CLI::Validator integerIn(long long lo, long long hi) {
  const std::string range = "an integer in " + std::to_string(lo) + ".." + std::to_string(hi);
  return CLI::Validator(
      [=](std::string &value) -> std::string {
        long long v = 0;
        const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
        if (ec != std::errc() || end != value.data() + value.size() || v < lo || v > hi)
          return "must be " + range + ", got '" + value + "'";
        return "";
      },
      range);
}

CLI::Validator unsigned64() {
  return CLI::Validator(
      [](std::string &value) -> std::string {
        std::uint64_t v = 0;
        const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
        if (ec != std::errc() || end != value.data() + value.size())
          return "must be an integer in 0..18446744073709551615, got '" + value + "'";
        return "";
      },
      "0..2^64-1");
}

CLI::Validator nonEmptyPath() {
  return CLI::Validator(
      [](std::string &value) -> std::string {
        return value.empty() ? "must be a path, got an empty string (an unset shell variable?)" : "";
      },
      "PATH");
}

CLI::Validator fileNamePrefix() {
  return CLI::Validator(
      [](std::string &value) -> std::string {
        if (value.find_first_of("/\\") == std::string::npos && value != "." && value != "..") return "";
        return "must be a file-name prefix without '/', '\\' or '..', got '" + value +
               "' (the files are written into the -o folder; choose another folder with -o)";
      },
      "NAME");
}

void addSamplingOptions(CLI::App &app, SamplingOptions &o) {
  app.add_option("--config", o.config_file, "YAML config (see config/hpds.yaml); flags override it");
  // Each flag is checked where it is parsed, so that a bad value is a bad command line (exit 2) naming the flag,
  // as for every other option: it was exit 1 naming the config key the flag sets (hierarchy.max_depth for
  // --max-depth 22). The config's own checks still run on the result.
  app.add_option("--cell-size", o.cell_size, "[m] level-0 cell edge, fixed (hierarchy.cell_size; default: derived "
                                             "from the spacing)")
      ->check(finiteIn(0.0, 1e6));
  app.add_option("--max-depth", o.max_depth, "finest level 0..21 (hierarchy.max_depth)")->check(integerIn(0, 21));
  auto *lvl = app.add_option("--level", o.level, "write levels 0..D (output.level)")->check(integerIn(0, 21));
  auto *sp = app.add_option("--spacing", o.spacing,
                            "[m] output radius: samples at least S apart; exactly S unless --cell-size fixes the cell, "
                            "then the coarsest level with r_D <= S (output.spacing)")
                ->check(positiveUpTo(1e6));
  lvl->excludes(sp);
  // Every occurrence kept, so that the config's value stays unless one of the two is given, and both together are
  // refused (a count would add them up to nothing).
  app.add_flag("--normals,!--no-normals", o.normals_flags,
               "estimate PCA normals and curvature, or not (normals.enabled; default: the config's, on)");
  app.add_flag("--covariances", o.covariances,
               "also write GICP covariances cov_xx..cov_zz (normals.covariances; implies --normals)");
  app.add_flag("--float64-xyz", o.float64_xyz,
               "write x y z as float64 (output.float64_xyz): for georeferenced coordinates");
  app.add_flag("--float32-xyz", o.float32_xyz,
               "write x y z as float32 even from float64 input (output.float32_xyz): for float32-only readers");
  app.add_option("--order", o.order, "random | input | sphericity | surface_variation (order.type)")
      ->check(CLI::IsMember({"random", "input", "sphericity", "surface_variation"}));
  app.add_option("--seed", o.seed, "seed of the random order (order.seed)")->check(unsigned64());
  app.add_option("--mode", o.mode, "scan | map (mode)")->check(CLI::IsMember({"scan", "map"}));
  app.add_option("--evict-distance", o.evict_distance,
                 "[m] map mode: before each frame, drop samples farther than this from its sensor, 0 = never "
                 "(map.evict_distance)")
      ->check(finiteIn(0.0, 1e9));
  app.add_option("--max-samples", o.max_samples,
                 "map mode: cap on stored samples, the farthest from the sensor go first, 0 = none (map.max_samples)")
      ->check(unsigned64());
  app.add_option("--threads", o.threads, "worker threads, 0 = all cores (threads)")->check(integerIn(0, 1024));
}

HpdsConfig resolveConfig(const SamplingOptions &o) {
  // The file's values are judged with the flags over them: `--normals` mends a file's normals.enabled: false
  // beside its covariances: true, which the file alone could not take.
  HpdsConfig c = o.config_file.empty() ? HpdsConfig{} : loadConfigFile(o.config_file, ConfigValidation::kByCaller);
  if (o.cell_size) c.hierarchy.cell_size = *o.cell_size;
  if (o.max_depth) c.hierarchy.max_depth = *o.max_depth;
  if (o.level) {
    c.output.level = *o.level;
  } else if (o.spacing) {
    c.output.level = -1;
    c.output.spacing = *o.spacing;
  }
  std::optional<bool> normals;
  for (const std::string &flag : o.normals_flags) {
    const bool on = CLI::detail::to_flag_value(flag) > 0;
    if (normals && *normals != on)
      throw CLI::ValidationError("--normals and --no-normals contradict each other: give one of them");
    normals = on;
  }
  if (normals) c.normals.enabled = *normals;
  if (o.covariances && normals && !*normals)
    throw CLI::ValidationError("--covariances needs normals: it cannot go with --no-normals");
  // Flags override the config: --no-normals asks for no normals, and a covariance is built from one, so the config's
  // covariances go too rather than the run failing on a key the user did not touch on this command line.
  if (normals && !*normals && c.normals.covariances && !o.covariances) {
    c.normals.covariances = false;
    std::cerr << "hpds: warning: --no-normals also turns off normals.covariances: true of --config '" << o.config_file
              << "' (a covariance is built from the sample's normal); the output has neither\n";
  }
  if (o.covariances) c.normals.enabled = c.normals.covariances = true;
  if (o.float64_xyz && o.float32_xyz)
    throw CLI::ValidationError("--float64-xyz and --float32-xyz contradict each other: give one of them");
  // A flag overrides the config's choice of type, whichever of the two keys the config set.
  if (o.float64_xyz || o.float32_xyz) {
    c.output.float64_xyz = o.float64_xyz;
    c.output.float32_xyz = o.float32_xyz;
  }
  if (o.order) c.order.type = parseInsertionOrder(*o.order, "--order");
  if (o.seed) c.order.seed = *o.seed;
  if (o.mode) c.mode = parseMode(*o.mode, "--mode");
  if (o.evict_distance) c.map.evict_distance = *o.evict_distance;
  if (o.max_samples) c.map.max_samples = *o.max_samples;
  if ((o.evict_distance || o.max_samples) && c.mode != Mode::Map)
    std::cerr << "hpds: warning: --evict-distance and --max-samples bound a map: scan mode (each frame on its own) "
                 "ignores them; give --mode map for a map\n";
  if (o.threads) c.threads = *o.threads;
  try {
    validateConfig(c);
  } catch (const std::invalid_argument &e) {
    if (o.config_file.empty()) throw;
    throw std::invalid_argument(std::string(e.what()) + " (in " + o.config_file + ", with the flags over it)");
  }
  return c;
}

void addCellSizeOptions(CLI::App &app, CellSizeOptions &o, bool depth_bounds_keys) {
  auto *cell = app.add_option("--cell-size", o.cell_size,
                              "[m] level-0 cell edge the sampling was made with (default: the one its header "
                              "records, as hpds sample and replay write it)")
                   ->check(positiveUpTo(1e6));
  auto *spacing = app.add_option("--spacing", o.spacing,
                                 "[m] or: the --spacing (output.spacing) the sampling was made with, the cell derived "
                                 "from it as hpds sample does when no cell size is fixed")
                      ->check(positiveUpTo(1e6));
  auto *depth = app.add_option("--max-depth", o.max_depth,
                               depth_bounds_keys
                                   ? "the hierarchy.max_depth the sampling was made with: with --spacing it "
                                     "derives the cell; --input points 2^30 - 8 cells of that level or more from "
                                     "the origin were never inserted and are not checked for coverage (with "
                                     "--cell-size and no --max-depth: the deeper of 8 and the sampling's deepest "
                                     "level; with neither flag, the one its header records)"
                                   : "with --spacing: the hierarchy.max_depth of the sampling")
                    ->capture_default_str()
                    ->check(integerIn(0, 21));
  cell->excludes(spacing);
  if (!depth_bounds_keys) depth->needs(spacing);
}

namespace {
HpdsConfig spacingConfig(const CellSizeOptions &o) {
  HpdsConfig c;
  c.hierarchy.cell_size = 0.0;
  c.hierarchy.max_depth = o.max_depth;
  c.output.level = -1;
  c.output.spacing = *o.spacing;
  return c;
}
}  // namespace

int deepestLevelFor(const CellSizeOptions &o) {
  if (o.recorded_level) return *o.recorded_level;
  if (o.cell_size || !o.spacing) return -1;
  return resolveOutput(spacingConfig(o)).level;
}

namespace {
// The cell --cell-size or --spacing [--max-depth] gives (one of the two is set).
double cellSizeOfFlags(const CellSizeOptions &o) {
  if (o.cell_size) {
    if (!(*o.cell_size > 0.0)) throw std::invalid_argument("--cell-size: must be > 0");
    return *o.cell_size;
  }
  const HpdsConfig c = spacingConfig(o);
  if (!(*o.spacing > 0.0)) throw std::invalid_argument("--spacing: must be > 0");
  validateConfig(c);
  return resolveOutput(c).cell_size;
}
}  // namespace

SamplingRecord samplingRecordOf(const Pipeline &pipeline) {
  return {pipeline.hierarchy().cellSize(), pipeline.hierarchy().maxDepth(), pipeline.outputLevel()};
}

double resolveSamplingCell(CellSizeOptions &o, const std::string &sampling, bool max_depth_given) {
  const std::optional<SamplingRecord> record = readSamplingRecord(sampling);
  if (!o.cell_size && !o.spacing) {
    if (!record)
      throw std::invalid_argument("--cell-size or --spacing is required: '" + sampling +
                                  "' does not record the cell it was sampled with (written by another tool or an "
                                  "older hpds); give the --cell-size, or the --spacing and --max-depth, of its run");
    o.cell_size = record->cell_size;
    if (!max_depth_given) o.max_depth = record->max_depth;
    o.recorded_level = record->output_level;
    return record->cell_size;
  }
  const double given = cellSizeOfFlags(o);
  if (!record) return given;
  const bool same_cell = std::abs(given - record->cell_size) <= 1e-12 * record->cell_size;
  const bool same_depth = !max_depth_given || o.max_depth == record->max_depth;
  if (!same_cell || !same_depth)
    std::cerr << "hpds: warning: '" << sampling << "' was sampled with cell size " << record->cell_size
              << " m and max_depth " << record->max_depth << " (its header says so), but is checked with cell size "
              << given << " m" << (max_depth_given ? " and max_depth " + std::to_string(o.max_depth) : std::string())
              << " as given; leave out --cell-size, --spacing and --max-depth to use the recorded ones\n";
  return given;
}

std::vector<Eigen::Isometry3d> readPosesOption(const std::string &path) {
  PoseCorrection correction;
  std::vector<Eigen::Isometry3d> poses = readKittiPoses(path, correction);
  if (const std::string w = poseCorrectionWarning(path, correction); !w.empty()) std::cerr << "hpds: warning: " << w << "\n";
  return poses;
}

}  // namespace hpds::cli
