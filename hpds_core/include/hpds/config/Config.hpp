// HpdsConfig: every tunable of the sampler, the CLI and the ROS node, with its default.
//
// Contract
// - Plain data with in-class defaults; `config/hpds.yaml` documents the same keys and values (a test keeps them equal).
// - No YAML, ROS or PCL here: loaders live at the edges (ConfigYaml.hpp) and all call `validateConfig`.
// - Units: metres, seconds, Hertz.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace hpds {

enum class InsertionOrder { Random, Input, Sphericity, SurfaceVariation };
enum class Mode { Scan, Map };

[[nodiscard]] const char *toString(InsertionOrder order);
[[nodiscard]] const char *toString(Mode mode);
/// Parses "random" | "input" | "sphericity" | "surface_variation"; throws std::invalid_argument naming `key`.
[[nodiscard]] InsertionOrder parseInsertionOrder(const std::string &text, const std::string &key = "order.type");
/// Parses "scan" | "map"; throws std::invalid_argument naming `key`.
[[nodiscard]] Mode parseMode(const std::string &text, const std::string &key = "mode");

/// Level-0 cell edge [m] when hierarchy.cell_size is 0 and the output is not chosen by a spacing; also the largest
/// level-0 cell a derived cell size gets (see resolveOutput).
inline constexpr double kDefaultCellSize = 4.0;

struct HierarchyConfig {
  double cell_size = 0.0;  ///< [m] edge of a level-0 cell; level D has edge cell_size / 2^D and radius sqrt(3)/2 of it;
                           ///< 0 = derived: the output level's radius is output.spacing exactly (see resolveOutput)
  int max_depth = 8;       ///< finest level that may be built, 0..21 (points are only inserted down to the levels
                           ///< that are read: Pipeline::buildDepth)
};

struct OrderConfig {
  InsertionOrder type = InsertionOrder::Random;  ///< order in which a frame's points are offered to the hierarchy
  std::uint64_t seed = 0;                        ///< seed of the random order (same input + seed = same output)
  double feature_radius = 0.0;  ///< [m] PCA radius of the feature orders; 0 = twice r_D of the output level
};

struct OutputConfig {
  int level = -1;        ///< output level D (levels 0..D are output); -1 = derive from `spacing`, else max_depth
  double spacing = 0.1;  ///< [m] with level = -1: the output's Poisson radius (see resolveOutput); 0 = unused
  bool float64_xyz = false;  ///< output x y z as float64 (always so when the input's x y z are float64)
  bool float32_xyz = false;  ///< output x y z as float32 even when the input's are float64; not with float64_xyz
};

struct NormalConfig {
  bool enabled = true;     ///< estimate PCA normals and curvature for the output samples
  double radius = 0.0;     ///< [m] neighbourhood radius; 0 = 2.5 * r_D of the output level (when k = 0)
  int k = 0;               ///< k nearest neighbours (within `radius` when it is > 0); 0 = radius only
  int min_neighbors = 5;   ///< fewer neighbours (the sample included) -> invalid normal (NaN, counted)
  int neighborhood_level_offset = 2;  ///< also take samples of levels L+1..L+offset inside the footprint (noise
                                      ///< averaging; clamped to max_depth; scan mode: the frame's point centroids
                                      ///< per cell of level L+offset instead); 0 = levels 0..L only
  double max_growth = 8.0;  ///< grow a line-like (one scan line) or too small neighbourhood up to this factor; 1 = off
  bool covariances = false;  ///< also output a GICP covariance per sample (cov_xx..cov_zz) from its normal; needs enabled
  double covariance_epsilon = 0.001;  ///< covariance's variance along the normal, the in-plane one being 1; 1e-4..1
  double covariance_line_ratio = 0.2;  ///< l1 / l2 of the normal's neighbourhood below this -> identity covariance
  int covariance_k = 30;  ///< a plane covariance's normal: PCA of the k nearest output samples; 0 = the output normal
};

struct MapConfig {
  double evict_distance = 100.0;  ///< [m] map mode: drop samples farther than this from the latest sensor; 0 = never
  std::uint64_t max_samples = 10000000;  ///< map mode: cap on stored samples, farthest from the sensor go first; 0 = none
  int keep_depth = -1;  ///< map mode: also build and keep levels down to this one (<= max_depth); -1 = only the
                        ///< levels the outputs read (Pipeline::buildDepth)
};

struct InputConfig {
  bool skip_zero_points = true;  ///< drop exact (0,0,0) points, which drivers emit for no-return beams
  double min_range = 0.0;        ///< [m] drop points closer than this to the sensor; 0 = keep all
  double max_range = 0.0;        ///< [m] drop points farther than this from the sensor; 0 = keep all
};

struct HpdsConfig {
  Mode mode = Mode::Scan;  ///< scan: each frame sampled on its own; map: one persistent hierarchy in the fixed frame
  HierarchyConfig hierarchy;
  OrderConfig order;
  OutputConfig output;
  NormalConfig normals;
  MapConfig map;
  InputConfig input;
  int threads = 1;  ///< worker threads (normals, feature orders); 0 = all cores
};

/// Throws std::invalid_argument whose message starts with the offending key (e.g. "hierarchy.max_depth: ...").
void validateConfig(const HpdsConfig &config);

/// How a loader ends. kNow: validateConfig on the result (every loader's default). kByCaller: the keys, their types
/// and their syntax are checked but not the values or their combination, for a caller that lays more settings over
/// the loaded config (command-line flags, a dict of overrides) and then validates the result itself, so that a file
/// whose combination only the overrides make valid (`normals: {enabled: false, covariances: true}` with `--normals`)
/// is judged with them.
enum class ConfigValidation { kNow, kByCaller };

/// The output level and the level-0 cell a config runs with, and why.
///  - output.level -1, output.spacing S > 0, hierarchy.cell_size 0 (derived): r_L = S. L is the largest level, at
///    most max_depth, with 2 S / sqrt(3) * 2^L <= kDefaultCellSize (else 0), and cell_size = 2 S / sqrt(3) * 2^L
///    (raised by an ulp or two if rounding put r_L below S), so the level-0 cell lies in (2, 4] m for S <= 3.4 m.
///  - output.level -1, spacing S > 0, cell_size fixed: the coarsest level with r_D <= S (levels halve from the cell,
///    so r_L lies in (S/2, S]), or max_depth when even its radius exceeds S (the reason says so).
///  - output.level D >= 0: level D; output.level -1 and spacing 0: max_depth. The cell is cell_size, or
///    kDefaultCellSize when cell_size is 0.
struct OutputResolution {
  double cell_size = kDefaultCellSize;  ///< [m] level-0 cell edge the hierarchy runs with (> 0)
  int level = 0;                        ///< output level L
  double radius = 0.0;                  ///< [m] r_L: output samples are at least this far apart
  double spacing_asked = 0.0;           ///< [m] output.spacing when it chose the level, else 0
  std::string reason;                   ///< one sentence for logs and --stats: how L and cell_size were chosen
};
[[nodiscard]] OutputResolution resolveOutput(const HpdsConfig &config);

/// What to do about points counted as out of key range under `config` (as the user gave it, before resolvedConfig):
/// how far from the origin the exact keys of level hierarchy.max_depth reach, and which settings widen that reach.
/// For warnings of the CLI, the node and the bindings, which must not advise a setting that cannot help.
[[nodiscard]] std::string keyRangeAdvice(const HpdsConfig &config);

/// resolveOutput(config).level.
[[nodiscard]] int resolveOutputLevel(const HpdsConfig &config);

/// The finer level the normals of output level `output_level` average (output_level +
/// normals.neighborhood_level_offset, clamped to hierarchy.max_depth), or -1 when they average none (normals off, an
/// offset of 0, or the output at max_depth).
[[nodiscard]] int normalsAveragingLevel(const HpdsConfig &config, int output_level);

/// `config` with hierarchy.cell_size and output.level set to resolveOutput's values (what a Pipeline runs with and a
/// map file records); every other key unchanged. Resolving a resolved config changes nothing.
[[nodiscard]] HpdsConfig resolvedConfig(const HpdsConfig &config);

/// Edge of a level-`depth` cell and the Poisson radius of that level, in metres.
[[nodiscard]] double cellEdge(double cell_size, int depth);
[[nodiscard]] double poissonRadius(double cell_size, int depth);

}  // namespace hpds
