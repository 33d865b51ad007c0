// ParamBridge: the node's private rosparams into a NodeConfig, through the same YAML loader as config files.
//
// Contract
// - Defaults, then the YAML file in ~config_file (if set), then every other private parameter, all through
//   applyNodeConfigYaml: the node accepts and refuses exactly what a config file does.
// - Throws std::invalid_argument naming the parameter ("parameter /hpds/hierarchy/max_depth: ...").
// - Reads the parameter server only; call from any thread that may use the node handle.
#pragma once

#include <ros/node_handle.h>

#include "hpds_node/NodeConfig.hpp"

namespace hpds_node {

[[nodiscard]] NodeConfig loadNodeConfigFromParams(const ros::NodeHandle &private_nh);

}  // namespace hpds_node
