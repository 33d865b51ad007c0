#include "io/FileAccess.hpp"

#include <filesystem>
#include <system_error>

namespace hpds::io_detail {

void requireRegularFile(const std::string &path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) fail(path, "file not found");
  if (status.type() == fs::file_type::none) fail(path, "cannot access: " + ec.message());
  if (!fs::is_regular_file(status)) fail(path, "not a regular file");
}

}  // namespace hpds::io_detail
