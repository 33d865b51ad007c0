// YAML edge of HpdsConfig: load, overlay and dump, all driven by one key table in ConfigYaml.cpp.
//
// Contract
// - The YAML mirrors the struct: top-level `mode`, `threads` and one map per section
//   (`hierarchy`, `order`, `output`, `normals`, `map`, `input`); enums are their toString() names.
// - Strict: unknown keys, wrong types, quoted numbers, yes/no booleans and integers with a leading zero are errors,
//   never ignored. The ROS node's own top-level keys (`ros:` map, `diagnostic_period`) are validated exactly as the
//   node does (NodeConfig.hpp) and not kept, so that one file configures the node and the CLI alike and a file the
//   CLI accepts is never refused by the node.
// - Every error is std::invalid_argument whose message starts with the dotted key
//   ("hierarchy.max_depth: expected an integer, got 'abc'"); errors with no key start with "(document)"
//   (syntax errors, which carry yaml-cpp's line and column) or "config file '<path>'" (unreadable file).
// - Every loader finishes with validateConfig on the result, unless its caller asks to do that itself
//   (ConfigValidation::kByCaller).
// - yaml-cpp stays out of this header so callers (the CLI, the ROS node) need not see it.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "hpds/config/Config.hpp"

namespace hpds {

/// The most a config (file or text) may hold: real ones are a few kilobytes, and yaml-cpp needs a few hundred bytes
/// of memory per YAML node.
inline constexpr std::size_t kMaxConfigBytes = 256 * 1024;

/// The text of a config file: a regular file (not a device or FIFO) of at most kMaxConfigBytes; otherwise
/// std::invalid_argument "config file '<path>': <problem>".
[[nodiscard]] std::string readConfigFile(const std::string &path);

/// Reads the YAML file at `path` (readConfigFile) over the defaults; errors name `path`. An empty file gives the
/// defaults.
[[nodiscard]] HpdsConfig loadConfigFile(const std::string &path);
/// The same with the values left for the caller to validate (ConfigValidation::kByCaller) or not.
[[nodiscard]] HpdsConfig loadConfigFile(const std::string &path, ConfigValidation validation);

/// Same as loadConfigFile for YAML held in memory.
[[nodiscard]] HpdsConfig loadConfigString(const std::string &yaml_text);

/// Overlays the keys present in `yaml_text` onto `config` (absent keys keep their values) and validates the
/// result. Strong guarantee: on any error `config` is unchanged. `source` (a file path, "rosparam ~", ...) is
/// appended to error messages as " (in <source>)" when not empty.
void applyConfigYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source = "");
void applyConfigYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source,
                     ConfigValidation validation);

/// Complete YAML of every key in struct order; loading it back gives an equal struct (doubles are printed
/// with the shortest text that parses back to the same value).
[[nodiscard]] std::string dumpConfigYaml(const HpdsConfig &config);

/// Dotted names of every key ("mode", "hierarchy.cell_size", ..., "threads") in dump order, e.g. for a
/// caller that must pick the config keys out of a larger parameter namespace.
[[nodiscard]] std::vector<std::string> configKeys();

}  // namespace hpds
