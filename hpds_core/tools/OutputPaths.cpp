#include "OutputPaths.hpp"

#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/HierarchyFile.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <optional>
#include <stdexcept>

namespace hpds::cli {

namespace {

namespace fs = std::filesystem;

std::string lowerExtension(const std::string &path) {
  std::string ext = fs::path(path).extension().string();
  for (char &c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::string inQuotes(const std::string &path) { return "'" + path + "'"; }

[[noreturn]] void refuse(const std::string &flag, const std::string &path, const std::string &why) {
  throw std::invalid_argument(flag + ": " + inQuotes(path) + " " + why);
}

std::string folderOf(const std::string &path) {
  const fs::path parent = fs::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

// A file's identity: (device, inode) of the file when it exists, else of its folder plus its name.
struct Identity {
  dev_t dev = 0;
  ino_t ino = 0;
  std::string name;
  bool operator==(const Identity &o) const { return dev == o.dev && ino == o.ino && name == o.name; }
};

std::optional<Identity> identify(const std::string &given) {
  // As AtomicFile writes it: through symbolic links, even a dangling one.
  const std::string path = followLinks(given);
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) return Identity{st.st_dev, st.st_ino, ""};
  if (::stat(folderOf(path).c_str(), &st) == 0) return Identity{st.st_dev, st.st_ino, fs::path(path).filename()};
  return std::nullopt;
}

void checkExtension(const OutputPath &o) {
  const std::string ext = lowerExtension(o.path);
  if (!o.extensions.empty()) {
    if (std::find(o.extensions.begin(), o.extensions.end(), ext) != o.extensions.end()) return;
    std::string list;
    for (std::size_t i = 0; i < o.extensions.size(); ++i)
      list += (i == 0 ? "" : i + 1 == o.extensions.size() ? " or " : ", ") + o.extensions[i];
    refuse(o.flag, o.path, "must end in " + list + " (" + o.format + " is written there)");
  }
  if (isOtherFormatName(o.path))
    refuse(o.flag, o.path, "has the extension of another format (" + ext + "); " + o.format +
                               " needs another name, e.g. map.hpdsmap");
}

// Why an existing output that is not a regular file cannot be written, or "" when it can. Every output goes whole
// to a temporary beside it, renamed into place once every output of the run is complete; a pipe or a device can
// only be written into. A pipe would then hold the run, after all its work, until something reads it, and a
// reader would get a cloud whose run failed on a later output. The null device takes anything and keeps nothing.
std::string specialFileProblem(const struct stat &st) {
  if (S_ISREG(st.st_mode)) return {};
  const std::string advice = ": hpds writes each output whole under a temporary name and renames it into place; "
                             "write to a file and read that (or to /dev/null to discard the output)";
  if (S_ISFIFO(st.st_mode)) return "is a pipe (FIFO), not a regular file" + advice;
  if (S_ISCHR(st.st_mode)) {
    struct stat null {};
    if (::stat("/dev/null", &null) == 0 && S_ISCHR(null.st_mode) && null.st_rdev == st.st_rdev) return {};
    return "is a character device (a terminal?), not a regular file" + advice;
  }
  if (S_ISDIR(st.st_mode)) return "is a directory";
  return std::string(S_ISBLK(st.st_mode) ? "is a block device" : "is a socket or other special file") +
         ", not a regular file" + advice;
}

struct Planned {
  std::string flag, path;
  std::optional<Identity> id;
};

}  // namespace

void checkPaths(const std::vector<InputPath> &inputs, const std::vector<OutputPath> &outputs,
                const std::vector<OutputFolder> &folders) {
  std::vector<Planned> planned;
  for (const OutputPath &o : outputs) {
    if (o.path.empty()) continue;
    struct stat st {};
    const bool exists = ::stat(o.path.c_str(), &st) == 0;
    if (exists)
      if (const std::string why = specialFileProblem(st); !why.empty()) refuse(o.flag, o.path, why);
    // The null device is written in place and holds nothing to lose: any name, no folder to write into.
    if (!exists || S_ISREG(st.st_mode)) {
      checkExtension(o);
      // The folder the file lands in: a symbolic link's target's (AtomicFile follows links, even a dangling one).
      if (const std::string why = folderProblem(o.path); !why.empty()) refuse(o.flag, o.path, why);
      if (exists && ::access(o.path.c_str(), W_OK) != 0)
        refuse(o.flag, o.path, "exists and is read-only; hpds does not replace files it may not write");
    }
    planned.push_back({o.flag, o.path, identify(o.path)});
  }
  for (const OutputFolder &f : folders) {
    if (f.path.empty()) continue;
    struct stat st {};
    if (::stat(f.path.c_str(), &st) == 0) {
      if (!S_ISDIR(st.st_mode)) refuse(f.flag, f.path, "exists and is not a folder");
      if (::access(f.path.c_str(), W_OK | X_OK) != 0) refuse(f.flag, f.path, "is a folder that is not writable");
    } else {
      // Created with its missing parents: the nearest existing ancestor must take them.
      fs::path ancestor = fs::absolute(f.path).parent_path();
      while (!ancestor.empty() && ::stat(ancestor.c_str(), &st) != 0 && ancestor != ancestor.root_path())
        ancestor = ancestor.parent_path();
      if (!S_ISDIR(st.st_mode)) refuse(f.flag, f.path, "cannot be created: " + inQuotes(ancestor.string()) + " is not a folder");
      if (::access(ancestor.c_str(), W_OK | X_OK) != 0)
        refuse(f.flag, f.path, "cannot be created in " + inQuotes(ancestor.string()) + ", which is not writable");
    }
    for (const std::string &name : f.files) {
      const std::string path = (fs::path(f.path) / name).string();
      if (struct stat file {}; ::stat(path.c_str(), &file) == 0)
        if (const std::string why = specialFileProblem(file); !why.empty()) refuse(f.flag, path, why);
      planned.push_back({f.flag, path, identify(path)});
    }
  }

  for (std::size_t i = 0; i < planned.size(); ++i) {
    const Planned &o = planned[i];
    if (!o.id) continue;
    for (const InputPath &in : inputs) {
      if (in.path.empty()) continue;
      struct stat st {};
      if (::stat(in.path.c_str(), &st) != 0) continue;  // a missing input is the reader's error
      if (!(Identity{st.st_dev, st.st_ino, ""} == *o.id)) continue;
      refuse(o.flag, o.path,
             "is the " + (in.flag == "input" ? std::string("input ") : in.flag + " file ") + inQuotes(in.path) +
                 "; hpds never writes over what it reads");
    }
    for (std::size_t j = 0; j < i; ++j)
      if (planned[j].id && *planned[j].id == *o.id)
        refuse(o.flag, o.path, "is also the output of " + planned[j].flag + " (" + inQuotes(planned[j].path) + ")");
  }
}

namespace {
constexpr const char *kStagingPrefix = ".hpds-staging.";

// Removes the staging folders in `folder` whose run is gone: nobody holds the flock on their lock file.
void removeStaleStaging(const fs::path &folder) {
  std::error_code ec;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(kStagingPrefix, 0) != 0 || !it->is_directory(ec)) continue;
    const int fd = ::open((it->path() / ".lock").c_str(), O_RDONLY | O_CLOEXEC);
    const bool gone = fd < 0 || ::flock(fd, LOCK_EX | LOCK_NB) == 0;
    if (fd >= 0) ::close(fd);
    std::error_code ignored;
    if (gone) fs::remove_all(it->path(), ignored);
  }
}
}  // namespace

RunFolder::RunFolder(const std::string &path) {
  // Normalised first, so that the folders created are exactly those walked here ("a/../b" creates b alone).
  target_ = fs::weakly_canonical(fs::absolute(path));
  fs::path missing;
  for (fs::path p = target_; !p.empty() && !fs::exists(p) && p != p.parent_path(); p = p.parent_path()) missing = p;
  fs::create_directories(target_);
  created_ = missing;
  if (!created_.empty()) return;
  removeStaleStaging(target_);
  static unsigned counter = 0;
  staging_ = target_ / (kStagingPrefix + std::to_string(::getpid()) + "." + std::to_string(counter++));
  fs::create_directory(staging_);
  lock_fd_ = ::open((staging_ / ".lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (lock_fd_ < 0 || ::flock(lock_fd_, LOCK_EX) != 0)
    throw std::runtime_error(staging_.string() + ": cannot lock the run's staging folder");
}

std::string RunFolder::file(const std::string &name) {
  if (staging_.empty()) return (target_ / name).string();
  staged_.push_back(name);
  return (staging_ / name).string();
}

void RunFolder::keep() {
  for (const std::string &name : staged_) {
    const fs::path from = staging_ / name;
    if (!fs::exists(from)) continue;  // asked for but not written
    const std::string to = followLinks((target_ / name).string());
    if (::rename(from.c_str(), to.c_str()) != 0)
      throw std::runtime_error(to + ": cannot rename the run's file into place: " + std::strerror(errno));
  }
  if (!staging_.empty()) {
    // The renames reach the disk with the folder's entry.
    const int dir = ::open(target_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dir >= 0) {
      ::fsync(dir);
      ::close(dir);
    }
  }
  created_.clear();
}

RunFolder::~RunFolder() {
  std::error_code ignored;  // a destructor during unwinding must not throw; the run's own error is what counts
  if (!staging_.empty()) fs::remove_all(staging_, ignored);
  if (lock_fd_ >= 0) ::close(lock_fd_);
  if (!created_.empty()) fs::remove_all(created_, ignored);
}

}  // namespace hpds::cli
