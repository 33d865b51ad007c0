// The HpdsConfig keys of a YAML document alone (ConfigYaml's key table), for NodeConfig, which reads the rest of a
// config file (`ros:`, diagnostic_period) and hands the remaining keys here. A `ros:` map is only shape-checked.
// Public callers go through applyConfigYaml, which reads the whole file.
#pragma once

#include <string>

#include "hpds/config/Config.hpp"

namespace hpds {

/// applyConfigYaml's contract for the HpdsConfig keys (strong guarantee, errors start with the dotted key).
void applyConfigKeysYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source);

}  // namespace hpds
