// The files a command will read and write, checked before any work so that a run never ends, after minutes, on an
// output it cannot write, and never writes over its own input.
//
// Contract
// - checkPaths throws std::invalid_argument naming the flag and the path when an output
//   - has an extension of another format than the one it is written in (`-o out.pcd` for a PLY), or, for a map
//     (no fixed extension), the extension of a format hpds reads or writes (`--save-map in.pcd`);
//   - is a directory, or lies in a folder that does not exist or is not writable;
//   - is the same file as an input or as another output. "Same" is the file system's identity (device and inode),
//     not the spelling: `./a.ply`, `dir/../a.ply`, a hard link and a symbolic link to the input are all the input;
//     an output that does not exist yet is identified by its folder's identity and its name.
// - An existing output that is not a regular file is refused: a pipe (a FIFO, /dev/stdout into a pipe), a terminal
//   or other device, a socket. Outputs are written whole under a temporary name and renamed into place (AtomicFile),
//   which such a file cannot take; written into directly, a pipe would hold the run after its work until read. The
//   null device (/dev/null) is accepted under any name: it discards the output.
// - Outputs that are folders (render, analyze, synth -o DIR) are checked as the folder they will create or fill,
//   plus every file name the command writes into it.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace hpds::cli {

struct InputPath {
  std::string flag;  ///< how the user gave it: "input", "--config", "--poses", "--load-map", ...
  std::string path;
};

struct OutputPath {
  std::string flag;                     ///< "-o", "--stats", "--save-map"
  std::string path;
  std::vector<std::string> extensions;  ///< accepted, lower case with the dot; empty: any but another format's
  std::string format;                   ///< what is written, for the message ("PLY", "JSON", "an hpds map")
};

/// Outputs that are folders: the folder (created when missing, so its parent must exist and be writable) and the
/// names of the files the command writes into it.
struct OutputFolder {
  std::string flag;
  std::string path;
  std::vector<std::string> files;
};

void checkPaths(const std::vector<InputPath> &inputs, const std::vector<OutputPath> &outputs,
                const std::vector<OutputFolder> &folders = {});

/// The output folder of one run (render, analyze, synth -o DIR), created with its missing parents. Every file of the
/// run is written where file(name) says and put in place together by keep(), so that a failed run changes nothing:
/// - a folder the run created is removed, with whatever the run put there, if the run throws before keep();
/// - in a folder that existed, the files are written into a staging folder inside it (".hpds-staging.<pid>.<n>",
///   held under a flock) and renamed into place by keep(), each over the file a symbolic link of that name leads
///   to, as AtomicFile does. A run that throws, or is killed, before keep() leaves every file of the folder as it
///   was (a killed run's staging folder is removed by the next RunFolder there). Not thread-safe.
class RunFolder {
 public:
  explicit RunFolder(const std::string &path);
  RunFolder(const RunFolder &) = delete;
  RunFolder &operator=(const RunFolder &) = delete;
  ~RunFolder();
  /// Where the run writes its file `name` (a plain file name).
  [[nodiscard]] std::string file(const std::string &name);
  /// The run succeeded: its files go in place and the folder stays. Throws std::runtime_error naming the file that
  /// could not be renamed into place (the files renamed before it stay).
  void keep();

 private:
  std::filesystem::path target_;
  std::filesystem::path created_;  // topmost folder this run created; empty when it created none
  std::filesystem::path staging_;  // empty when the folder was created by this run (nothing there to keep)
  int lock_fd_ = -1;
  std::vector<std::string> staged_;
};

}  // namespace hpds::cli
