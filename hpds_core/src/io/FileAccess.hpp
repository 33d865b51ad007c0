// Internal to the I/O files: one error convention ("<path>: <what>", std::runtime_error), an owning FILE*, the
// checks every reader makes before opening a path, the writers' output file, and the limits readers enforce (writers refuse to produce files
// beyond them, so that whatever is written reads back).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>

#include "hpds/io/AtomicFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds::io_detail {

/// A PCD/PLY header longer than this is not a point-cloud header (real ones are a few hundred bytes).
constexpr std::size_t kMaxHeaderBytes = 1 << 20;
/// Elements one field may have (PCD COUNT; a PLY writer expands them into this many properties).
using hpds::kMaxFieldCount;
/// Properties a PLY header may declare: PCL's header parser takes time quadratic in their number (40 000 took 3 s,
/// 24 s under the sanitizers), and real files have a few dozen.
constexpr std::size_t kMaxPlyProperties = 8192;

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

/// Text taken from a possibly binary file, in single quotes, for a message: at most 40 bytes ("..." after them), and
/// every byte outside printable ASCII (a NUL would cut the message short) as '?'.
[[nodiscard]] std::string quote(std::string_view text);

/// A file being written by one of the writers: an AtomicFile (temporary beside the target, renamed into place by
/// close()), so a failed or interrupted write leaves whatever was at the path untouched.
class OutputFile : public AtomicFile {
 public:
  using AtomicFile::AtomicFile;
  /// Flushes and puts the file in place; no write() after it.
  void close() { commit(); }
};

}  // namespace hpds::io_detail
