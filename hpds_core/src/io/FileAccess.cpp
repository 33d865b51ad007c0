#include "io/FileAccess.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <utility>

namespace hpds::io_detail {

void requireRegularFile(const std::string &path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) fail(path, "file not found");
  if (status.type() == fs::file_type::none) fail(path, "cannot access: " + ec.message());
  if (!fs::is_regular_file(status)) fail(path, "not a regular file");
}

OutputFile::OutputFile(std::string path) : path_(std::move(path)), file_(std::fopen(path_.c_str(), "wb")) {
  if (!file_) fail(path_, std::string("cannot open for writing: ") + std::strerror(errno));
}

OutputFile::~OutputFile() {
  if (!file_) return;
  file_.reset();
  removePartial();
}

void OutputFile::write(const void *data, std::size_t bytes) {
  if (bytes > 0 && std::fwrite(data, 1, bytes, file_.get()) != bytes) abandon(errno);
}

void OutputFile::close() {
  if (std::fflush(file_.get()) != 0) abandon(errno);
  if (std::fclose(file_.release()) != 0) {
    const int err = errno;
    removePartial();
    fail(path_, std::string("write failed: ") + std::strerror(err));
  }
}

void OutputFile::abandon(int err) {
  file_.reset();
  removePartial();
  fail(path_, std::string("write failed: ") + std::strerror(err));
}

void OutputFile::removePartial() const {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::symlink_status(path_, ec).type() == fs::file_type::regular) fs::remove(path_, ec);
}

}  // namespace hpds::io_detail
