// Internal to the I/O files: one error convention ("<path>: <what>", std::runtime_error), an owning FILE*, and the
// checks every reader makes before opening a path.
#pragma once

#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>

namespace hpds::io_detail {

[[noreturn]] inline void fail(const std::string &path, const std::string &what) {
  throw std::runtime_error(path + ": " + what);
}

struct FileCloser {
  void operator()(std::FILE *f) const {
    if (f) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

/// Throws (via fail) unless `path` names an existing regular file: "file not found", "cannot access: ...",
/// "not a regular file".
void requireRegularFile(const std::string &path);

}  // namespace hpds::io_detail
