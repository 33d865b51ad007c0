// Node settings: the node YAML (config keys + ros:) goes through the shared loader; ros.* keys are as strict.
#include <gtest/gtest.h>

#include <fstream>
#include <tuple>

#include "hpds/config/ConfigYaml.hpp"
#include "hpds_node/NodeConfig.hpp"

namespace {

using hpds_node::NodeConfig;

std::string errorOf(const std::string &yaml) {
  NodeConfig c;
  try {
    hpds_node::applyNodeConfigYaml(yaml, c, "test");
  } catch (const std::invalid_argument &e) {
    return e.what();
  }
  return "";
}

TEST(NodeConfig, DefaultsAreValid) {
  NodeConfig c;
  EXPECT_NO_THROW(hpds_node::validateRosConfig(c.ros, c.hpds));
  EXPECT_NO_THROW(hpds_node::applyNodeConfigYaml("", c, "empty"));
  EXPECT_EQ(c.ros.fixed_frame, "map");
  EXPECT_EQ(c.ros.queue_size, 1);
}

// A frame can wait queue_size frames of processing and then tf_timeout before its pose is looked up: tf must still
// hold the transforms of its stamp then (with tf's 10 s, a queue of 1000 behind a bag played at 5x lost its oldest
// third as no_transform).
TEST(NodeConfig, TfCacheCoversTheLongestWaitOfAQueuedFrame) {
  hpds::RosConfig ros;
  EXPECT_EQ(hpds::tfCacheSeconds(ros), 10.0) << "the default queue keeps tf's default";
  ros.queue_size = 1000;
  ros.tf_timeout = 0.5;
  EXPECT_GE(hpds::tfCacheSeconds(ros), 1000 * 1.0 + 0.5);
  ros.queue_size = 30;
  EXPECT_GE(hpds::tfCacheSeconds(ros), 30.5);
  EXPECT_LE(hpds::tfCacheSeconds(ros), 60.0) << "no more than the wait needs";
}

TEST(NodeConfig, ConfigKeysAndRosSectionTogether) {
  NodeConfig c;
  hpds_node::applyNodeConfigYaml(R"(
mode: map
hierarchy: {cell_size: 2, max_depth: 6}
normals:
  enabled: true
ros:
  fixed_frame: /odom
  output_frame: ""
  sensor_frame: /velodyne
  tf_timeout: 0.25
  local_map_radius: 30
  local_map_rate: 2.5
  publish_levels: [1, 3]
  queue_size: 3
diagnostic_period: 0.5
config_file: ignored.yaml
)",
                                 c, "test");
  EXPECT_EQ(c.hpds.mode, hpds::Mode::Map);
  EXPECT_EQ(c.hpds.hierarchy.cell_size, 2.0);
  EXPECT_EQ(c.hpds.hierarchy.max_depth, 6);
  EXPECT_TRUE(c.hpds.normals.enabled);
  EXPECT_EQ(c.ros.fixed_frame, "odom") << "leading slash dropped for tf2";
  EXPECT_EQ(c.ros.tf_timeout, 0.25);
  EXPECT_EQ(c.ros.sensor_frame, "velodyne") << "tf2 refuses the leading slash";
  EXPECT_EQ(c.ros.local_map_radius, 30.0);
  EXPECT_EQ(c.ros.local_map_rate, 2.5);
  EXPECT_EQ(c.ros.publish_levels, (std::vector<int>{1, 3}));
  EXPECT_EQ(c.ros.queue_size, 3);
  EXPECT_EQ(c.diagnostic_period, 0.5) << "the node reports at the file's period unless its parameter is set";
}

TEST(NodeConfig, PublishLevelsFromALaunchString) {
  NodeConfig c;
  hpds_node::applyNodeConfigYaml("ros: {publish_levels: \"[2, 4]\"}", c, "launch");
  EXPECT_EQ(c.ros.publish_levels, (std::vector<int>{2, 4}));
}

TEST(NodeConfig, ErrorsNameTheKeyAndLeaveTheConfigUnchanged) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"hierarchy: {max_depth: 30}", "hierarchy.max_depth:"},
      {"hierarchy: {cell_size: \"4.0\"}", "hierarchy.cell_size:"},
      {"cell_size: 4.0", "cell_size:"},
      {"ros: {tf_timeout: -1}", "ros.tf_timeout:"},
      {"ros: {tf_timeout: \"0.1\"}", "ros.tf_timeout:"},
      {"ros: {tf_timeout: 1e12}", "ros.tf_timeout: must be in 0..60 [s]"},
      {"ros: {local_map_radius: 1e12}", "ros.local_map_radius: must be > 0 and <= 1e6 [m]"},
      {"ros: {local_map_rate: 1e9}", "ros.local_map_rate: must be in 0..1000 [Hz]"},
      {"mode: map\nros: {fixed_frame: odom, map_file: /tmp/m.PLY}", "ros.map_file: '/tmp/m.PLY' has the extension"},
      {"ros: {queue_size: 0}", "ros.queue_size:"},
      {"ros: {queue_size: 1.5}", "ros.queue_size:"},
      {"ros: {local_map_radius: 0}", "ros.local_map_radius:"},
      {"ros: {local_map_rate: .nan}", "ros.local_map_rate:"},
      {"ros: {publish_levels: [9]}", "ros.publish_levels:"},
      {"ros: {publish_levels: [2, 2]}", "ros.publish_levels:"},
      {"ros: {publish_levels: 3}", "ros.publish_levels:"},
      {"ros: {fixed_frame: \"a b\"}", "ros.fixed_frame:"},
      {"mode: map\nros: {fixed_frame: \"\"}", "ros.fixed_frame:"},
      {"ros: {fixd_frame: odom}", "ros.fixd_frame:"},
      {"ros: [1]", "ros:"},
      {"mode: [", "(document)"},
  };
  for (const auto &[yaml, prefix] : cases) {
    const std::string e = errorOf(yaml);
    EXPECT_EQ(e.rfind(prefix, 0), 0u) << yaml << " -> '" << e << "'";
    EXPECT_NE(e.find("(in test)"), std::string::npos) << e;
  }
  NodeConfig c;
  c.ros.queue_size = 7;
  EXPECT_THROW(hpds_node::applyNodeConfigYaml("ros: {queue_size: 2}\nhierarchy: {max_depth: 99}", c, ""),
               std::invalid_argument);
  EXPECT_EQ(c.ros.queue_size, 7) << "strong guarantee";
}

TEST(NodeConfig, ConfigFilesMustBeSmallRegularFiles) {
  for (const std::string path : {"/dev/zero", "/dev/null"}) {
    try {
      (void)hpds_node::loadNodeConfigFile(path);
      ADD_FAILURE() << path << " was read";
    } catch (const std::invalid_argument &e) {
      EXPECT_EQ(std::string(e.what()), "config file '" + path + "': not a regular file (a config is a YAML text file)");
    }
  }
  NodeConfig c;
  std::string sequence = "ros: {publish_levels: [";
  while (sequence.size() <= hpds::kMaxConfigBytes) sequence += "1, ";
  EXPECT_THROW(hpds_node::applyNodeConfigYaml(sequence + "1]}", c, "rosparam"), std::invalid_argument);
}

TEST(NodeConfig, MapPersistenceKeys) {
  NodeConfig c;
  EXPECT_EQ(c.ros.map_file, "");
  EXPECT_FALSE(c.ros.load_map_on_start);
  EXPECT_FALSE(c.ros.save_map_on_shutdown);
  hpds_node::applyNodeConfigYaml(
      "mode: map\nros: {map_file: /var/lib/hpds/m.hpdsmap, load_map_on_start: true, save_map_on_shutdown: true}", c,
      "test");
  EXPECT_EQ(c.ros.map_file, "/var/lib/hpds/m.hpdsmap");
  EXPECT_TRUE(c.ros.load_map_on_start);
  EXPECT_TRUE(c.ros.save_map_on_shutdown);
  // The services alone need nothing at configuration time (they answer success=false in scan mode or without a
  // file); a path may be set in scan mode.
  NodeConfig s;
  EXPECT_NO_THROW(hpds_node::applyNodeConfigYaml("mode: scan\nros: {map_file: m.hpdsmap}", s, "test"));
  EXPECT_EQ(s.ros.map_file, "m.hpdsmap");
  NodeConfig off;
  EXPECT_NO_THROW(hpds_node::applyNodeConfigYaml(
      "mode: map\nros: {load_map_on_start: false, save_map_on_shutdown: false}", off, "test"));
}

TEST(NodeConfig, MapPersistenceErrors) {
  // (yaml, key prefix, words the message must contain)
  const std::vector<std::tuple<std::string, std::string, std::string>> cases = {
      {"mode: map\nros: {load_map_on_start: true}", "ros.load_map_on_start:", "ros.map_file"},
      {"mode: map\nros: {save_map_on_shutdown: true}", "ros.save_map_on_shutdown:", "ros.map_file"},
      {"mode: map\nros: {map_file: \"\", save_map_on_shutdown: true}", "ros.save_map_on_shutdown:", "ros.map_file"},
      {"ros: {map_file: m.hpdsmap, load_map_on_start: true}", "ros.load_map_on_start:", "mode: map"},
      {"mode: scan\nros: {map_file: m.hpdsmap, save_map_on_shutdown: true}", "ros.save_map_on_shutdown:",
       "mode: map"},
      {"mode: map\nros: {map_file: m, load_map_on_start: yes}", "ros.load_map_on_start:", "true or false"},
      {"mode: map\nros: {map_file: m, load_map_on_start: \"true\"}", "ros.load_map_on_start:", "true or false"},
      {"mode: map\nros: {map_file: m, save_map_on_shutdown: 1}", "ros.save_map_on_shutdown:", "true or false"},
      {"ros: {map_file: [a, b]}", "ros.map_file:", "string"},
      {"ros: {map_file: {a: b}}", "ros.map_file:", "string"},
      {"ros: {map_file: \"a\\0b\"}", "ros.map_file:", "NUL"},
      {"ros: {save_map: true}", "ros.save_map:", "map_file, load_map_on_start, save_map_on_shutdown"},
  };
  for (const auto &[yaml, prefix, words] : cases) {
    const std::string e = errorOf(yaml);
    EXPECT_EQ(e.rfind(prefix, 0), 0u) << yaml << " -> '" << e << "'";
    EXPECT_NE(e.find(words), std::string::npos) << yaml << " -> '" << e << "'";
    EXPECT_NE(e.find("(in test)"), std::string::npos) << e;
  }
  // Strong guarantee: a refused persistence key leaves every value as it was.
  NodeConfig c;
  c.hpds.mode = hpds::Mode::Map;
  c.ros.map_file = "kept.hpdsmap";
  EXPECT_THROW(hpds_node::applyNodeConfigYaml("ros: {map_file: \"\", load_map_on_start: true}", c, ""),
               std::invalid_argument);
  EXPECT_EQ(c.ros.map_file, "kept.hpdsmap");
  EXPECT_FALSE(c.ros.load_map_on_start);
  // validateRosConfig on its own (what FrameProcessor and the node call) applies the same rules.
  hpds_node::RosConfig ros;
  ros.save_map_on_shutdown = true;
  EXPECT_THROW(hpds_node::validateRosConfig(ros, c.hpds), std::invalid_argument);
  ros.map_file = "m.hpdsmap";
  EXPECT_NO_THROW(hpds_node::validateRosConfig(ros, c.hpds));
  EXPECT_THROW(hpds_node::validateRosConfig(ros, hpds::HpdsConfig{}), std::invalid_argument) << "scan mode";
}

TEST(NodeConfig, RosDumpLoadsBack) {
  NodeConfig c;
  c.ros.fixed_frame = "odom";
  c.ros.output_frame = "base_link";
  c.ros.sensor_frame = "velodyne";
  c.ros.tf_timeout = 0.3;
  c.ros.publish_levels = {0, 5};
  c.ros.queue_size = 4;
  c.hpds.mode = hpds::Mode::Map;
  c.ros.map_file = "/tmp/a map \"quoted\".hpdsmap";
  c.ros.load_map_on_start = true;
  c.ros.save_map_on_shutdown = true;
  NodeConfig d;
  hpds_node::applyNodeConfigYaml(hpds::dumpConfigYaml(c.hpds) + hpds_node::dumpRosConfigYaml(c.ros), d, "dump");
  EXPECT_EQ(d.ros.fixed_frame, c.ros.fixed_frame);
  EXPECT_EQ(d.ros.output_frame, c.ros.output_frame);
  EXPECT_EQ(d.ros.sensor_frame, c.ros.sensor_frame);
  EXPECT_EQ(d.ros.tf_timeout, c.ros.tf_timeout);
  EXPECT_EQ(d.ros.publish_levels, c.ros.publish_levels);
  EXPECT_EQ(d.ros.queue_size, c.ros.queue_size);
  EXPECT_EQ(d.ros.map_file, c.ros.map_file);
  EXPECT_TRUE(d.ros.load_map_on_start);
  EXPECT_TRUE(d.ros.save_map_on_shutdown);
}

// The project's documented config file loads as node settings (the node reads it through <rosparam load>) and,
// when it documents the ros: section, with exactly the RosConfig defaults.
TEST(NodeConfig, ProjectConfigFileLoadsWithTheDefaults) {
  const std::string path = std::string(HPDS_SOURCE_DIR) + "/config/hpds.yaml";
  NodeConfig c;
  ASSERT_NO_THROW(c = hpds_node::loadNodeConfigFile(path));
  EXPECT_EQ(hpds::dumpConfigYaml(c.hpds), hpds::dumpConfigYaml(hpds::HpdsConfig{}));
  EXPECT_EQ(hpds_node::dumpRosConfigYaml(c.ros), hpds_node::dumpRosConfigYaml(hpds_node::RosConfig{}));
}

}  // namespace
