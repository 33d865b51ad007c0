#include "hpds/config/NodeConfig.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "ConfigKeysYaml.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/config/YamlScalar.hpp"

namespace hpds {

namespace {

[[noreturn]] void fail(const std::string &key, const std::string &why) {
  throw std::invalid_argument(key + ": " + why);
}

// Single values by ConfigYaml's own rules (quoted numbers, explicit tags, wording), so that the node accepts and refuses
// the same text for ros.* as for every other key.
using yaml_node::describeNode;
using yaml_node::isQuotedScalar;
using yaml_node::plainScalarText;
using yaml_node::refuseExplicitTag;

double parseNumber(const YAML::Node &n, const std::string &key) {
  return yaml::parseNumber(plainScalarText(n, key, "a number"), isQuotedScalar(n), key);
}

int parseInt(const YAML::Node &n, const std::string &key) {
  return yaml::parseInt(plainScalarText(n, key, "an integer"), isQuotedScalar(n), key);
}

std::string parseString(const YAML::Node &n, const std::string &key) {
  refuseExplicitTag(n, key);
  if (n.IsNull()) return "";
  if (!n.IsScalar()) fail(key, "expected a string, got " + describeNode(n));
  return n.Scalar();
}

bool parseBool(const YAML::Node &n, const std::string &key) {
  return yaml::parseBool(plainScalarText(n, key, "true or false"), isQuotedScalar(n), key);
}

std::string parseFrameId(const YAML::Node &n, const std::string &key) {
  std::string id = parseString(n, key);
  // tf2 refuses ids with a leading slash; ROS 1 launch files still commonly write them.
  while (!id.empty() && id.front() == '/') id.erase(id.begin());
  if (id.find_first_of(" \t\n") != std::string::npos) fail(key, "frame id '" + id + "' contains whitespace");
  return id;
}

void applyRosSection(const YAML::Node &section, RosConfig &ros) {
  if (section.IsNull()) return;
  if (!section.IsMap()) fail("ros", "expected a map of ros.* keys, got " + describeNode(section));
  std::vector<std::string> seen;
  for (const auto &item : section) {
    if (!item.first.IsScalar()) fail("ros", "map keys must be strings");
    const std::string leaf = item.first.Scalar();
    const std::string key = "ros." + leaf;
    if (std::find(seen.begin(), seen.end(), leaf) != seen.end()) fail(key, "duplicate key");
    seen.push_back(leaf);
    const YAML::Node &v = item.second;
    if (leaf == "fixed_frame") {
      ros.fixed_frame = parseFrameId(v, key);
    } else if (leaf == "output_frame") {
      ros.output_frame = parseFrameId(v, key);
    } else if (leaf == "sensor_frame") {
      ros.sensor_frame = parseFrameId(v, key);
    } else if (leaf == "tf_timeout") {
      ros.tf_timeout = parseNumber(v, key);
    } else if (leaf == "local_map_radius") {
      ros.local_map_radius = parseNumber(v, key);
    } else if (leaf == "local_map_rate") {
      ros.local_map_rate = parseNumber(v, key);
    } else if (leaf == "queue_size") {
      ros.queue_size = parseInt(v, key);
    } else if (leaf == "map_file") {
      ros.map_file = parseString(v, key);
    } else if (leaf == "load_map_on_start") {
      ros.load_map_on_start = parseBool(v, key);
    } else if (leaf == "save_map_on_shutdown") {
      ros.save_map_on_shutdown = parseBool(v, key);
    } else if (leaf == "publish_levels") {
      ros.publish_levels.clear();
      YAML::Node list = v;
      // roslaunch <param> and <arg> values are strings: "[2, 4]" is taken as the list it spells.
      if (v.IsScalar() && isQuotedScalar(v)) {
        try {
          list = YAML::Load(v.Scalar());
        } catch (const YAML::Exception &) {
          fail(key, "expected a list of levels, e.g. [2, 4], got " + describeNode(v));
        }
      }
      if (list.IsNull()) continue;
      if (!list.IsSequence()) fail(key, "expected a list of levels, e.g. [2, 4], got " + describeNode(v));
      for (std::size_t i = 0; i < list.size(); ++i) ros.publish_levels.push_back(parseInt(list[i], key));
    } else {
      fail(key,
           "unknown key (ros keys: fixed_frame, output_frame, sensor_frame, tf_timeout, local_map_radius, "
           "local_map_rate, publish_levels, queue_size, map_file, load_map_on_start, save_map_on_shutdown)");
    }
  }
}

// Re-emits a parsed node for applyConfigKeysYaml, keeping quoted scalars quoted and explicit tags (verbatim), so that
// its "quoted numbers are errors" and "tags are errors" rules still see them, naming the key.
void emit(YAML::Emitter &out, const YAML::Node &n) {
  if (const std::string &tag = n.Tag(); !tag.empty() && tag != "?" && tag != "!") out << YAML::VerbatimTag(tag);
  if (n.IsMap()) {
    out << YAML::BeginMap;
    for (const auto &item : n) {
      out << YAML::Key;
      emit(out, item.first);
      out << YAML::Value;
      emit(out, item.second);
    }
    out << YAML::EndMap;
  } else if (n.IsSequence()) {
    out << YAML::Flow << YAML::BeginSeq;
    for (const auto &item : n) emit(out, item);
    out << YAML::EndSeq;
  } else if (n.IsScalar()) {
    if (isQuotedScalar(n)) out << YAML::DoubleQuoted;
    out << n.Scalar();
  } else {
    out << YAML::Null;
  }
}

std::string formatDouble(double v) { return yaml::formatNumber(v); }

std::string quoted(const std::string &s) {
  YAML::Emitter e;
  e << YAML::DoubleQuoted << s;
  return e.c_str();
}

}  // namespace

void validateRosConfig(const RosConfig &ros, const HpdsConfig &config) {
  // Upper bounds: a wait, radius or rate beyond them is a typo, and tf_timeout must fit ros::WallDuration.
  if (!std::isfinite(ros.tf_timeout) || ros.tf_timeout < 0.0 || ros.tf_timeout > 60.0)
    fail("ros.tf_timeout", "must be in 0..60 [s], got " + formatDouble(ros.tf_timeout));
  if (!std::isfinite(ros.local_map_radius) || ros.local_map_radius <= 0.0 || ros.local_map_radius > 1e6)
    fail("ros.local_map_radius", "must be > 0 and <= 1e6 [m], got " + formatDouble(ros.local_map_radius));
  if (!std::isfinite(ros.local_map_rate) || ros.local_map_rate < 0.0 || ros.local_map_rate > 1000.0)
    fail("ros.local_map_rate", "must be in 0..1000 [Hz] (0 = off), got " + formatDouble(ros.local_map_rate));
  if (ros.queue_size < 1 || ros.queue_size > 1000)
    fail("ros.queue_size", "must be in 1..1000, got " + std::to_string(ros.queue_size));
  for (std::size_t i = 0; i < ros.publish_levels.size(); ++i) {
    const int d = ros.publish_levels[i];
    if (d < 0 || d > config.hierarchy.max_depth)
      fail("ros.publish_levels", "level " + std::to_string(d) + " is outside 0..hierarchy.max_depth (" +
                                     std::to_string(config.hierarchy.max_depth) + ")");
    if (std::find(ros.publish_levels.begin(), ros.publish_levels.begin() + i, d) != ros.publish_levels.begin() + i)
      fail("ros.publish_levels", "level " + std::to_string(d) + " is listed twice");
  }
  if (config.mode == Mode::Map && ros.fixed_frame.empty())
    fail("ros.fixed_frame", "must be set in map mode (the frame the map is built in)");
  if (ros.map_file.find('\0') != std::string::npos) fail("ros.map_file", "contains a NUL character");
  if (isOtherFormatName(ros.map_file))
    fail("ros.map_file", "'" + ros.map_file + "' has the extension of another format; name the map e.g. map.hpdsmap");
  for (const auto &[key, on] : {std::pair<const char *, bool>{"ros.load_map_on_start", ros.load_map_on_start},
                                {"ros.save_map_on_shutdown", ros.save_map_on_shutdown}}) {
    if (!on) continue;
    if (config.mode != Mode::Map) fail(key, "needs mode: map (scan mode keeps no map)");
    if (ros.map_file.empty()) fail(key, "needs ros.map_file (the path of the map file) to be set");
  }
}

std::string ignoredRosKeysWarning(const RosConfig &ros, Mode mode) {
  const RosConfig defaults;
  std::vector<std::string> keys;
  if (mode == Mode::Scan) {
    if (ros.fixed_frame != defaults.fixed_frame) keys.push_back("ros.fixed_frame ('" + ros.fixed_frame + "')");
    if (ros.local_map_radius != defaults.local_map_radius) keys.emplace_back("ros.local_map_radius");
    if (ros.local_map_rate != defaults.local_map_rate) keys.emplace_back("ros.local_map_rate");
    if (!ros.map_file.empty()) keys.emplace_back("ros.map_file");
  } else if (!ros.output_frame.empty()) {
    keys.push_back("ros.output_frame ('" + ros.output_frame + "')");
  }
  if (keys.empty()) return "";
  std::string text;
  for (std::size_t i = 0; i < keys.size(); ++i) text += (i == 0 ? "" : i + 1 == keys.size() ? " and " : ", ") + keys[i];
  text += (keys.size() == 1 ? " is a " : " are ");
  if (mode == Mode::Scan)
    return text + (keys.size() == 1 ? "map-mode setting" : "map-mode settings") +
           ", ignored in scan mode: set mode: map to build a map in ros.fixed_frame, or ros.output_frame to publish "
           "each scan in another frame";
  return text + "scan-mode setting, ignored in map mode: map-mode outputs are in ros.fixed_frame ('" +
         ros.fixed_frame + "')";
}

double tfCacheSeconds(const RosConfig &ros) {
  constexpr double kTfDefaultCache = 10.0;    // tf2::BufferCore::DEFAULT_CACHE_TIME
  constexpr double kLongestFrameSeconds = 1.0;  // five times the densest shared frame at the defaults
  return std::max(kTfDefaultCache, ros.tf_timeout + ros.queue_size * kLongestFrameSeconds);
}

double checkDiagnosticPeriod(double period) {
  if (!(std::isfinite(period) && period > 0.0 && period <= 3600.0))
    fail("diagnostic_period", "must be a number of seconds in (0, 3600], got " + formatDouble(period));
  return period;
}

const std::vector<std::string> &nodeOnlyKeys() {
  static const std::vector<std::string> keys = {"config_file", "diagnostic_period"};
  return keys;
}

void applyNodeConfigYaml(const std::string &yaml_text, NodeConfig &config, const std::string &source,
                         ConfigValidation validation) {
  const std::vector<std::string> &ignored_keys = nodeOnlyKeys();
  const std::string suffix = source.empty() ? "" : " (in " + source + ")";
  if (yaml_text.size() > kMaxConfigBytes)
    throw std::invalid_argument("(document): " + std::to_string(yaml_text.size()) + " bytes, more than the " +
                                std::to_string(kMaxConfigBytes) + " a config may have" + suffix);
  try {
    // The whole text through the shared loader first, for the document's own errors, worded as the CLI words them
    // (syntax, NUL bytes, several documents, of which Load below would read the first only). Errors of single keys
    // come from the pass below, which knows the node's keys.
    HpdsConfig scratch = config.hpds;
    applyConfigKeysYaml(yaml_text, scratch, source);
  } catch (const std::invalid_argument &e) {
    if (std::string(e.what()).rfind("(document)", 0) == 0) throw;
  }
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception &) {
    throw std::invalid_argument("(document): YAML syntax error" + suffix);
  }
  NodeConfig result = config;
  if (!root.IsMap()) {
    // empty document: defaults; anything else: its error
    applyConfigKeysYaml(yaml_text, result.hpds, source, validation);
  } else {
    YAML::Node rest(YAML::NodeType::Map);
    try {
      for (const auto &entry : root) {
        const std::string name = entry.first.IsScalar() ? entry.first.Scalar() : std::string();
        static const char *const kRosLeaves[] = {"fixed_frame",      "output_frame",   "sensor_frame",
                                                 "tf_timeout",       "local_map_radius", "local_map_rate",
                                                 "publish_levels",   "queue_size",     "map_file",
                                                 "load_map_on_start", "save_map_on_shutdown"};
        if (name == "ros") {
          applyRosSection(entry.second, result.ros);
        } else if (std::find(std::begin(kRosLeaves), std::end(kRosLeaves), name) != std::end(kRosLeaves)) {
          fail(name, "unknown key (did you mean 'ros." + name + "'? the node's own keys are under ros/)");
        } else if (name == "input" && entry.second.IsScalar()) {
          // `_input:=/velodyne_points` sets a parameter; the topic is a remapping.
          fail(name, "expected a map of input.* keys (skip_zero_points, min_range, max_range), got '" +
                         entry.second.Scalar() + "': the topic is not a parameter, remap it: ~input:=" +
                         entry.second.Scalar());
        } else if (name == "diagnostic_period") {
          result.diagnostic_period = checkDiagnosticPeriod(parseNumber(entry.second, name));
        } else if (std::find(ignored_keys.begin(), ignored_keys.end(), name) == ignored_keys.end()) {
          rest[entry.first] = entry.second;
        }
      }
    } catch (const std::invalid_argument &e) {
      throw std::invalid_argument(e.what() + suffix);
    }
    YAML::Emitter out;
    emit(out, rest);
    applyConfigKeysYaml(rest.size() ? std::string(out.c_str()) : std::string(), result.hpds, source, validation);
  }
  try {
    if (validation == ConfigValidation::kNow) validateRosConfig(result.ros, result.hpds);
  } catch (const std::invalid_argument &e) {
    throw std::invalid_argument(e.what() + suffix);
  }
  config = std::move(result);
}

void validateRosSectionOfFile(const std::string &path) {
  const NodeConfig file = loadNodeConfigFile(path, ConfigValidation::kByCaller);
  try {
    validateRosConfig(file.ros, file.hpds);
  } catch (const std::invalid_argument &e) {
    throw std::invalid_argument(std::string(e.what()) + " (in " + path + ")");
  }
}

NodeConfig loadNodeConfigFile(const std::string &path, ConfigValidation validation) {
  NodeConfig config;
  applyNodeConfigYaml(readConfigFile(path), config, path, validation);
  return config;
}

std::string dumpRosConfigYaml(const RosConfig &ros) {
  std::ostringstream s;
  s << "ros:\n";
  s << "  fixed_frame: " << quoted(ros.fixed_frame) << "\n";
  s << "  output_frame: " << quoted(ros.output_frame) << "\n";
  s << "  sensor_frame: " << quoted(ros.sensor_frame) << "\n";
  s << "  tf_timeout: " << formatDouble(ros.tf_timeout) << "\n";
  s << "  local_map_radius: " << formatDouble(ros.local_map_radius) << "\n";
  s << "  local_map_rate: " << formatDouble(ros.local_map_rate) << "\n";
  s << "  publish_levels: [";
  for (std::size_t i = 0; i < ros.publish_levels.size(); ++i) s << (i ? ", " : "") << ros.publish_levels[i];
  s << "]\n";
  s << "  queue_size: " << ros.queue_size << "\n";
  s << "  map_file: " << quoted(ros.map_file) << "\n";
  s << "  load_map_on_start: " << (ros.load_map_on_start ? "true" : "false") << "\n";
  s << "  save_map_on_shutdown: " << (ros.save_map_on_shutdown ? "true" : "false") << "\n";
  return s.str();
}

}  // namespace hpds
