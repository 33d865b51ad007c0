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

struct HierarchyConfig {
  double cell_size = 4.0;  ///< [m] edge of a level-0 cell; level D has edge cell_size / 2^D and radius sqrt(3)/2 of it
  int max_depth = 8;       ///< finest level, 0..21; points rejected at every level are dropped and counted
};

struct OrderConfig {
  InsertionOrder type = InsertionOrder::Random;  ///< order in which a frame's points are offered to the hierarchy
  std::uint64_t seed = 0;                        ///< seed of the random order (same input + seed = same output)
  double feature_radius = 0.0;  ///< [m] PCA radius of the feature orders; 0 = twice r_D of the output level
};

struct OutputConfig {
  int level = -1;        ///< output level D (levels 0..D are output); -1 = derive from `spacing`, else max_depth
  double spacing = 0.0;  ///< [m] with level = -1: the coarsest level with r_D <= spacing; 0 = unused
};

struct NormalConfig {
  bool enabled = false;    ///< estimate PCA normals and curvature for the output samples
  double radius = 0.0;     ///< [m] neighbourhood radius; 0 = 2.5 * r_D of the output level (when k = 0)
  int k = 0;               ///< k nearest neighbours (within `radius` when it is > 0); 0 = radius only
  int min_neighbors = 5;   ///< fewer neighbours (the sample included) -> invalid normal (NaN, counted)
  int neighborhood_level_offset = 2;  ///< also take samples of levels L+1..L+offset inside the footprint (noise
                                      ///< averaging; clamped to max_depth); 0 = levels 0..L only
  double max_growth = 8.0;  ///< grow a line-like (one scan line) or too small neighbourhood up to this factor; 1 = off
};

struct MapConfig {
  double evict_distance = 0.0;  ///< [m] map mode: drop samples farther than this from the latest sensor; 0 = never
  std::uint64_t max_samples = 0;  ///< map mode: cap on stored samples, farthest from the sensor go first; 0 = none
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

/// Output level implied by `config.output` (level, or spacing, or max_depth).
[[nodiscard]] int resolveOutputLevel(const HpdsConfig &config);

/// Edge of a level-`depth` cell and the Poisson radius of that level, in metres.
[[nodiscard]] double cellEdge(double cell_size, int depth);
[[nodiscard]] double poissonRadius(double cell_size, int depth);

}  // namespace hpds
