// The node's settings: hpds::NodeConfig (hpds/config/NodeConfig.hpp), which lives in the core so that the CLI and
// the library validate a config file's `ros:` section exactly as the node does. Names kept for the node's code.
#pragma once

#include "hpds/config/NodeConfig.hpp"

namespace hpds_node {

using hpds::applyNodeConfigYaml;
using hpds::checkDiagnosticPeriod;
using hpds::dumpRosConfigYaml;
using hpds::loadNodeConfigFile;
using hpds::NodeConfig;
using hpds::nodeOnlyKeys;
using hpds::RosConfig;
using hpds::validateRosConfig;

}  // namespace hpds_node
