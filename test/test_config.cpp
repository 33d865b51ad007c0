// Config YAML edge: config/hpds.yaml vs the struct defaults, dump/load round trip, overlay, and every error path.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <fstream>
#include <functional>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "TestData.hpp"
#include "hpds/config/Config.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/config/NodeConfig.hpp"

namespace {

using hpds::HpdsConfig;

const std::string kDefaultYaml = HPDS_SOURCE_DIR "/config/hpds.yaml";

// Compares every member and returns how many it compared. The structured bindings stop compiling when a member is
// added to a config struct: extend them and the comparisons below, then add the key to the key table in
// ConfigYaml.cpp and to config/hpds.yaml (DefaultYamlDocumentsEveryKey checks the file).
std::size_t expectSameConfig(const HpdsConfig &a, const HpdsConfig &b) {
  [[maybe_unused]] const auto &[mode, hierarchy, order, output, normals, map, input, threads] = a;
  [[maybe_unused]] const auto &[cell_size, max_depth] = a.hierarchy;
  [[maybe_unused]] const auto &[type, seed, feature_radius] = a.order;
  [[maybe_unused]] const auto &[level, spacing, float64_xyz, float32_xyz] = a.output;
  [[maybe_unused]] const auto &[enabled, radius, k, min_neighbors, neighborhood_level_offset, max_growth, covariances,
                                 covariance_epsilon, covariance_line_ratio, covariance_k] = a.normals;
  [[maybe_unused]] const auto &[evict_distance, max_samples, keep_depth] = a.map;
  [[maybe_unused]] const auto &[skip_zero_points, min_range, max_range] = a.input;

  std::size_t compared = 0;
  auto same = [&compared](const char *key, const auto &x, const auto &y) {
    ++compared;
    EXPECT_EQ(x, y) << key;
  };
  same("mode", a.mode, b.mode);
  same("hierarchy.cell_size", a.hierarchy.cell_size, b.hierarchy.cell_size);
  same("hierarchy.max_depth", a.hierarchy.max_depth, b.hierarchy.max_depth);
  same("order.type", a.order.type, b.order.type);
  same("order.seed", a.order.seed, b.order.seed);
  same("order.feature_radius", a.order.feature_radius, b.order.feature_radius);
  same("output.level", a.output.level, b.output.level);
  same("output.spacing", a.output.spacing, b.output.spacing);
  same("output.float64_xyz", a.output.float64_xyz, b.output.float64_xyz);
  same("output.float32_xyz", a.output.float32_xyz, b.output.float32_xyz);
  same("normals.enabled", a.normals.enabled, b.normals.enabled);
  same("normals.radius", a.normals.radius, b.normals.radius);
  same("normals.k", a.normals.k, b.normals.k);
  same("normals.min_neighbors", a.normals.min_neighbors, b.normals.min_neighbors);
  same("normals.neighborhood_level_offset", a.normals.neighborhood_level_offset, b.normals.neighborhood_level_offset);
  same("normals.max_growth", a.normals.max_growth, b.normals.max_growth);
  same("normals.covariances", a.normals.covariances, b.normals.covariances);
  same("normals.covariance_epsilon", a.normals.covariance_epsilon, b.normals.covariance_epsilon);
  same("normals.covariance_line_ratio", a.normals.covariance_line_ratio, b.normals.covariance_line_ratio);
  same("normals.covariance_k", a.normals.covariance_k, b.normals.covariance_k);
  same("map.evict_distance", a.map.evict_distance, b.map.evict_distance);
  same("map.max_samples", a.map.max_samples, b.map.max_samples);
  same("map.keep_depth", a.map.keep_depth, b.map.keep_depth);
  same("input.skip_zero_points", a.input.skip_zero_points, b.input.skip_zero_points);
  same("input.min_range", a.input.min_range, b.input.min_range);
  same("input.max_range", a.input.max_range, b.input.max_range);
  same("threads", a.threads, b.threads);
  return compared;
}

// Dotted paths of the leaves of a YAML map, walked independently of the library's key table.
void collectLeafKeys(const YAML::Node &node, const std::string &prefix, std::set<std::string> &keys) {
  for (const auto &entry : node) {
    const std::string key = prefix.empty() ? entry.first.Scalar() : prefix + "." + entry.first.Scalar();
    if (entry.second.IsMap()) {
      collectLeafKeys(entry.second, key, keys);
    } else {
      keys.insert(key);
    }
  }
}

std::set<std::string> leafKeys(const YAML::Node &root) {
  std::set<std::string> keys;
  collectLeafKeys(root, "", keys);
  return keys;
}

// A config where every key differs from its default (NonDefaultTouchesEveryKey holds it to that).
HpdsConfig nonDefaultConfig() {
  HpdsConfig c;
  c.mode = hpds::Mode::Map;
  c.hierarchy.cell_size = 2.5;
  c.hierarchy.max_depth = 12;
  c.order.type = hpds::InsertionOrder::SurfaceVariation;
  c.order.seed = std::numeric_limits<std::uint64_t>::max();
  c.order.feature_radius = 0.1;  // not exactly representable: the dump must still round-trip it
  c.output.level = 5;
  c.output.spacing = 0.3;
  c.output.float64_xyz = true;
  c.output.float32_xyz = true;
  c.normals.enabled = false;
  c.normals.radius = 1.0 / 3.0;
  c.normals.k = 20;
  c.normals.min_neighbors = 7;
  c.normals.neighborhood_level_offset = 3;
  c.normals.max_growth = 2.5;
  c.normals.covariances = true;
  c.normals.covariance_epsilon = 0.01;
  c.normals.covariance_line_ratio = 0.05;
  c.normals.covariance_k = 12;
  c.map.evict_distance = 123.456;
  c.map.max_samples = 1000000;
  c.map.keep_depth = 9;
  c.input.skip_zero_points = false;
  c.input.min_range = 0.5;
  c.input.max_range = 1e3;
  c.threads = 4;
  return c;
}

// nonDefaultConfig() as a valid config: normals.covariances needs normals on, the default, so this one key keeps it;
// and x y z take one type, so output.float32_xyz stays off beside float64_xyz.
HpdsConfig validNonDefaultConfig() {
  HpdsConfig c = nonDefaultConfig();
  c.normals.enabled = true;
  c.output.float32_xyz = false;
  return c;
}

std::vector<std::string> lines(const std::string &text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

std::string errorOf(const std::function<void()> &action) {
  try {
    action();
  } catch (const std::invalid_argument &e) {
    return e.what();
  }
  return "<no std::invalid_argument thrown>";
}

std::string loadError(const std::string &yaml) {
  return errorOf([&] { (void)hpds::loadConfigString(yaml); });
}

void writeFile(const std::filesystem::path &path, const std::string &text) {
  std::ofstream(path) << text;
}

// ------------------------------------------------------------------------------------------------------------------

TEST(ConfigYaml, DefaultYamlEqualsStructDefaults) {
  const HpdsConfig loaded = hpds::loadConfigFile(kDefaultYaml);
  const std::size_t compared = expectSameConfig(loaded, HpdsConfig{});
  // The library's table must cover every member compared above, or some member is never read from YAML.
  EXPECT_EQ(compared, hpds::configKeys().size());
}

TEST(ConfigYaml, DefaultYamlDocumentsEveryKey) {
  const std::set<std::string> dumped = leafKeys(YAML::Load(hpds::dumpConfigYaml(HpdsConfig{})));
  const std::set<std::string> documented = leafKeys(YAML::LoadFile(kDefaultYaml));
  const std::vector<std::string> table = hpds::configKeys();
  EXPECT_EQ(dumped, std::set<std::string>(table.begin(), table.end()));
  for (const std::string &key : dumped) EXPECT_EQ(documented.count(key), 1u) << key << " missing from config/hpds.yaml";
  // ros.* and diagnostic_period belong to the node (test_node_config checks them against the node's defaults).
  for (const std::string &key : documented) {
    if (key.rfind("ros.", 0) == 0 || key == "diagnostic_period") continue;
    EXPECT_EQ(dumped.count(key), 1u) << key << " in config/hpds.yaml is not a key";
  }
  EXPECT_EQ(hpds::loadConfigString("ros: {fixed_frame: odom, queue_size: 3}\ndiagnostic_period: 0.5\n").hierarchy.cell_size,
            HpdsConfig{}.hierarchy.cell_size);
  EXPECT_NE(loadError("ros: 3\n").find("ros: expected a map"), std::string::npos);
}

TEST(ConfigYaml, NonDefaultTouchesEveryKey) {
  const std::vector<std::string> defaults = lines(hpds::dumpConfigYaml(HpdsConfig{}));
  const std::vector<std::string> custom = lines(hpds::dumpConfigYaml(nonDefaultConfig()));
  ASSERT_EQ(defaults.size(), custom.size());
  for (std::size_t i = 0; i < defaults.size(); ++i) {
    const bool section_header = defaults[i].back() == ':';
    if (!section_header) {
      EXPECT_NE(defaults[i], custom[i]) << "nonDefaultConfig() leaves this key at its default";
    }
  }
}

TEST(ConfigYaml, DumpLoadRoundTrip) {
  const HpdsConfig original = validNonDefaultConfig();
  const std::string dumped = hpds::dumpConfigYaml(original);
  const HpdsConfig loaded = hpds::loadConfigString(dumped);
  expectSameConfig(loaded, original);
  EXPECT_EQ(hpds::dumpConfigYaml(loaded), dumped);
  EXPECT_NE(dumped.find("seed: 18446744073709551615\n"), std::string::npos) << dumped;
  EXPECT_NE(dumped.find("feature_radius: 0.1\n"), std::string::npos) << dumped;
  EXPECT_NE(dumped.find("max_range: 1000.0\n"), std::string::npos) << dumped;

  expectSameConfig(hpds::loadConfigString(hpds::dumpConfigYaml(HpdsConfig{})), HpdsConfig{});
}

TEST(ConfigYaml, EmptyDocumentsGiveDefaults) {
  for (const char *text : {"", "# only a comment\n", "---\n", "hierarchy:\n", "\n\n", "---\n...\n", "~\n", "%YAML 1.2\n---\n"}) {
    SCOPED_TRACE(text);
    expectSameConfig(hpds::loadConfigString(text), HpdsConfig{});
  }
  const auto dir = hpds::test::scratchDir("config_empty");
  writeFile(dir / "empty.yaml", "");
  expectSameConfig(hpds::loadConfigFile((dir / "empty.yaml").string()), HpdsConfig{});
}

TEST(ConfigYaml, PartialOverlayKeepsAbsentKeys) {
  HpdsConfig config = validNonDefaultConfig();
  // (covariances need normals: switching normals off alone would be rejected, see InvalidDocumentsNameTheKey)
  hpds::applyConfigYaml("hierarchy:\n  max_depth: 10\nnormals: {enabled: false, covariances: false}\nmode: scan\n",
                        config);
  HpdsConfig expected = validNonDefaultConfig();
  expected.hierarchy.max_depth = 10;
  expected.normals.enabled = false;
  expected.normals.covariances = false;
  expected.mode = hpds::Mode::Scan;
  expectSameConfig(config, expected);
}

TEST(ConfigYaml, AcceptedScalarSpellings) {
  const HpdsConfig c = hpds::loadConfigString(
      "hierarchy: {cell_size: 8, max_depth: +3}\n"  // an integer is a fine double
      "order: {type: 'sphericity', seed: 42, feature_radius: 1.5e-1}\n"
      "input: {min_range: .5, max_range: 2.}\n");
  EXPECT_EQ(c.hierarchy.cell_size, 8.0);
  EXPECT_EQ(c.hierarchy.max_depth, 3);
  EXPECT_EQ(c.order.type, hpds::InsertionOrder::Sphericity);
  EXPECT_EQ(c.order.seed, 42u);
  EXPECT_EQ(c.order.feature_radius, 0.15);
  EXPECT_EQ(c.input.min_range, 0.5);
  EXPECT_EQ(c.input.max_range, 2.0);
}

TEST(ConfigYaml, CovarianceKMeetsMinNeighborsOnlyWhereCovariancesAreMade) {
  // A larger min_neighbors than the default covariance_k is fine as long as no covariance is asked for.
  EXPECT_EQ(hpds::loadConfigString("normals: {min_neighbors: 40}").normals.min_neighbors, 40);
  EXPECT_EQ(loadError("normals: {min_neighbors: 40, covariances: true}").rfind("normals.covariance_k:", 0), 0u);
  EXPECT_EQ(hpds::loadConfigString("normals: {min_neighbors: 40, covariances: true, covariance_k: 0}")
                .normals.covariance_k,
            0);
  EXPECT_EQ(hpds::loadConfigString("normals: {min_neighbors: 40, covariances: true, covariance_k: 40}")
                .normals.covariance_k,
            40);
}

TEST(ConfigYaml, FailedOverlayLeavesConfigUnchanged) {
  HpdsConfig config = validNonDefaultConfig();
  // The first key is valid and would be applied before the second fails.
  EXPECT_THROW(hpds::applyConfigYaml("threads: 2\nhierarchy: {max_depth: 30}\n", config), std::invalid_argument);
  EXPECT_THROW(hpds::applyConfigYaml("threads: 2\nnormals: {min_neighbors: 2}\n", config), std::invalid_argument);
  expectSameConfig(config, validNonDefaultConfig());
}

struct InvalidCase {
  const char *yaml;
  const char *key;     // the message must start with this
  const char *detail;  // and contain this
};

void expectRefused(const InvalidCase &c) {
  const std::string message = loadError(c.yaml);
  EXPECT_EQ(message.rfind(std::string(c.key) + ":", 0), 0u) << "yaml: " << c.yaml << "\nmessage: " << message;
  EXPECT_NE(message.find(c.detail), std::string::npos) << "yaml: " << c.yaml << "\nmessage: " << message;
}

TEST(ConfigYaml, InvalidDocumentsNameTheKey) {
  const InvalidCase cases[] = {
      // values validateConfig rejects
      {"hierarchy: {cell_size: -1.0}", "hierarchy.cell_size", "> 0"},
      {"map: {keep_depth: -2}", "map.keep_depth", "-1 or in 0..hierarchy.max_depth"},
      {"hierarchy: {max_depth: 6}\nmap: {keep_depth: 7}", "map.keep_depth", "0..hierarchy.max_depth (6)"},
      {"output: {spacing: 1e7}", "output.spacing", "too large"},
      // cells whose exact keys cannot hold a frame: every point would be out of key range
      {"output: {spacing: 1e-300}", "output.spacing", "too small"},
      {"output: {spacing: 1e-8}", "output.spacing", "reach only"},
      {"hierarchy: {cell_size: 1e-6}", "hierarchy.cell_size", "lower hierarchy.max_depth"},
      {"hierarchy: {cell_size: 0.01, max_depth: 21}", "hierarchy.cell_size", "too small"},
      {"hierarchy: {cell_size: .nan}", "hierarchy.cell_size", "finite"},
      {"hierarchy: {cell_size: -.inf}", "hierarchy.cell_size", "finite"},
      {"hierarchy: {max_depth: 22}", "hierarchy.max_depth", "0..21"},
      {"hierarchy: {max_depth: -1}", "hierarchy.max_depth", "0..21"},
      {"hierarchy: {max_depth: 4}\noutput: {level: 5}", "output.level", "max_depth"},
      {"normals: {min_neighbors: 2}", "normals.min_neighbors", ">= 3"},
      {"normals: {neighborhood_level_offset: -1}", "normals.neighborhood_level_offset", "0..21"},
      {"normals: {max_growth: 0.5}", "normals.max_growth", "1..1024"},
      {"normals: {k: 4}", "normals.k", "min_neighbors"},
      {"normals: {enabled: false, covariances: true}", "normals.covariances", "normals.enabled"},
      {"output: {float64_xyz: true, float32_xyz: true}", "output.float32_xyz", "output.float64_xyz"},
      {"normals: {covariance_epsilon: 0}", "normals.covariance_epsilon", "1e-4..1"},
      {"normals: {covariance_epsilon: 1.5}", "normals.covariance_epsilon", "1e-4..1"},
      {"normals: {covariance_epsilon: .nan}", "normals.covariance_epsilon", "finite"},
      {"normals: {covariance_line_ratio: -0.1}", "normals.covariance_line_ratio", "0..1"},
      {"normals: {covariance_line_ratio: 2}", "normals.covariance_line_ratio", "0..1"},
      {"normals: {covariances: true, covariance_k: 4}", "normals.covariance_k", "min_neighbors (5)..1024"},
      {"normals: {covariance_k: -1}", "normals.covariance_k", "must be 0"},
      {"normals: {covariance_k: 2000}", "normals.covariance_k", "..1024"},
      {"threads: -1", "threads", "0..1024"},
      // size-like values beyond their bounds (each took 30-60 s per frame)
      {"normals: {k: 2000000000}", "normals.k", "must be in 0..1024"},
      {"normals: {min_neighbors: 5000}", "normals.min_neighbors", "must be in 3..1024"},
      {"normals: {radius: 1e6}", "normals.radius", "(64 radii of level 7, the finest level the normals read)"},
      {"output: {level: 3}\nnormals: {radius: 30.0, neighborhood_level_offset: 0}", "normals.radius",
       "64 radii of level 3"},
      {"order: {feature_radius: 1e6}", "order.feature_radius", "(64 radii of level 5, the output level)"},
      // unknown keys
      {"bogus: 1", "bogus", "unknown key"},
      {"hierarchy: {max_dpeth: 3}", "hierarchy.max_dpeth", "did you mean 'hierarchy.max_depth'"},
      {"thread: 2", "thread", "did you mean 'threads'"},
      {"hierachy: {max_depth: 3}", "hierachy", "did you mean 'hierarchy'"},
      {"cell_size: 2.0", "cell_size", "did you mean 'hierarchy.cell_size'"},
      {"output: {colour: red}", "output.colour", "unknown key"},
      // a dotted name as one key (found in a user trial: it was told "did you mean 'output.spacing'?")
      {"output.spacing: 0.2", "output.spacing", "write it nested, as key 'spacing' under section 'output'"},
      // wrong types
      {"hierarchy: {max_depth: abc}", "hierarchy.max_depth", "expected an integer, got 'abc'"},
      {"hierarchy: {max_depth: 3.5}", "hierarchy.max_depth", "expected an integer, got '3.5'"},
      {"hierarchy: {max_depth: 0x10}", "hierarchy.max_depth", "expected an integer"},
      // a leading zero: octal to a YAML 1.1 reader (rosparam), so the node would read another number
      {"output: {level: 010}", "output.level", "'010' has a leading zero"},
      {"order: {seed: 007}", "order.seed", "leading zero"},
      {"hierarchy: {cell_size: 010}", "hierarchy.cell_size", "leading zero"},
      {"hierarchy: {max_depth: -05}", "hierarchy.max_depth", "leading zero"},
      {"hierarchy: {max_depth: 99999999999}", "hierarchy.max_depth", "out of range"},
      {"hierarchy: {cell_size: abc}", "hierarchy.cell_size", "expected a number, got 'abc'"},
      {"hierarchy: {cell_size: '4.0'}", "hierarchy.cell_size", "quoted string"},
      // explicit tags: the text would mean something else to a YAML reader than to hpds
      {"output: {spacing: !!str 0.2}", "output.spacing", "YAML tag !!str"},
      {"output: {spacing: !foo 0.2}", "output.spacing", "YAML tag !foo"},
      {"normals: {enabled: !!str true}", "normals.enabled", "YAML tag !!str"},
      {"mode: !!int map", "mode", "YAML tag !!int"},
      {"output: {level: !!float 3}", "output.level", "YAML tag !!float"},
      {"order: {type: !!binary random}", "order.type", "YAML tag !!binary"},
      {"hierarchy: {cell_size: }", "hierarchy.cell_size", "expected a number"},
      {"hierarchy: {cell_size: 1e999}", "hierarchy.cell_size", "out of the range"},
      {"order: {seed: -1}", "order.seed", "non-negative integer"},
      {"order: {seed: 18446744073709551616}", "order.seed", "out of range"},
      {"map: {max_samples: -5}", "map.max_samples", "non-negative integer"},
      {"normals: {enabled: yes}", "normals.enabled", "expected true or false, got 'yes'"},
      {"normals: {enabled: 1}", "normals.enabled", "true or false"},
      {"threads: [1, 2]", "threads", "got a sequence"},
      {"mode: {scan: true}", "mode", "got a map"},
      // unknown enum strings
      {"order: {type: fastest}", "order.type", "fastest"},
      {"mode: batch", "mode", "batch"},
      // structure
      {"hierarchy: 4", "hierarchy", "expected a map"},
      {"normals: [true]", "normals", "expected a map"},
      {"- mode\n- scan\n", "(document)", "expected a map"},
      {"just text", "(document)", "expected a map"},
      {"threads: 2\nthreads: 3\n", "threads", "duplicate key"},
      {"hierarchy: {max_depth: 3}\nhierarchy: {cell_size: 3}\n", "hierarchy", "duplicate key"},
      {"hierarchy: {max_depth: 3, max_depth: 4}", "hierarchy.max_depth", "duplicate key"},
      {"mode: scan\n---\nmode: map\n", "(document)", "one YAML document"},
      {"mode: scan\n...\nmode: map\n", "(document)", "one YAML document"},
      {"mode: scan\n---\n,\n", "(document)", "one YAML document"},
      {",\n", "(document)", "not YAML"},
      // syntax
      {"hierarchy: {cell_size: 4.0\nthreads: 1\n", "(document)", "line "},
      {"hierarchy:\n  cell_size: 4.0\n max_depth: 3\n", "(document)", "YAML syntax error"},
  };
  for (const InvalidCase &c : cases) expectRefused(c);
  // With the cell derived from the spacing, the output level's cell is 2 S / sqrt(3) at any max_depth: the advice is
  // the spacing alone; with a fixed cell, max_depth helps too.
  for (const char *depth : {"8", "2"}) {
    const std::string derived = loadError(std::string("output: {spacing: 1e-8}\nhierarchy: {max_depth: ") + depth + "}");
    EXPECT_NE(derived.find("are needed); raise it"), std::string::npos) << derived;
    EXPECT_EQ(derived.find("max_depth", derived.find("are needed")), std::string::npos) << derived;
  }
  EXPECT_NE(loadError("hierarchy: {cell_size: 1e-6}").find("raise it or lower hierarchy.max_depth"), std::string::npos);
  // A NUL byte (yaml-cpp reported what followed it as an "unknown escape character").
  const std::string nul("output:\n  spacing: 0.3\0garbage", 28);
  const std::string message = loadError(nul);
  EXPECT_NE(message.find("NUL byte at line 2"), std::string::npos) << message;
}

// The ROS node's part of a config file is validated by every reader (loadConfig, applyConfigYaml, the CLI's
// --config) exactly as the node validates it: a file that `hpds sample --config` accepts is never refused by the node.
TEST(ConfigYaml, TheNodesKeysAreValidatedByEveryReader) {
  const InvalidCase cases[] = {
      {"ros: {queue_sise: 3}", "ros.queue_sise", "unknown key"},
      {"ros: {queue_size: 0}", "ros.queue_size", "1..1000"},
      {"ros: {publish_levels: [99]}", "ros.publish_levels", "outside 0..hierarchy.max_depth (8)"},
      {"ros: {tf_timeout: '0.1'}", "ros.tf_timeout", "quoted string"},
      {"ros: {tf_timeout: !!str 0.1}", "ros.tf_timeout", "YAML tag !!str"},
      {"ros: {fixed_frame: !!str odom}", "ros.fixed_frame", "YAML tag !!str"},
      {"ros: {load_map_on_start: true}", "ros.load_map_on_start", "needs mode: map"},
      {"diagnostic_period: abc", "diagnostic_period", "expected a number"},
      {"diagnostic_period: 0", "diagnostic_period", "(0, 3600]"},
      {"fixed_frame: odom", "fixed_frame", "did you mean 'ros.fixed_frame'"},
  };
  for (const InvalidCase &c : cases) {
    expectRefused(c);
    HpdsConfig config;
    EXPECT_THROW(hpds::applyConfigYaml(c.yaml, config), std::invalid_argument) << c.yaml;
  }
  // The node's keys are checked against the whole file's config: level 10 is fine at max_depth 12.
  EXPECT_EQ(hpds::loadConfigString("hierarchy: {max_depth: 12}\nros: {publish_levels: [10]}\n").hierarchy.max_depth, 12);
}

// Found: `fixed_frame: odom` with mode left at scan gave scan output in the sensor frame, without a word.
TEST(ConfigYaml, SettingsTheModeIgnoresAreNamed) {
  hpds::NodeConfig config;
  EXPECT_EQ(hpds::ignoredRosKeysWarning(config.ros, hpds::Mode::Scan), "") << "the defaults say nothing";
  EXPECT_EQ(hpds::ignoredRosKeysWarning(config.ros, hpds::Mode::Map), "");
  hpds::applyNodeConfigYaml("ros: {fixed_frame: odom}", config, "test");
  std::string w = hpds::ignoredRosKeysWarning(config.ros, hpds::Mode::Scan);
  EXPECT_NE(w.find("ros.fixed_frame ('odom') is a map-mode setting, ignored in scan mode"), std::string::npos) << w;
  EXPECT_NE(w.find("set mode: map"), std::string::npos) << w;
  EXPECT_EQ(hpds::ignoredRosKeysWarning(config.ros, hpds::Mode::Map), "") << "map mode uses it";
  hpds::applyNodeConfigYaml("ros: {local_map_rate: 2.0, map_file: /tmp/m.hpdsmap}", config, "test");
  w = hpds::ignoredRosKeysWarning(config.ros, hpds::Mode::Scan);
  EXPECT_NE(w.find("ros.fixed_frame ('odom'), ros.local_map_rate and ros.map_file are map-mode settings"),
            std::string::npos) << w;
  hpds::applyNodeConfigYaml("ros: {output_frame: base_link}", config, "test");
  w = hpds::ignoredRosKeysWarning(config.ros, hpds::Mode::Map);
  EXPECT_NE(w.find("ros.output_frame ('base_link') is a scan-mode setting, ignored in map mode"), std::string::npos)
      << w;
}

TEST(ConfigYaml, FileErrorsNameThePath) {
  const auto dir = hpds::test::scratchDir("config_errors");

  const std::string missing = (dir / "does_not_exist.yaml").string();
  std::string message = errorOf([&] { (void)hpds::loadConfigFile(missing); });
  EXPECT_NE(message.find(missing), std::string::npos) << message;

  message = errorOf([&] { (void)hpds::loadConfigFile(dir.string()); });
  EXPECT_NE(message.find("directory"), std::string::npos) << message;

  // Devices and oversized files: refused before they are read (/dev/zero grew without bound, a 6 MB YAML sequence
  // took 1.4 GB).
  message = errorOf([&] { (void)hpds::loadConfigFile("/dev/zero"); });
  EXPECT_EQ(message, "config file '/dev/zero': not a regular file (a config is a YAML text file)");
  const std::string big = (dir / "big.yaml").string();
  std::string sequence = "threads: [";
  while (sequence.size() <= hpds::kMaxConfigBytes) sequence += "1, ";
  writeFile(big, sequence + "1]\n");
  message = errorOf([&] { (void)hpds::loadConfigFile(big); });
  EXPECT_EQ(message, "config file '" + big + "': larger than 262144 bytes, the most a config file may have");
  message = errorOf([&] { (void)hpds::loadConfigString(sequence + "1]\n"); });
  EXPECT_EQ(message.rfind("(document): ", 0), 0u) << message;
  EXPECT_NE(message.find("more than the 262144 a config may have"), std::string::npos) << message;

  const std::string broken = (dir / "broken.yaml").string();
  writeFile(broken, "mode: scan\nhierarchy: [1,\n");
  message = errorOf([&] { (void)hpds::loadConfigFile(broken); });
  EXPECT_EQ(message.rfind("(document): YAML syntax error at line ", 0), 0u) << message;
  EXPECT_NE(message.find(broken), std::string::npos) << message;

  // A text file that is no config (found: config_file:=/etc/passwd, whose 1.5 KB filled the FATAL line): its start
  // and its length are named, not all of it.
  const std::string not_config = (dir / "passwd").string();
  std::string lines;
  for (int i = 0; i < 40; ++i) lines += "user" + std::to_string(i) + ":x:100" + std::to_string(i) + ":/home/user\n";
  writeFile(not_config, lines);
  message = errorOf([&] { (void)hpds::loadConfigFile(not_config); });
  EXPECT_NE(message.find("expected a map of config keys, got 'user0:x:1000:/home/user"), std::string::npos) << message;
  EXPECT_NE(message.find("... ("), std::string::npos) << message;
  EXPECT_LT(message.size(), 300u) << message;

  const std::string bad_value = (dir / "bad_value.yaml").string();
  writeFile(bad_value, "hierarchy:\n  max_depth: 22\n");
  message = errorOf([&] { (void)hpds::loadConfigFile(bad_value); });
  EXPECT_EQ(message.rfind("hierarchy.max_depth:", 0), 0u) << message;
  EXPECT_NE(message.find(bad_value), std::string::npos) << message;
}

TEST(ConfigYaml, SourceLabelIsAppended) {
  HpdsConfig config;
  const std::string message =
      errorOf([&] { hpds::applyConfigYaml("threads: -1", config, "rosparam /hpds_node"); });
  EXPECT_EQ(message.rfind("threads:", 0), 0u) << message;
  EXPECT_NE(message.find("(in rosparam /hpds_node)"), std::string::npos) << message;
}

}  // namespace
