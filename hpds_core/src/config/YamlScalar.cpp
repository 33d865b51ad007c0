#include "hpds/config/YamlScalar.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>

namespace hpds::yaml {

namespace {

[[noreturn]] void fail(const std::string &key, const std::string &why) {
  throw std::invalid_argument(key + ": " + why);
}

// "the quoted string '4.0'" says why a number was not taken; a plain scalar is shown as written.
std::string shown(std::string_view text, bool quoted) {
  return quoted ? "the quoted string '" + std::string(text) + "'" : "'" + std::string(text) + "'";
}

// Numbers and booleans must be plain scalars: accepting a quoted one would hide a quoting mistake in whatever
// generated the text.
void requirePlain(std::string_view text, bool quoted, const std::string &key, const char *expected) {
  if (quoted) fail(key, std::string("expected ") + expected + ", got " + shown(text, quoted));
}

bool isDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

// YAML 1.2 core-schema decimal number: [-+]? ( . digits | digits ( . digits? )? ) ( [eE] [-+]? digits )?
bool isDecimalNumber(std::string_view s) {
  std::size_t i = 0;
  if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
  std::size_t mantissa_digits = 0;
  while (i < s.size() && isDigit(s[i])) ++i, ++mantissa_digits;
  if (i < s.size() && s[i] == '.') {
    ++i;
    while (i < s.size() && isDigit(s[i])) ++i, ++mantissa_digits;
  }
  if (mantissa_digits == 0) return false;
  if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
    ++i;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
    std::size_t exponent_digits = 0;
    while (i < s.size() && isDigit(s[i])) ++i, ++exponent_digits;
    if (exponent_digits == 0) return false;
  }
  return i == s.size();
}

// A YAML 1.1 reader (rosparam, PyYAML) takes 010 as octal 8 and 09 as a string: the same file would mean one number
// to hpds and another to the node's parameter server. Refused like yes/no and quoted numbers.
void refuseLeadingZero(std::string_view digits, std::string_view text, const std::string &key) {
  if (digits.size() > 1 && digits[0] == '0')
    fail(key, "'" + std::string(text) + "' has a leading zero, which YAML 1.1 readers (rosparam) take as an octal "
                  "number; write it without the zero");
}

template <typename Int>
Int parseInteger(std::string_view text, bool quoted, const std::string &key) {
  constexpr bool kUnsigned = std::is_unsigned_v<Int>;
  const char *expected = kUnsigned ? "a non-negative integer" : "an integer";
  requirePlain(text, quoted, key, expected);
  std::string_view number = text;
  if (!number.empty() && number[0] == '+') number.remove_prefix(1);
  std::string_view digits = number;
  if (!kUnsigned && !digits.empty() && digits[0] == '-') digits.remove_prefix(1);
  if (digits.empty() || !std::all_of(digits.begin(), digits.end(), isDigit))
    fail(key, std::string("expected ") + expected + ", got '" + std::string(text) + "'");
  refuseLeadingZero(digits, text, key);
  Int value{};
  const auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), value);
  if (ec == std::errc::result_out_of_range)
    fail(key, "integer out of range " + std::to_string(std::numeric_limits<Int>::min()) + ".." +
                  std::to_string(std::numeric_limits<Int>::max()) + ", got '" + std::string(text) + "'");
  if (ec != std::errc() || end != number.data() + number.size())
    fail(key, std::string("expected ") + expected + ", got '" + std::string(text) + "'");
  return value;
}

}  // namespace

double parseNumber(std::string_view text, bool quoted, const std::string &key) {
  requirePlain(text, quoted, key, "a number");
  std::string_view body = text;
  const bool negative = !body.empty() && body[0] == '-';
  if (!body.empty() && (body[0] == '+' || body[0] == '-')) body.remove_prefix(1);
  // Non-finite values parse so that the caller's validation, not the parser, reports them with the key's own rule.
  if (body == ".inf" || body == ".Inf" || body == ".INF")
    return negative ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
  if (text == ".nan" || text == ".NaN" || text == ".NAN") return std::numeric_limits<double>::quiet_NaN();
  if (!isDecimalNumber(text)) fail(key, "expected a number, got '" + std::string(text) + "'");
  if (std::all_of(body.begin(), body.end(), isDigit)) refuseLeadingZero(body, text, key);
  double value = 0.0;
  const auto [end, ec] = std::from_chars(body.data(), body.data() + body.size(), value);
  if (ec == std::errc::result_out_of_range)
    fail(key, "number out of the range of a double, got '" + std::string(text) + "'");
  if (ec != std::errc() || end != body.data() + body.size())
    fail(key, "expected a number, got '" + std::string(text) + "'");
  return negative ? -value : value;
}

int parseInt(std::string_view text, bool quoted, const std::string &key) {
  return parseInteger<int>(text, quoted, key);
}

std::uint64_t parseUInt64(std::string_view text, bool quoted, const std::string &key) {
  return parseInteger<std::uint64_t>(text, quoted, key);
}

bool parseBool(std::string_view text, bool quoted, const std::string &key) {
  requirePlain(text, quoted, key, "true or false");
  if (text == "true") return true;
  if (text == "false") return false;
  fail(key, "expected true or false, got '" + std::string(text) + "'");
}

std::string formatNumber(double value) {
  if (std::isnan(value)) return ".nan";
  if (std::isinf(value)) return value > 0 ? ".inf" : "-.inf";
  char buffer[64];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, value);  // shortest text that round-trips
  std::string text(buffer, ec == std::errc() ? end : buffer);
  if (text.find_first_of(".e") == std::string::npos) text += ".0";
  return text;
}

}  // namespace hpds::yaml
