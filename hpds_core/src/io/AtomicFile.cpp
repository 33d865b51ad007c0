#include "hpds/io/AtomicFile.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <optional>
#include <set>
#include <stdexcept>

namespace hpds {

namespace {

namespace fs = std::filesystem;

constexpr const char *kMarker = ".hpds-tmp.";
// Map files saved by earlier versions used "<target>.tmp.<pid>.<n>"; such a leftover is recognised by its magic.
constexpr const char *kLegacyMarker = ".tmp.";
constexpr char kLegacyMapMagic[8] = {'H', 'P', 'D', 'S', 'M', 'A', 'P', '\0'};
constexpr std::size_t kBufferBytes = std::size_t(1) << 20;
constexpr std::size_t kNameMax = 255;  // bytes of one path component on Linux's file systems (NAME_MAX)

std::string errnoText(int err) { return std::strerror(err); }

std::string folderOf(const std::string &path) {
  const fs::path parent = fs::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

bool writeAll(int fd, const char *data, std::size_t n) {
  while (n > 0) {
    const ::ssize_t put = ::write(fd, data, n);
    if (put < 0 && errno == EINTR) continue;
    if (put <= 0) {
      if (put == 0) errno = EIO;
      return false;
    }
    data += put;
    n -= static_cast<std::size_t>(put);
  }
  return true;
}

// "<digits>.<digits>" to the end: the pid of the writer.
std::optional<long> writerPid(const std::string &name, std::size_t after) {
  const std::size_t dot = name.find('.', after);
  if (dot == std::string::npos || dot == after || dot + 1 == name.size()) return std::nullopt;
  for (std::size_t i = after; i < name.size(); ++i)
    if (i != dot && (name[i] < '0' || name[i] > '9')) return std::nullopt;
  if (dot - after > 9) return std::nullopt;
  return std::stol(name.substr(after, dot - after));
}

bool processIsGone(long pid) {
  if (pid <= 0 || pid == static_cast<long>(::getpid())) return false;
  return ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
}

// Removes `path` if it is a regular file nobody holds a lock on (and, for a legacy name, starts like a map file).
bool removeIfAbandoned(const std::string &path, bool legacy) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
  if (fd < 0) return false;
  bool removed = false;
  struct stat st {};
  if (::flock(fd, LOCK_EX | LOCK_NB) == 0 && ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) {
    bool ours = true;
    if (legacy) {
      char magic[sizeof kLegacyMapMagic] = {};
      ours = ::read(fd, magic, sizeof magic) == static_cast<::ssize_t>(sizeof magic) &&
             std::memcmp(magic, kLegacyMapMagic, sizeof magic) == 0;
    }
    removed = ours && ::unlink(path.c_str()) == 0;
  }
  ::close(fd);
  return removed;
}

void removeStaleTemporariesOnce(const std::string &folder) {
  static std::mutex mutex;
  static std::set<std::string> done;
  std::error_code ec;
  const fs::path canonical = fs::canonical(folder, ec);
  const std::string key = ec ? folder : canonical.string();
  {
    const std::lock_guard<std::mutex> lock(mutex);
    if (!done.insert(key).second) return;
  }
  removeStaleTemporaries(folder);
}

}  // namespace

// At most 40 links, as the kernel; a dangling last link is followed too, so writing through it creates its file.
std::string followLinks(const std::string &path) {
  fs::path p = path;
  for (int hops = 0; hops < 40; ++hops) {
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(p, ec))) break;
    const fs::path to = fs::read_symlink(p, ec);
    if (ec) break;
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  return p.string();
}

std::size_t removeStaleTemporaries(const std::string &folder) {
  std::size_t removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    bool legacy = false;
    std::size_t at = name.rfind(kMarker);
    if (at != std::string::npos) {
      at += std::strlen(kMarker);
    } else if ((at = name.rfind(kLegacyMarker)) != std::string::npos) {
      // "<target>.tmp.<pid>.<n>": rfind found the ".tmp." before "<pid>.<n>" only if nothing else follows.
      at += std::strlen(kLegacyMarker);
      legacy = true;
    } else {
      continue;
    }
    const std::optional<long> pid = writerPid(name, at);
    if (!pid || !processIsGone(*pid)) continue;
    if (removeIfAbandoned(it->path().string(), legacy)) ++removed;
  }
  return removed;
}

AtomicFile::AtomicFile(const std::string &target) : target_(target), final_(followLinks(target)) {
  struct stat st {};
  const bool exists = ::stat(final_.c_str(), &st) == 0;
  if (exists && S_ISDIR(st.st_mode)) fail("is a directory");
  if (exists && !S_ISREG(st.st_mode)) {
    in_place_ = true;
    writing_ = final_;
    fd_ = ::open(final_.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd_ < 0) fail("cannot open for writing: " + errnoText(errno));
    return;
  }
  removeStaleTemporariesOnce(folderOf(final_));
  static std::atomic<unsigned> counter{0};
  for (int attempt = 0;; ++attempt) {
    const std::string suffix = kMarker + std::to_string(::getpid()) + "." + std::to_string(counter++);
    // A name of up to NAME_MAX bytes is a valid output: its temporary keeps only as much of it as fits (what marks a
    // temporary, for removeStaleTemporaries, is the suffix).
    const fs::path at(final_);
    std::string name = at.filename().string();
    if (name.size() + suffix.size() > kNameMax) name.resize(kNameMax > suffix.size() ? kNameMax - suffix.size() : 0);
    writing_ = (at.parent_path() / (name + suffix)).string();
    fd_ = ::open(writing_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ >= 0) break;
    if (errno != EEXIST || attempt == 100) fail("cannot create a temporary file beside it: " + errnoText(errno));
  }
  // Marks the temporary as in use (see removeStaleTemporaries); a fresh file, so the lock is free.
  ::flock(fd_, LOCK_EX | LOCK_NB);
  if (exists) ::fchmod(fd_, st.st_mode & 07777);
}

AtomicFile::~AtomicFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !in_place_ && !writing_.empty()) ::unlink(writing_.c_str());
}

void AtomicFile::fail(const std::string &what) const { throw std::runtime_error(target_ + ": " + what); }

void AtomicFile::flushBuffer() {
  if (fd_ < 0) fail("write failed: the file was already committed or abandoned");
  if (!writeAll(fd_, buffer_.data(), buffer_.size())) {
    const int err = errno;
    buffer_.clear();
    fail("write failed: " + errnoText(err));
  }
  buffer_.clear();
}

void AtomicFile::write(const void *data, std::size_t bytes) {
  const char *p = static_cast<const char *>(data);
  if (buffer_.size() + bytes <= kBufferBytes) {
    buffer_.insert(buffer_.end(), p, p + bytes);
    return;
  }
  flushBuffer();
  if (bytes >= kBufferBytes) {
    if (!writeAll(fd_, p, bytes)) fail("write failed: " + errnoText(errno));
  } else {
    buffer_.assign(p, p + bytes);
  }
}

void AtomicFile::finish() {
  flushBuffer();
  if (!in_place_ && ::fsync(fd_) != 0) fail("write failed: fsync: " + errnoText(errno));
}

void AtomicFile::commit() {
  flushBuffer();
  if (in_place_) {
    const int fd = fd_;
    fd_ = -1;
    committed_ = true;
    if (::close(fd) != 0) fail("write failed: " + errnoText(errno));
    return;
  }
  // Data on disk before the rename publishes it, or a crash could leave a complete-looking empty file.
  if (::fsync(fd_) != 0) fail("write failed: fsync: " + errnoText(errno));
  if (std::rename(writing_.c_str(), final_.c_str()) != 0)
    fail("cannot rename the temporary file into place: " + errnoText(errno));
  committed_ = true;
  ::close(fd_);  // releases the lock only now: until the rename, the temporary is visibly in use
  fd_ = -1;
  // Makes the rename durable; failing here only weakens durability, the file is complete.
  const int dir = ::open(folderOf(final_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

std::string folderProblem(const std::string &path) {
  // A folder is no file name: AtomicFile would refuse it only when writing, after the work.
  struct stat st {};
  if (!path.empty() && path.back() == '/') return "names a folder (ends with '/'), not a file";
  if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) return "is a folder, not a file name";
  const std::string folder = folderOf(followLinks(path));
  if (::stat(folder.c_str(), &st) != 0) return "is in folder '" + folder + "', which does not exist";
  if (!S_ISDIR(st.st_mode)) return "is in '" + folder + "', which is not a folder";
  if (::access(folder.c_str(), W_OK | X_OK) != 0) return "is in folder '" + folder + "', which is not writable";
  return {};
}

void writeFileAtomically(const std::string &target, std::string_view bytes) {
  AtomicFile file(target);
  file.write(bytes);
  file.commit();
}

}  // namespace hpds
