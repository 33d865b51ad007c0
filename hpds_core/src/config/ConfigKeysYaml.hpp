// The HpdsConfig keys of a YAML document alone (ConfigYaml's key table), for NodeConfig, which reads the rest of a
// config file (`ros:`, diagnostic_period) and hands the remaining keys here. A `ros:` map is only shape-checked.
// Public callers go through applyConfigYaml, which reads the whole file. Also ConfigYaml's rules for single values,
// so that NodeConfig words and refuses the ros.* values exactly as the other keys.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>

#include "hpds/config/Config.hpp"

namespace hpds {

/// applyConfigYaml's contract for the HpdsConfig keys (strong guarantee, errors start with the dotted key).
void applyConfigKeysYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source,
                         ConfigValidation validation = ConfigValidation::kNow);

namespace yaml_node {
/// What a node is, for messages: "a map", "nothing (null)", "the quoted string '4.0'", "'abc'".
[[nodiscard]] std::string describeNode(const YAML::Node &node);
/// yaml-cpp tags quoted scalars "!".
[[nodiscard]] bool isQuotedScalar(const YAML::Node &node);
/// Throws std::invalid_argument "<key>: has the YAML tag ..." for an explicit tag (!!str, !custom).
void refuseExplicitTag(const YAML::Node &node, const std::string &key);
/// The text of an untagged scalar, else std::invalid_argument "<key>: expected <expected>, got ...".
[[nodiscard]] const std::string &plainScalarText(const YAML::Node &node, const std::string &key, const char *expected);
}  // namespace yaml_node

}  // namespace hpds
