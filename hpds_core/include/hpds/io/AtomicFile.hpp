// AtomicFile: how hpds writes every file. The bytes go to a temporary file in the target's folder, which is renamed
// over the target only when complete, so that an interrupted run (an exception, a full disk, kill -9, a power cut
// after the rename) never leaves a half-written file at the target and never destroys the file that was there.
//
// Contract
// - The temporary is "<target>.hpds-tmp.<pid>.<n>" beside the target (one file system: the rename is atomic),
//   created exclusively and held under an exclusive flock until the rename. A symbolic link at the target is
//   followed: the link stays and the file it leads to is replaced.
// - commit(): writes what is buffered, fsyncs, renames over the target (keeping an existing target's permission
//   bits), fsyncs the folder. Without commit() (an exception on the way, a failed write) the destructor removes
//   the temporary and the target is untouched.
// - An existing target that is neither a regular file nor a directory (/dev/null, a FIFO) is written in place:
//   it holds nothing to preserve and cannot be replaced by a rename. A directory at the target is refused.
// - Stale temporaries: the first AtomicFile of a process in a folder removes the hpds temporaries there whose
//   writer is gone (its process no longer runs and nobody holds the file's lock): what a killed run left behind.
//   Temporaries of running writers are never touched.
// - Errors: std::runtime_error "<target>: <problem>": "is a directory", "cannot create a temporary file beside
//   it: <reason>", "write failed: <reason>", "cannot rename the temporary file into place: <reason>".
// - Thread-safety: one AtomicFile is used by one thread; any number may write at once, to one target too (every
//   commit puts a whole file in place; the last one stays).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace hpds {

class AtomicFile {
 public:
  explicit AtomicFile(const std::string &target);
  ~AtomicFile();
  AtomicFile(const AtomicFile &) = delete;
  AtomicFile &operator=(const AtomicFile &) = delete;

  void write(const void *data, std::size_t bytes);
  void write(std::string_view text) { write(text.data(), text.size()); }
  /// Writes what is buffered and fsyncs, so that every write error (a full disk) has been reported, but leaves the
  /// target as it was: a program with several outputs finishes all of them, then commits them, so that a failure
  /// changes none. Optional; no write() after it.
  void finish();
  /// Puts the file in place (see contract); no write() after it.
  void commit();

  /// The target as given.
  [[nodiscard]] const std::string &target() const { return target_; }
  /// The file being written (the temporary, or the target itself when written in place), for a writer that opens
  /// files by name (rosbag): write through this name or through write(), not both; then commit().
  [[nodiscard]] const std::string &writingPath() const { return writing_; }

 private:
  void flushBuffer();
  [[noreturn]] void fail(const std::string &what) const;

  std::string target_;   // as given, for messages
  std::string final_;    // the target with symbolic links followed: what the rename replaces
  std::string writing_;  // the temporary, or final_ when written in place
  int fd_ = -1;
  bool in_place_ = false;
  bool committed_ = false;
  std::vector<char> buffer_;
};

/// `bytes` into `target` through one AtomicFile.
void writeFileAtomically(const std::string &target, std::string_view bytes);

/// The file a write to `path` replaces: `path` with symbolic links followed (the last one kept when it dangles).
[[nodiscard]] std::string followLinks(const std::string &path);

/// Why an AtomicFile for `path` could not be written (links followed: the folder of followLinks), as "is a folder,
/// not a file name" (also for a path ending in '/'), "is in folder 'F', which does not exist", "is in 'F', which is
/// not a folder" or "is in folder 'F', which is not writable"; empty when it could. For programs that check outputs
/// before the work.
[[nodiscard]] std::string folderProblem(const std::string &path);

/// Removes the hpds temporaries in `folder` whose writer is gone (see contract) and returns how many. AtomicFile
/// calls it once per folder and process; a long-running program may call it again.
std::size_t removeStaleTemporaries(const std::string &folder);

}  // namespace hpds
