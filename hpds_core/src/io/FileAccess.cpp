#include "io/FileAccess.hpp"

#include <filesystem>
#include <system_error>

namespace hpds::io_detail {

std::string quote(std::string_view text) {
  constexpr std::size_t kMax = 40;
  std::string out = "'";
  for (std::size_t i = 0; i < text.size() && i < kMax; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (text.size() > kMax) out += "...";
  return out + "'";
}

void requireRegularFile(const std::string &path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) fail(path, "file not found");
  if (status.type() == fs::file_type::none) fail(path, "cannot access: " + ec.message());
  if (!fs::is_regular_file(status)) fail(path, "not a regular file");
}

}  // namespace hpds::io_detail
