// Strict YAML scalars: the one parser of numbers, integers and booleans behind config files (ConfigYaml) and the
// ROS node's parameters (hpds_node/NodeConfig), so both accept and refuse exactly the same text.
//
// Contract
// - Input is a scalar's text as written and whether it was quoted; yaml-cpp stays out of this header.
// - Numbers must be plain (a quoted "4.0" is a string in YAML and is refused), in YAML 1.2 core-schema decimal
//   form, or [-+].inf/.Inf/.INF or .nan/.NaN/.NAN; validation of the value's range belongs to the
//   caller. Integers: optional sign and digits only (no 1.5, 1e3 or hex). Booleans: plain true/false only (not
//   YAML 1.1's yes/no/on/off). Locale-independent (std::from_chars).
// - Every error is std::invalid_argument "<key>: expected ..., got '<text>'".
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace hpds::yaml {

[[nodiscard]] double parseNumber(std::string_view text, bool quoted, const std::string &key);
[[nodiscard]] int parseInt(std::string_view text, bool quoted, const std::string &key);
[[nodiscard]] std::uint64_t parseUInt64(std::string_view text, bool quoted, const std::string &key);
[[nodiscard]] bool parseBool(std::string_view text, bool quoted, const std::string &key);

/// Shortest text that parses back to the same double, with ".0" added to integral values (so that people and other
/// YAML tools read a double), and .inf/-.inf/.nan for the non-finite values.
[[nodiscard]] std::string formatNumber(double value);

}  // namespace hpds::yaml
