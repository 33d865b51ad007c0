#include "hpds/config/ConfigYaml.hpp"

#include "ConfigKeysYaml.hpp"
#include "hpds/config/NodeConfig.hpp"
#include "hpds/config/YamlScalar.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string_view>
#include <variant>

namespace hpds {

namespace {

// ---------------------------------------------------------------------------------------------------------------
// The key table: the only list of config keys. Load, dump, configKeys() and the unknown-key suggestions all read
// it, so a key cannot exist in one direction and be missing in the other.

using FieldRef = std::variant<double *, int *, std::uint64_t *, bool *, Mode *, InsertionOrder *>;

struct Key {
  const char *section;  // "" for the top-level scalars
  const char *name;
  FieldRef (*ref)(HpdsConfig &);

  [[nodiscard]] std::string dotted() const {
    return *section != '\0' ? std::string(section) + "." + name : std::string(name);
  }
};

template <auto Member>
FieldRef topRef(HpdsConfig &c) {
  return &(c.*Member);
}

template <auto Section, auto Member>
FieldRef sectionRef(HpdsConfig &c) {
  return &((c.*Section).*Member);
}

// Stringizing the member makes the YAML key equal to the C++ member name by construction, and the member
// pointer gives the variant alternative, so a row cannot pair a name with the wrong field or type.
#define HPDS_TOP_KEY(member) \
  Key { "", #member, &topRef<&HpdsConfig::member> }
#define HPDS_SECTION_KEY(section, member) \
  Key { #section, #member, &sectionRef<&HpdsConfig::section, &decltype(HpdsConfig::section)::member> }

// Struct order; rows of one section must stay contiguous because the dump opens a section where its first row is.
constexpr Key kKeys[] = {
    HPDS_TOP_KEY(mode),
    HPDS_SECTION_KEY(hierarchy, cell_size),
    HPDS_SECTION_KEY(hierarchy, max_depth),
    HPDS_SECTION_KEY(order, type),
    HPDS_SECTION_KEY(order, seed),
    HPDS_SECTION_KEY(order, feature_radius),
    HPDS_SECTION_KEY(output, level),
    HPDS_SECTION_KEY(output, spacing),
    HPDS_SECTION_KEY(output, float64_xyz),
    HPDS_SECTION_KEY(output, float32_xyz),
    HPDS_SECTION_KEY(normals, enabled),
    HPDS_SECTION_KEY(normals, radius),
    HPDS_SECTION_KEY(normals, k),
    HPDS_SECTION_KEY(normals, min_neighbors),
    HPDS_SECTION_KEY(normals, neighborhood_level_offset),
    HPDS_SECTION_KEY(normals, max_growth),
    HPDS_SECTION_KEY(normals, covariances),
    HPDS_SECTION_KEY(normals, covariance_epsilon),
    HPDS_SECTION_KEY(normals, covariance_line_ratio),
    HPDS_SECTION_KEY(normals, covariance_k),
    HPDS_SECTION_KEY(map, evict_distance),
    HPDS_SECTION_KEY(map, max_samples),
    HPDS_SECTION_KEY(map, keep_depth),
    HPDS_SECTION_KEY(input, skip_zero_points),
    HPDS_SECTION_KEY(input, min_range),
    HPDS_SECTION_KEY(input, max_range),
    HPDS_TOP_KEY(threads),
};

#undef HPDS_TOP_KEY
#undef HPDS_SECTION_KEY

// Adding a member to any config struct breaks one of these bindings at compile time, which sends its author
// here to add the member's row above (test_config then insists on it in config/hpds.yaml as well).
[[maybe_unused]] void everyMemberHasARow(HpdsConfig &c) {
  [[maybe_unused]] auto &[mode, hierarchy, order, output, normals, map, input, threads] = c;
  [[maybe_unused]] auto &[cell_size, max_depth] = c.hierarchy;
  [[maybe_unused]] auto &[type, seed, feature_radius] = c.order;
  [[maybe_unused]] auto &[level, spacing, float64_xyz, float32_xyz] = c.output;
  [[maybe_unused]] auto &[enabled, radius, k, min_neighbors, neighborhood_level_offset, max_growth, covariances,
                           covariance_epsilon, covariance_line_ratio, covariance_k] = c.normals;
  [[maybe_unused]] auto &[evict_distance, max_samples, keep_depth] = c.map;
  [[maybe_unused]] auto &[skip_zero_points, min_range, max_range] = c.input;
}
static_assert(std::size(kKeys) == 2 + 2 + 3 + 4 + 10 + 3 + 3,
              "one row per leaf bound in everyMemberHasARow: the top-level scalars plus every section member");

const Key *findKey(std::string_view section, std::string_view name) {
  for (const Key &key : kKeys)
    if (section == key.section && name == key.name) return &key;
  return nullptr;
}

bool isSection(std::string_view name) {
  return !name.empty() && std::any_of(std::begin(kKeys), std::end(kKeys),
                                      [&](const Key &key) { return name == key.section; });
}

// ---------------------------------------------------------------------------------------------------------------
// Errors

constexpr const char *kDocument = "(document)";

[[noreturn]] void fail(const std::string &key, const std::string &why) {
  throw std::invalid_argument(key + ": " + why);
}

std::string describe(const YAML::Node &node) {
  switch (node.Type()) {
    case YAML::NodeType::Null:
      return "nothing (null)";
    case YAML::NodeType::Sequence:
      return "a sequence";
    case YAML::NodeType::Map:
      return "a map";
    case YAML::NodeType::Scalar: {
      // A file that is no config at all (found: /etc/passwd as config_file) reads as one long scalar: its start
      // says what it is, the whole of it would fill the terminal.
      constexpr std::size_t kShown = 80;
      std::string text = node.Scalar();
      if (text.size() > kShown) text = text.substr(0, kShown) + "... (" + std::to_string(text.size()) + " characters)";
      // yaml-cpp tags quoted scalars "!"; saying so explains why '4.0' was not taken as a number.
      return node.Tag() == "!" ? "the quoted string '" + text + "'" : "'" + text + "'";
    }
    case YAML::NodeType::Undefined:
      break;
  }
  return "an undefined node";
}

std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

[[noreturn]] void failUnknown(const std::string &dotted) {
  // Typos are matched on the whole dotted key, so a misspelt section ("hierachy") is caught too.
  std::string best;
  std::size_t best_distance = 3;
  auto consider = [&](const std::string &candidate) {
    const std::size_t d = editDistance(dotted, candidate);
    if (d < best_distance) {
      best_distance = d;
      best = candidate;
    }
  };
  for (const Key &key : kKeys) {
    consider(key.dotted());
    if (*key.section != '\0') consider(key.section);
  }
  // A correct name in the wrong place (top-level "cell_size", "hierarchy.seed") is the other common slip.
  if (best.empty()) {
    const std::size_t dot = dotted.rfind('.');
    const std::string leaf = dot == std::string::npos ? dotted : dotted.substr(dot + 1);
    for (const Key &key : kKeys)
      if (leaf == key.name) {
        best = key.dotted();
        break;
      }
  }
  // A dotted name written as one key ({"output.spacing": 0.2}, a ROS-parameter habit) matches a key exactly.
  if (best_distance == 0 && best.find('.') != std::string::npos) {
    const std::size_t dot = best.find('.');
    fail(dotted, "unknown key: a dotted name is not a key; write it nested, as key '" + best.substr(dot + 1) +
                     "' under section '" + best.substr(0, dot) + "'");
  }
  fail(dotted, best.empty() ? "unknown key" : "unknown key (did you mean '" + best + "'?)");
}

// ---------------------------------------------------------------------------------------------------------------
// Scalars. Parsed from the scalar text (YamlScalar.hpp) rather than with yaml-cpp's as<T>(), whose stream
// conversions accept things this file must reject (yes/no, 1.5 for an int, hex) and depend on the global locale.

// yaml-cpp tags quoted scalars "!" and plain untagged ones "?". Any other tag (!!str, !!int, !custom) would change
// what the value means to a YAML reader while hpds read the text alone: refused, naming the key.
bool isQuoted(const YAML::Node &node) { return node.Tag() == "!"; }
void refuseTag(const YAML::Node &node, const std::string &key) {
  const std::string &tag = node.Tag();
  if (tag.empty() || tag == "?" || tag == "!") return;
  const std::string shown = tag.rfind("tag:yaml.org,2002:", 0) == 0 ? "!!" + tag.substr(18) : tag;
  fail(key, "has the YAML tag " + shown + "; config values are plain scalars (remove the tag)");
}

// A value must be an untagged scalar; the text itself goes to the one strict scalar parser (YamlScalar.hpp), or is
// an enum's name.
const std::string &scalarText(const YAML::Node &node, const std::string &key, const char *expected) {
  if (!node.IsScalar()) fail(key, std::string("expected ") + expected + ", got " + describe(node));
  refuseTag(node, key);
  return node.Scalar();
}

void parseValue(const YAML::Node &node, const std::string &key, double *out) {
  *out = yaml::parseNumber(scalarText(node, key, "a number"), isQuoted(node), key);
}
void parseValue(const YAML::Node &node, const std::string &key, int *out) {
  *out = yaml::parseInt(scalarText(node, key, "an integer"), isQuoted(node), key);
}
void parseValue(const YAML::Node &node, const std::string &key, std::uint64_t *out) {
  *out = yaml::parseUInt64(scalarText(node, key, "a non-negative integer"), isQuoted(node), key);
}
void parseValue(const YAML::Node &node, const std::string &key, bool *out) {
  *out = yaml::parseBool(scalarText(node, key, "true or false"), isQuoted(node), key);
}

const std::string &enumScalar(const YAML::Node &node, const std::string &key) {
  return scalarText(node, key, "a string");
}

void parseValue(const YAML::Node &node, const std::string &key, Mode *out) {
  *out = parseMode(enumScalar(node, key), key);
}

void parseValue(const YAML::Node &node, const std::string &key, InsertionOrder *out) {
  *out = parseInsertionOrder(enumScalar(node, key), key);
}

std::string formatValue(double v) { return yaml::formatNumber(v); }
std::string formatValue(int v) { return std::to_string(v); }
std::string formatValue(std::uint64_t v) { return std::to_string(v); }
std::string formatValue(bool v) { return v ? "true" : "false"; }
std::string formatValue(Mode v) { return toString(v); }
std::string formatValue(InsertionOrder v) { return toString(v); }

// ---------------------------------------------------------------------------------------------------------------
// Documents

std::string keyText(const YAML::Node &key_node, const std::string &where) {
  if (!key_node.IsScalar()) fail(where, "map keys must be strings, got " + describe(key_node));
  return key_node.Scalar();
}

// yaml-cpp keeps both entries of a repeated key; without this check the last one would silently win.
void rejectDuplicate(std::vector<std::string> &seen, const std::string &dotted) {
  if (std::find(seen.begin(), seen.end(), dotted) != seen.end()) fail(dotted, "duplicate key");
  seen.push_back(dotted);
}

void assign(const YAML::Node &value, const std::string &dotted, const Key &key, HpdsConfig &config) {
  std::visit([&](auto *field) { parseValue(value, dotted, field); }, key.ref(config));
}

// Lines of the text, without comments and trailing blanks, that mean something to a YAML parser.
std::vector<std::string_view> meaningfulLines(std::string_view text) {
  std::vector<std::string_view> lines;
  while (!text.empty()) {
    const std::size_t nl = text.find('\n');
    std::string_view line = text.substr(0, nl);
    text = nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
    // A '#' starts a comment at the line start or after a blank (our keys and values never contain one).
    for (std::size_t i = 0; i < line.size(); ++i)
      if (line[i] == '#' && (i == 0 || line[i - 1] == ' ' || line[i - 1] == '\t')) {
        line = line.substr(0, i);
        break;
      }
    while (!line.empty() && (line.back() == ' ' || line.back() == '\t' || line.back() == '\r')) line.remove_suffix(1);
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

bool isMarker(std::string_view line, std::string_view marker) {
  return line.substr(0, 3) == marker && (line.size() == 3 || line[3] == ' ' || line[3] == '\t');
}

// Documents in the text: a "---" at column 0 after content, or content after a "..." end marker, starts another.
std::size_t countDocuments(std::string_view text) {
  std::size_t documents = 0;
  bool open = false;  // a document has started and not been ended by "..."
  bool content = false;
  for (std::string_view line : meaningfulLines(text)) {
    if (line[0] == '%') continue;  // directives
    if (isMarker(line, "---")) {
      if (open && content) ++documents;
      open = true;
      content = line.size() > 3;
      continue;
    }
    if (isMarker(line, "...")) {
      if (open || content) ++documents;
      open = content = false;
      continue;
    }
    open = content = true;
  }
  return documents + (open ? 1 : 0);
}

// True when the text holds anything besides comments, directives, markers and an explicit null.
bool hasContent(std::string_view text) {
  for (std::string_view line : meaningfulLines(text)) {
    if (line[0] == '%' || isMarker(line, "---") || isMarker(line, "...")) continue;
    if (line == "~" || line == "null" || line == "Null" || line == "NULL") continue;
    return true;
  }
  return false;
}

// Top-level section owned by the ROS node: NodeConfig reads and validates it before the keys come here.
constexpr const char *kRosSection = "ros";
constexpr const char *kRosDiagnosticPeriod = "diagnostic_period";

void applyDocument(const YAML::Node &root, HpdsConfig &config) {
  if (root.IsNull()) return;  // empty file or a file of comments: all defaults
  if (!root.IsMap()) fail(kDocument, "expected a map of config keys, got " + describe(root));
  std::vector<std::string> seen;
  for (const auto &entry : root) {
    const std::string name = keyText(entry.first, kDocument);
    rejectDuplicate(seen, name);
    if (const Key *key = findKey("", name)) {
      assign(entry.second, name, *key, config);
      continue;
    }
    const YAML::Node &section = entry.second;
    if (name == kRosSection) {
      // The ROS node's own settings (topics' frames, rates, queue): read and validated by NodeConfig, which keeps
      // one file for the node and the CLI. Here only its shape is checked.
      if (!section.IsNull() && !section.IsMap()) fail(name, "expected a map of ros.* keys, got " + describe(section));
      continue;
    }
    if (name == kRosDiagnosticPeriod) continue;  // the node's diagnostics period, validated by NodeConfig
    if (!isSection(name)) failUnknown(name);
    if (section.IsNull()) continue;  // a section whose keys are all commented out
    if (!section.IsMap()) fail(name, "expected a map of " + name + ".* keys, got " + describe(section));
    for (const auto &item : section) {
      const std::string leaf = keyText(item.first, name);
      const std::string dotted = name + "." + leaf;
      rejectDuplicate(seen, dotted);
      const Key *key = findKey(name, leaf);
      if (key == nullptr) failUnknown(dotted);
      assign(item.second, dotted, *key, config);
    }
  }
}

}  // namespace

namespace yaml_node {
std::string describeNode(const YAML::Node &node) { return describe(node); }
bool isQuotedScalar(const YAML::Node &node) { return isQuoted(node); }
void refuseExplicitTag(const YAML::Node &node, const std::string &key) { refuseTag(node, key); }
const std::string &plainScalarText(const YAML::Node &node, const std::string &key, const char *expected) {
  return scalarText(node, key, expected);
}
}  // namespace yaml_node

void applyConfigKeysYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source,
                         ConfigValidation validation) {
  try {
    // yaml-cpp takes a few hundred bytes per node: a 6 MB sequence took 1.4 GB.
    if (yaml_text.size() > kMaxConfigBytes)
      fail(kDocument, std::to_string(yaml_text.size()) + " bytes, more than the " + std::to_string(kMaxConfigBytes) +
                          " a config may have");
    // yaml-cpp 0.7's LoadAll never returns on some garbage (a lone ','), so documents are counted here and the
    // text is parsed with Load, which does return.
    // A NUL byte ends the text for yaml-cpp's scanner partway, which then reports whatever follows oddly (an
    // "unknown escape character"); say what it is.
    if (const std::size_t nul = yaml_text.find('\0'); nul != std::string::npos) {
      const std::size_t line = 1 + static_cast<std::size_t>(std::count(yaml_text.begin(), yaml_text.begin() + nul, '\n'));
      fail(kDocument, "a NUL byte at line " + std::to_string(line) + " (byte " + std::to_string(nul) +
                          "): a config is YAML text");
    }
    const std::size_t documents = countDocuments(yaml_text);
    if (documents > 1) fail(kDocument, "expected one YAML document, got " + std::to_string(documents));
    YAML::Node document;
    try {
      document = YAML::Load(yaml_text);
    } catch (const YAML::Exception &e) {
      std::string where;
      if (!e.mark.is_null())
        where = " at line " + std::to_string(e.mark.line + 1) + ", column " + std::to_string(e.mark.column + 1);
      fail(kDocument, "YAML syntax error" + where + ": " + e.msg);
    }
    // Load reads some garbage (a lone ',') as an empty document; only comments and markers may be empty.
    if (document.IsNull() && hasContent(yaml_text))
      fail(kDocument, "expected a map of config keys, got text that is not YAML");
    HpdsConfig result = config;  // work on a copy so a failure leaves the caller's config untouched
    applyDocument(document, result);
    if (validation == ConfigValidation::kNow) validateConfig(result);
    config = result;
  } catch (const std::invalid_argument &e) {
    if (source.empty()) throw;
    throw std::invalid_argument(std::string(e.what()) + " (in " + source + ")");
  }
}

void applyConfigYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source) {
  applyConfigYaml(yaml_text, config, source, ConfigValidation::kNow);
}

void applyConfigYaml(const std::string &yaml_text, HpdsConfig &config, const std::string &source,
                     ConfigValidation validation) {
  // The whole file as the node reads it: its `ros:` section and diagnostic_period are validated, then dropped.
  NodeConfig node;
  node.hpds = config;
  applyNodeConfigYaml(yaml_text, node, source, validation);
  config = node.hpds;
}

HpdsConfig loadConfigString(const std::string &yaml_text) {
  HpdsConfig config;
  applyConfigYaml(yaml_text, config);
  return config;
}

std::string readConfigFile(const std::string &path) {
  namespace fs = std::filesystem;
  const auto refuse = [&](const std::string &why) { throw std::invalid_argument("config file '" + path + "': " + why); };
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status)) refuse("no such file");
  if (fs::is_directory(status)) refuse("is a directory");
  // A device or a FIFO (/dev/zero, /dev/stdin) would be read without end.
  if (!fs::is_regular_file(status)) refuse("not a regular file (a config is a YAML text file)");
  std::ifstream in(path, std::ios::binary);
  if (!in) refuse("cannot be opened");
  // Read one byte past the limit, whatever the size said: the file may grow meanwhile.
  std::string text(kMaxConfigBytes + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  if (in.bad()) refuse("read error");
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxConfigBytes)
    refuse("larger than " + std::to_string(kMaxConfigBytes) + " bytes, the most a config file may have");
  return text;
}

HpdsConfig loadConfigFile(const std::string &path) { return loadConfigFile(path, ConfigValidation::kNow); }

HpdsConfig loadConfigFile(const std::string &path, ConfigValidation validation) {
  HpdsConfig config;
  applyConfigYaml(readConfigFile(path), config, path, validation);
  return config;
}

std::string dumpConfigYaml(const HpdsConfig &config) {
  HpdsConfig copy = config;  // the key table hands out mutable field pointers
  std::string out;
  std::string_view open_section;
  for (const Key &key : kKeys) {
    if (open_section != key.section) {
      open_section = key.section;
      if (!open_section.empty()) out.append(open_section).append(":\n");
    }
    if (!open_section.empty()) out += "  ";
    out.append(key.name).append(": ");
    out += std::visit([](const auto *field) { return formatValue(*field); }, key.ref(copy));
    out += '\n';
  }
  return out;
}

std::vector<std::string> configKeys() {
  std::vector<std::string> keys;
  keys.reserve(std::size(kKeys));
  for (const Key &key : kKeys) keys.push_back(key.dotted());
  return keys;
}

}  // namespace hpds
