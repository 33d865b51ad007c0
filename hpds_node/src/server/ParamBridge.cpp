#include "hpds_node/ParamBridge.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "hpds/config/YamlScalar.hpp"
#include "hpds_node/NodeConfig.hpp"

namespace hpds_node {

namespace {

void emitParam(YAML::Emitter &out, XmlRpc::XmlRpcValue &v) {
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeStruct:
      out << YAML::BeginMap;
      for (auto &item : v) {
        out << YAML::Key << item.first << YAML::Value;
        emitParam(out, item.second);
      }
      out << YAML::EndMap;
      break;
    case XmlRpc::XmlRpcValue::TypeArray:
      out << YAML::Flow << YAML::BeginSeq;
      for (int i = 0; i < v.size(); ++i) emitParam(out, v[i]);
      out << YAML::EndSeq;
      break;
    case XmlRpc::XmlRpcValue::TypeInt:
      out << static_cast<int>(v);
      break;
    case XmlRpc::XmlRpcValue::TypeDouble: {
      // Shortest round-trip text, so the value the loader sees is the double rosparam holds. XML-RPC integers are
      // 32-bit: rosparam turns a larger one (order/seed 5000000000) into a double, which is written back as the
      // integer it was while a double holds it exactly (up to 2^53).
      const double d = static_cast<double>(v);
      if (!std::isfinite(d))
        out << d;  // the emitter writes .nan/.inf/-.inf plain; as text they came out quoted, a "string"
      else if (std::fabs(d) >= 2147483648.0 && std::fabs(d) <= 9007199254740992.0 && d == std::floor(d))
        out << std::to_string(static_cast<long long>(d));
      else
        out << hpds::yaml::formatNumber(d);
      break;
    }
    case XmlRpc::XmlRpcValue::TypeBoolean:
      out << (static_cast<bool>(v) ? "true" : "false");
      break;
    case XmlRpc::XmlRpcValue::TypeString:
      // Quoted: a string parameter "4.0" must reach the loader as a string, which it refuses for a number key.
      out << YAML::DoubleQuoted << static_cast<std::string &>(v);
      break;
    default:
      out << YAML::DoubleQuoted << "<unsupported parameter type>";
      break;
  }
}

}  // namespace

NodeConfig loadNodeConfigFromParams(const ros::NodeHandle &private_nh) {
  NodeConfig config;
  const std::string ns = private_nh.getNamespace();
  std::string file;
  if (private_nh.hasParam("config_file") && !private_nh.getParam("config_file", file))
    throw std::invalid_argument("parameter " + ns + "/config_file: expected the path of a YAML file (a string)");
  if (!file.empty()) {
    try {
      config = loadNodeConfigFile(file);
    } catch (const std::invalid_argument &e) {
      throw std::invalid_argument(std::string(e.what()) + " [parameter " + ns + "/config_file]");
    }
  }
  XmlRpc::XmlRpcValue params;
  if (private_nh.getParam(ns, params) && params.getType() == XmlRpc::XmlRpcValue::TypeStruct) {
    YAML::Emitter out;
    emitParam(out, params);
    try {
      applyNodeConfigYaml(out.c_str(), config, "");
    } catch (const std::invalid_argument &e) {
      // The loader names the dotted key ("hierarchy.max_depth: ..."); say which parameter that is. Its "the quoted
      // string" speaks of YAML text; here the value was a string parameter (`_output/spacing:=abc`).
      std::string what = e.what();
      const std::string yaml_words = "the quoted string '";
      if (const std::size_t at = what.find(yaml_words); at != std::string::npos)
        what.replace(at, yaml_words.size(), "the string parameter '");
      const std::size_t colon = what.find(": ");
      const std::string key = what.substr(0, colon);
      if (colon == std::string::npos || key.empty() || key.find_first_of(" ()'") != std::string::npos)
        throw std::invalid_argument(what + " (in the private parameters of " + ns + ")");
      std::string param = key;
      std::replace(param.begin(), param.end(), '.', '/');
      throw std::invalid_argument("parameter " + ns + "/" + param + what.substr(colon));
    }
  }
  return config;
}

}  // namespace hpds_node
