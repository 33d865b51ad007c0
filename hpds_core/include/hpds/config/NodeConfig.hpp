// A config file as a whole: the shared HpdsConfig plus the ROS node's own RosConfig (`ros:`), which the node and
// `hpds replay` use and which every other reader of a config (the CLI, hpds::loadConfig, applyConfigYaml) validates
// too, so that a file checked with `hpds sample --config` is never refused by the node. No ROS dependency.
//
// Contract
// - One YAML shape for every source: the keys of config/hpds.yaml (mode, hierarchy.*, ..., threads) at the top
//   level, node-only keys under `ros:`. Private rosparams (~hierarchy/cell_size, ~ros/fixed_frame, ...) are turned
//   into the same YAML and go through the same loader, so the node and the CLI accept and refuse the same values.
// - HpdsConfig keys go through the strict key table of ConfigYaml (unknown keys, wrong types, quoted numbers are
//   errors) and validateConfig; `ros:` keys and `diagnostic_period` are parsed here with the same strictness. Every error is std::invalid_argument
//   starting with the dotted key ("ros.tf_timeout: ...", "hierarchy.max_depth: ...") and ending with
//   " (in <source>)".
// - Strong guarantee: on error the NodeConfig passed in is unchanged.
// - Frame ids are stored without a leading '/', which tf2 refuses.
#pragma once

#include <string>
#include <vector>

#include "hpds/config/Config.hpp"

namespace hpds {

struct RosConfig {
  std::string fixed_frame = "map";  ///< map mode: frame of the persistent hierarchy and of every output
  std::string output_frame;         ///< scan mode: publish in this frame (tf at the stamp); empty = input frame
  /// The sensor's frame when clouds arrive in another one (registered clouds in the fixed frame, clouds in
  /// base_link): its origin at the stamp is the viewpoint (normals face it, input ranges and map eviction measure
  /// from it). Empty = the cloud's own frame.
  std::string sensor_frame;
  double tf_timeout = 0.1;          ///< [s] wall time to wait for a transform before dropping the frame, >= 0
  double local_map_radius = 50.0;   ///< [m] map mode: ~local_map holds output-level samples within this of the sensor
  double local_map_rate = 1.0;      ///< [Hz] map mode: ~local_map at most this often (frame stamps); 0 = never
  std::vector<int> publish_levels;  ///< levels D that get their own ~level_<D> topic (samples of level D only)
  int queue_size = 1;               ///< frames waiting to be processed; when full the oldest is dropped (counted)
  // Map persistence (node only; `hpds replay` ignores these three).
  std::string map_file;              ///< map mode: the file ~save_map writes and ~load_map reads
  bool load_map_on_start = false;    ///< map mode: start from map_file (absent: empty map, warned; unreadable: no start)
  bool save_map_on_shutdown = false;  ///< map mode: write the map to map_file when the node stops
};

struct NodeConfig {
  HpdsConfig hpds;
  RosConfig ros;
  /// [s] a config's top-level diagnostic_period (checked by checkDiagnosticPeriod), 0 when it sets none: the node
  /// reports at this period when its ~diagnostic_period parameter is not set.
  double diagnostic_period = 0.0;
};

/// Top-level keys that belong to the node's namespace but not to HpdsConfig or RosConfig: `config_file` (read by the
/// node itself, skipped here) and `diagnostic_period` (diagnostic_updater's; checked here with
/// checkDiagnosticPeriod, kept as NodeConfig::diagnostic_period), so that one YAML file serves `<rosparam load>`, ~config_file and
/// `hpds replay --config` alike.
[[nodiscard]] const std::vector<std::string> &nodeOnlyKeys();

/// Overlays the YAML `yaml_text` (top-level config keys and an optional `ros:` map) onto `config` and validates
/// the result (validateConfig + validateRosConfig), unless `validation` leaves both to the caller.
void applyNodeConfigYaml(const std::string &yaml_text, NodeConfig &config, const std::string &source,
                         ConfigValidation validation = ConfigValidation::kNow);

/// Reads a YAML file (same shape) over the defaults; errors name the path.
[[nodiscard]] NodeConfig loadNodeConfigFile(const std::string &path,
                                            ConfigValidation validation = ConfigValidation::kNow);

/// Throws std::invalid_argument naming the "ros.*" key for a bad value; publish_levels are checked against
/// hierarchy.max_depth, fixed_frame must be set in map mode, load_map_on_start / save_map_on_shutdown need map mode
/// and a non-empty map_file.
void validateRosConfig(const RosConfig &ros, const HpdsConfig &config);

/// validateRosConfig on the config file at `path` as the node reads it alone (its `ros:` section against its own keys
/// over the defaults), for readers that use only the sampling keys and judge those with their flags over them
/// (`hpds sample --config`, the tiled map build): a file they accept, the node accepts. Errors name `path`.
void validateRosSectionOfFile(const std::string &path);

/// A warning (empty when there is none; no "hpds: warning:" prefix) naming the `ros:` settings that `mode` does not
/// use although they differ from their defaults (scan mode: fixed_frame, local_map_*, map_file; map mode:
/// output_frame): a user who set fixed_frame: odom and left mode at scan got scan-mode output in the sensor frame,
/// without a word.
[[nodiscard]] std::string ignoredRosKeysWarning(const RosConfig &ros, Mode mode);

/// [s] How long the node's tf buffer keeps transforms: tf's default 10 s, or more when a frame can wait longer than
/// that before its pose is looked up (queue_size frames of up to a second each, then tf_timeout). With the default
/// a long queue behind a bag replayed faster than the node lost its oldest frames as no_transform, though their
/// transforms had arrived before them.
[[nodiscard]] double tfCacheSeconds(const RosConfig &ros);

/// `period` if it is a valid diagnostic_period ([s], in (0, 3600]); else std::invalid_argument "diagnostic_period: ...".
double checkDiagnosticPeriod(double period);

/// The `ros:` section with every key, e.g. for documentation or for logging what the node runs with.
[[nodiscard]] std::string dumpRosConfigYaml(const RosConfig &ros);

}  // namespace hpds
