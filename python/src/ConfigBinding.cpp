// The config as Python sees it: named by a YAML file or by YAML text (python/hpds/config.py turns a dict into it),
// loaded by the core's own loader so that validation and messages are those of the CLI and the node.
#include <yaml-cpp/yaml.h>

#include <cctype>
#include <stdexcept>

#include "Bindings.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/config/NodeConfig.hpp"
#include "hpds/config/YamlScalar.hpp"
#include "hpds/pipeline/OutputCloud.hpp"

namespace py = pybind11;

namespace hpds::python {

HpdsConfig configFrom(const std::string &yaml_text, const std::string &path) {
  return path.empty() ? loadConfigString(yaml_text) : loadConfigFile(path);
}

namespace {

// A scalar of dumpConfigYaml's output as the Python value it stands for: the dump writes booleans as true/false,
// integers as bare digits, every double with a '.' or an exponent (or .inf/.nan), and enums by name.
py::object scalarValue(const std::string &text, const std::string &key) {
  if (text == "true") return py::bool_(true);
  if (text == "false") return py::bool_(false);
  const bool integer = !text.empty() && text.find_first_not_of("+-0123456789") == std::string::npos &&
                       std::isdigit(static_cast<unsigned char>(text.back()));
  if (integer) return py::reinterpret_steal<py::object>(PyLong_FromString(text.c_str(), nullptr, 10));
  try {
    return py::float_(yaml::parseNumber(text, false, key));
  } catch (const std::invalid_argument &) {
    return py::str(text);
  }
}

py::object toPython(const YAML::Node &node, const std::string &key) {
  if (node.IsMap()) {
    py::dict d;
    for (const auto &kv : node) {
      const std::string name = kv.first.as<std::string>();
      d[py::str(name)] = toPython(kv.second, key.empty() ? name : key + "." + name);
    }
    return std::move(d);
  }
  if (node.IsScalar()) return scalarValue(node.Scalar(), key);
  throw std::logic_error("config dump: unexpected YAML node at " + key);
}

}  // namespace

void bindConfig(py::module_ &m) {
  m.def(
      "config_yaml",
      [](const std::string &yaml_text, const std::string &path, const std::string &overlay) {
        if (overlay.empty()) return dumpConfigYaml(configFrom(yaml_text, path));
        // Its `ros:` section as the node reads the file, which the overlay does not touch (hpds sample does this too).
        if (!path.empty()) validateRosSectionOfFile(path);
        // The file's values are judged with the overlay over them, as the CLI judges a --config with its flags.
        HpdsConfig config;
        applyConfigYaml(path.empty() ? yaml_text : readConfigFile(path), config, path, ConfigValidation::kByCaller);
        applyConfigYaml(overlay, config, "", ConfigValidation::kByCaller);
        try {
          validateConfig(config);
        } catch (const std::invalid_argument &e) {
          throw std::invalid_argument(std::string(e.what()) +
                                      (path.empty() ? std::string() : " (in " + path + ", with the flags over it)"));
        }
        return dumpConfigYaml(config);
      },
      py::arg("config_yaml"), py::arg("config_path"), py::arg("overlay") = std::string(),
      "Every key of the config (YAML file `config_path` if not empty, else `config_yaml` over the defaults, then the "
      "keys of `overlay` over it), validated, as complete YAML text.");
  m.def(
      "widen_xyz_for_poses",
      [](const std::string &yaml_text, double largest_translation, const std::string &float32_key) {
        HpdsConfig config = loadConfigString(yaml_text);
        const std::string note = widenXyzForPoses(config, largest_translation, float32_key);
        return py::make_tuple(note.empty() ? yaml_text : dumpConfigYaml(config), note);
      },
      py::arg("config_yaml"), py::arg("largest_translation"), py::arg("float32_key"),
      "(config YAML, note): output.float64_xyz set where poses this far from the origin would make float32 x y z "
      "round by over 1 % of the output radius and the config chose no type (hpds::widenXyzForPoses); else the same "
      "YAML and an empty note.");
  m.def(
      "config_dict",
      [](const std::string &yaml_text, const std::string &path) {
        const std::string dump = dumpConfigYaml(configFrom(yaml_text, path));
        return toPython(YAML::Load(dump), "");
      },
      py::arg("config_yaml"), py::arg("config_path"), "The same config as a dict of sections.");
  m.def(
      "key_range_advice",
      [](const std::string &yaml_text, const std::string &path) { return keyRangeAdvice(configFrom(yaml_text, path)); },
      py::arg("config_yaml"), py::arg("config_path"),
      "How far the config's exact keys reach and which settings widen that reach (hpds::keyRangeAdvice).");
}

}  // namespace hpds::python
