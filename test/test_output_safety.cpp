// hpds never destroys data: every file is written under a temporary name and renamed into place (AtomicFile), a
// killed run leaves the previous output intact and its temporary is cleaned up later, and the CLI checks every
// output path before any work (OutputPaths): no output is an input or another output, each is in a writable folder
// and carries its format's extension. The kills are real: a child `hpds` process dies by SIGKILL (sent as soon as
// it starts writing) or by SIGXFSZ (the kernel's file size limit, which stops it at an exact byte).
#include <gtest/gtest.h>

#include <algorithm>

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/inotify.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "TestData.hpp"
#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;
using test::shellQuote;

void writeText(const fs::path &p, const std::string &s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

std::vector<fs::path> temporariesIn(const fs::path &dir) {
  std::vector<fs::path> found;
  for (const auto &e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".hpds-tmp.") != std::string::npos) found.push_back(e.path());
  return found;
}

// `n` random points in a 40 m cube, each with `payload` further float32 values: nearly all of them become samples at
// the default depth, so the output is about as large as the input.
void writeRandomCloud(const fs::path &path, std::size_t n, std::uint32_t payload = 0) {
  PointLayout layout;
  for (const char *a : {"x", "y", "z"}) layout.append(a, FieldType::Float32);
  if (payload > 0) layout.append("payload", FieldType::Float32, payload);
  PointBuffer cloud(layout, n);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-20.f, 20.f);
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) writeFromDouble(cloud.record(i), layout.fields[a], u(rng));
  writePly(path.string(), cloud);
}

// Starts `hpds args...` (stdout and stderr to `log`), optionally under a file size limit.
pid_t spawnHpds(const std::vector<std::string> &args, const fs::path &log, rlim_t file_size_limit = RLIM_INFINITY,
                bool ignore_sigxfsz = false) {
  std::vector<std::string> argv_strings = {test::cliPath()};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    const rlimit limit{file_size_limit, file_size_limit};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    ::signal(SIGXFSZ, ignore_sigxfsz ? SIG_IGN : SIG_DFL);  // ignored: a write past the limit fails with EFBIG
    std::vector<char *> argv;
    for (std::string &s : argv_strings) argv.push_back(s.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

int waitStatus(pid_t pid) {
  int status = 0;
  ::waitpid(pid, &status, 0);
  return status;
}

class OutputSafety : public testing::Test {
 protected:
  void SetUp() override { dir_ = test::scratchDir("output_safety"); }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// ---------------------------------------------------------------- killed writes

TEST_F(OutputSafety, WriteKilledByTheFileSizeLimitLeavesThePreviousOutputsAndTheNextRunCleansUp) {
  writeRandomCloud(dir_ / "in.ply", 200000);
  const std::string previous_ply = "previous PLY: must survive\n", previous_map = "previous map: must survive\n";
  writeText(dir_ / "out.ply", previous_ply);
  writeText(dir_ / "m.hpdsmap", previous_map);
  const std::string in = (dir_ / "in.ply").string(), out = (dir_ / "out.ply").string();
  const std::string map = (dir_ / "m.hpdsmap").string(), small = (dir_ / "small.ply").string();

  // 1. The PLY (about 3.4 MB) stops at 1 MB: the process dies by SIGXFSZ in the middle of the write.
  int status = waitStatus(spawnHpds({"sample", in, "-o", out}, dir_ / "log1.txt", 1 << 20));
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGXFSZ) << test::readText(dir_ / "log1.txt");
  EXPECT_EQ(test::readText(dir_ / "out.ply"), previous_ply) << "the previous output was destroyed";
  ASSERT_EQ(temporariesIn(dir_).size(), 1u) << "the killed run's temporary should be there";
  EXPECT_EQ(fs::file_size(temporariesIn(dir_)[0]), std::uintmax_t(1) << 20);

  // 2. The map (about 8 MB: every level kept, map.keep_depth 8) the same way, behind a small PLY (level 0).
  writeText(dir_ / "keep.yaml", "map: {keep_depth: 8}\n");
  status = waitStatus(spawnHpds({"sample", in, "--mode", "map", "--level", "0", "--config", (dir_ / "keep.yaml").string(),
                                 "-o", small, "--save-map", map},
                                dir_ / "log2.txt", 2 << 20));
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGXFSZ) << test::readText(dir_ / "log2.txt");
  EXPECT_EQ(test::readText(dir_ / "m.hpdsmap"), previous_map) << "the previous map was destroyed";
  EXPECT_FALSE(fs::exists(small)) << "the cloud of a run whose map was never written was put in place";
  // That run's first write into the folder removed the first run's leftover: only its own two are left.
  std::vector<fs::path> left = temporariesIn(dir_);
  ASSERT_EQ(left.size(), 2u);
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left[0].filename().string().rfind("m.hpdsmap.hpds-tmp.", 0), 0u) << left[0];
  EXPECT_EQ(left[1].filename().string().rfind("small.ply.hpds-tmp.", 0), 0u) << left[1];

  // 3. The next run into that folder removes the leftover and writes complete files.
  std::string log;
  ASSERT_EQ(test::runHpds("sample " + shellQuote(in) + " --mode map -o " + shellQuote(out) + " --save-map " +
                              shellQuote(map),
                          &log),
            0)
      << log;
  EXPECT_TRUE(temporariesIn(dir_).empty());
  EXPECT_GT(readPointCloud(out).size(), 190000u) << "complete output expected";
}

TEST_F(OutputSafety, AFailedWriteOfOneOutputReplacesNoneOfThem) {
  // A full disk while the map is written, after the cloud: the cloud, the map and the stats of a run all replace
  // their previous files, or none does. (SIGXFSZ ignored: the write fails with EFBIG and hpds reports it.)
  writeRandomCloud(dir_ / "in.ply", 200000);
  const std::string previous_ply = "previous PLY\n", previous_map = "previous map\n", previous_stats = "{}\n";
  writeText(dir_ / "out.ply", previous_ply);
  writeText(dir_ / "m.hpdsmap", previous_map);
  writeText(dir_ / "s.json", previous_stats);
  writeText(dir_ / "keep.yaml", "map: {keep_depth: 8}\n");
  const int status = waitStatus(spawnHpds({"sample", (dir_ / "in.ply").string(), "--mode", "map", "--level", "0",
                                           "--config", (dir_ / "keep.yaml").string(), "-o", (dir_ / "out.ply").string(),
                                           "--save-map", (dir_ / "m.hpdsmap").string(), "--stats",
                                           (dir_ / "s.json").string()},
                                          dir_ / "log.txt", 2 << 20, /*ignore_sigxfsz=*/true));
  const std::string log = test::readText(dir_ / "log.txt");
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << log;
  EXPECT_NE(log.find("m.hpdsmap: write failed"), std::string::npos) << log;
  EXPECT_EQ(test::readText(dir_ / "out.ply"), previous_ply) << "the cloud was replaced by a run that failed";
  EXPECT_EQ(test::readText(dir_ / "m.hpdsmap"), previous_map);
  EXPECT_EQ(test::readText(dir_ / "s.json"), previous_stats);
  EXPECT_TRUE(temporariesIn(dir_).empty()) << "a failed run removes its temporaries";
}

TEST_F(OutputSafety, SigkillDuringTheWriteLeavesThePreviousOutput) {
  writeRandomCloud(dir_ / "in.ply", 250000, 24);  // about 25 MB out
  const std::string in = (dir_ / "in.ply").string(), out = (dir_ / "out.ply").string();
  // The complete output, for the case where the kill lands after the rename.
  std::string log;
  ASSERT_EQ(test::runHpds("sample " + shellQuote(in) + " -o " + shellQuote(out), &log), 0) << log;
  const std::string complete = test::readText(out);
  ASSERT_GT(complete.size(), 15u << 20);
  const std::string previous = "previous output: must survive\n";

  bool killed_mid_write = false;
  for (int attempt = 0; attempt < 5 && !killed_mid_write; ++attempt) {
    writeText(out, previous);
    for (const fs::path &t : temporariesIn(dir_)) fs::remove(t);
    // SIGKILL at the first write into the folder after the input was read: the first flushed buffer of the output.
    const int watch = ::inotify_init1(IN_CLOEXEC);
    ASSERT_GE(watch, 0);
    ASSERT_GE(::inotify_add_watch(watch, dir_.c_str(), IN_MODIFY), 0);
    const pid_t pid = spawnHpds({"sample", in, "-o", out}, dir_ / "log.txt");
    alignas(inotify_event) char buf[4096];
    bool seen = false;
    while (!seen) {
      const ssize_t n = ::read(watch, buf, sizeof buf);
      ASSERT_GT(n, 0);
      for (char *p = buf; p < buf + n; p += sizeof(inotify_event) + reinterpret_cast<inotify_event *>(p)->len) {
        const auto *e = reinterpret_cast<inotify_event *>(p);
        if (e->len > 0 && std::string(e->name).rfind("out.ply", 0) == 0) seen = true;
      }
    }
    ::kill(pid, SIGKILL);
    const int status = waitStatus(pid);
    ::close(watch);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << test::readText(dir_ / "log.txt");
    const std::string now = test::readText(out);
    // Killed before the rename: the previous bytes; after it: the complete new file. Never anything else.
    EXPECT_TRUE(now == previous || now == complete) << "output is " << now.size() << " bytes, neither the previous "
                                                    << previous.size() << " nor the complete " << complete.size();
    killed_mid_write = now == previous && temporariesIn(dir_).size() == 1;
  }
  EXPECT_TRUE(killed_mid_write) << "the kill never landed during the write";
  ASSERT_EQ(test::runHpds("sample " + shellQuote(in) + " -o " + shellQuote(out), &log), 0) << log;
  EXPECT_TRUE(temporariesIn(dir_).empty()) << "the killed run's temporary was not cleaned up";
  EXPECT_EQ(test::readText(out), complete);
}

// A run that writes a folder of files (synth, render, analyze) into a folder that exists replaces all of its files or
// none: killed once it has reached its third frame, the folder holds the previous run's frames and poses, never some
// new frames beside old poses; the next run into it removes the killed run's staging folder.
TEST_F(OutputSafety, AKilledSynthLeavesAnExistingFolderAsItWas) {
  const fs::path out = dir_ / "s";
  fs::create_directory(out);
  const std::vector<std::string> names = {"frame_000000.pcd", "frame_000001.pcd", "frame_000002.pcd", "poses.txt"};
  for (const std::string &name : names) writeText(out / name, "previous " + name + "\n");
  auto stagingIn = [](const fs::path &dir) {
    std::vector<fs::path> found;
    for (const auto &e : fs::directory_iterator(dir))
      if (e.path().filename().string().rfind(".hpds-staging.", 0) == 0) found.push_back(e.path());
    return found;
  };
  const pid_t pid = spawnHpds({"synth", "-o", out.string(), "--frames", "50"}, dir_ / "log.txt");
  // Polled until the run has reached its third frame: in its staging folder that frame's temporary or, once
  // renamed, the frame itself, which stays there until the run ends (47 frames later), so a slow poll (a sanitizer
  // build) cannot miss it. A run writing straight into the folder would show the temporary there.
  auto startsThird = [](const fs::path &p) { return p.filename().string().rfind("frame_000002.pcd", 0) == 0; };
  bool third = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!third && std::chrono::steady_clock::now() < deadline) {
    for (const auto &e : fs::directory_iterator(out))
      third = third || (startsThird(e.path()) && e.path().filename() != "frame_000002.pcd");
    for (const fs::path &staging : stagingIn(out)) {
      std::error_code ec;
      for (fs::directory_iterator it(staging, ec), end; !ec && it != end; it.increment(ec))
        third = third || startsThird(it->path());
    }
    if (!third) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ::kill(pid, SIGKILL);
  const int status = waitStatus(pid);
  ASSERT_TRUE(third) << test::readText(dir_ / "log.txt");
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << test::readText(dir_ / "log.txt");
  for (const std::string &name : names)
    EXPECT_TRUE(test::readText(out / name) == "previous " + name + "\n") << name << " was replaced by a killed run";
  EXPECT_FALSE(fs::exists(out / "frame_000003.pcd"));
  ASSERT_EQ(stagingIn(out).size(), 1u) << "the killed run's staging folder should be there";

  std::string log;
  ASSERT_EQ(test::runHpds("synth -o " + shellQuote(out) + " --frames 3 --beams 4 --azimuth-steps 100", &log), 0) << log;
  EXPECT_TRUE(stagingIn(out).empty()) << "the killed run's staging folder was not removed";
  for (const std::string &name : names) EXPECT_NE(test::readText(out / name), "previous " + name + "\n") << name;
  EXPECT_EQ(readPointCloud((out / "frame_000002.pcd").string()).size(), 400u);
}

// ---------------------------------------------------------------- AtomicFile

TEST_F(OutputSafety, AtomicFileReplacesOnlyOnCommit) {
  const fs::path target = dir_ / "t.txt";
  writeText(target, "old");
  fs::permissions(target, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  {
    AtomicFile f(target.string());
    f.write("new text");
    EXPECT_EQ(test::readText(target), "old") << "visible before commit";
    EXPECT_TRUE(fs::exists(f.writingPath()));
    // Abandoned: the temporary goes, the target stays.
  }
  EXPECT_EQ(test::readText(target), "old");
  EXPECT_TRUE(temporariesIn(dir_).empty());
  {
    AtomicFile f(target.string());
    f.write(std::string(3 << 20, 'x'));  // more than the buffer
    f.commit();
  }
  EXPECT_EQ(fs::file_size(target), std::uintmax_t(3) << 20);
  EXPECT_EQ(fs::status(target).permissions() & fs::perms::all,
            fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read)
      << "the replaced file's permissions are kept";
  EXPECT_TRUE(temporariesIn(dir_).empty());
}

// Any name the file system takes is an output name, up to 255 bytes: the temporary keeps only as much of it as fits
// beside its marker, and a writer killed in the middle leaves one that the next run still recognises and removes.
TEST_F(OutputSafety, NamesUpToTheFileSystemsLimitAreWritten) {
  for (const std::size_t length : {std::size_t(200), std::size_t(241), std::size_t(255)}) {
    SCOPED_TRACE(length);
    const fs::path target = dir_ / (std::string(length - 4, 'n') + ".ply");
    {
      AtomicFile f(target.string());
      EXPECT_LE(fs::path(f.writingPath()).filename().string().size(), 255u);
      f.write("content");
      f.commit();
    }
    EXPECT_EQ(test::readText(target), "content");
    EXPECT_TRUE(temporariesIn(dir_).empty());
  }
  // A temporary of a long name whose writer is gone (pid 2^22 + 1 is above Linux's pid_max default) is removed.
  const std::string stale = std::string(230, 'n') + ".hpds-tmp.4194305.0";
  writeText(dir_ / stale, "left by a killed writer");
  EXPECT_EQ(removeStaleTemporaries(dir_.string()), 1u);
  EXPECT_FALSE(fs::exists(dir_ / stale));
}

TEST_F(OutputSafety, AtomicFileFollowsLinksWritesDevicesInPlaceAndRefusesDirectories) {
  fs::create_directory(dir_ / "real");
  writeText(dir_ / "real" / "data.txt", "old");
  fs::create_symlink(dir_ / "real" / "data.txt", dir_ / "link.txt");
  writeFileAtomically((dir_ / "link.txt").string(), "through the link");
  EXPECT_TRUE(fs::is_symlink(dir_ / "link.txt")) << "the link itself must stay";
  EXPECT_EQ(test::readText(dir_ / "real" / "data.txt"), "through the link");
  writeFileAtomically("/dev/null", "discarded");
  EXPECT_TRUE(fs::is_character_file("/dev/null"));
  try {
    writeFileAtomically((dir_ / "real").string(), "x");
    ADD_FAILURE() << "a directory was accepted";
  } catch (const std::runtime_error &e) {
    EXPECT_NE(std::string(e.what()).find("is a directory"), std::string::npos) << e.what();
  }
  try {
    writeFileAtomically((dir_ / "missing" / "x.txt").string(), "x");
    ADD_FAILURE() << "a missing folder was accepted";
  } catch (const std::runtime_error &e) {
    EXPECT_NE(std::string(e.what()).find("x.txt: cannot create a temporary file beside it"), std::string::npos)
        << e.what();
  }
}

TEST_F(OutputSafety, OnlyTemporariesOfGoneWritersAreRemoved) {
  // A writer that died: a child that creates its temporary and exits without cleaning up.
  const pid_t child = ::fork();
  if (child == 0) {
    const std::string name = (dir_ / "a.ply").string() + ".hpds-tmp." + std::to_string(::getpid()) + ".0";
    const int fd = ::open(name.c_str(), O_WRONLY | O_CREAT, 0644);
    ::_exit(fd >= 0 ? 0 : 1);
  }
  ASSERT_EQ(waitStatus(child), 0);
  const std::string dead = std::to_string(child);
  ASSERT_TRUE(fs::exists(dir_ / ("a.ply.hpds-tmp." + dead + ".0")));
  // A live writer (this process), one whose lock is held, files that only look similar, and legacy map temporaries
  // with and without the map magic.
  writeText(dir_ / ("b.ply.hpds-tmp." + std::to_string(::getpid()) + ".0"), "live");
  writeText(dir_ / ("c.ply.hpds-tmp." + dead + ".7"), "locked by a live process");
  const int locked = ::open((dir_ / ("c.ply.hpds-tmp." + dead + ".7")).c_str(), O_RDONLY);
  ASSERT_EQ(::flock(locked, LOCK_EX), 0);
  writeText(dir_ / ("d.ply.hpds-tmp." + dead + ".x"), "not our pattern");
  writeText(dir_ / ("notes.tmp." + dead + ".1"), "a user's file");
  writeText(dir_ / ("m.hpm.tmp." + dead + ".0"), std::string("HPDSMAP\0rest", 12));

  EXPECT_EQ(removeStaleTemporaries(dir_.string()), 2u);
  EXPECT_FALSE(fs::exists(dir_ / ("a.ply.hpds-tmp." + dead + ".0")));
  EXPECT_FALSE(fs::exists(dir_ / ("m.hpm.tmp." + dead + ".0")));
  EXPECT_TRUE(fs::exists(dir_ / ("b.ply.hpds-tmp." + std::to_string(::getpid()) + ".0")));
  EXPECT_TRUE(fs::exists(dir_ / ("c.ply.hpds-tmp." + dead + ".7")));
  EXPECT_TRUE(fs::exists(dir_ / ("d.ply.hpds-tmp." + dead + ".x")));
  EXPECT_TRUE(fs::exists(dir_ / ("notes.tmp." + dead + ".1")));
  ::close(locked);
}

// ---------------------------------------------------------------- output paths, checked before any work

struct Refusal {
  std::string args;
  std::string message;
};

TEST_F(OutputSafety, NoOutputIsAnInputOrAnotherOutput) {
  writeRandomCloud(dir_ / "a.ply", 2000);
  writeRandomCloud(dir_ / "b.ply", 2000);
  fs::create_directory(dir_ / "sub");
  fs::create_hard_link(dir_ / "a.ply", dir_ / "hard.ply");
  fs::create_symlink(dir_ / "a.ply", dir_ / "soft.ply");
  fs::create_symlink(dir_ / "out.ply", dir_ / "out_link.hpdsmap");  // dangling until out.ply is written
  writeText(dir_ / "c.yaml", "threads: 1\n");
  writeText(dir_ / "s.json", "{}\n");  // a config file (JSON is YAML) named like a stats file
  const std::string before = test::readText(dir_ / "a.ply");
  for (const char *path : {"synth_frames/frame_000001.pcd", "synth_poses/poses.txt"}) {
    fs::create_directories((dir_ / path).parent_path());
    ASSERT_EQ(::mkfifo((dir_ / path).c_str(), 0644), 0) << std::strerror(errno);
  }
  const auto q = [&](const std::string &name) { return " " + shellQuote(dir_ / name); };
  const std::vector<Refusal> cases = {
      {"sample" + q("a.ply") + " -o" + q("a.ply"), "-o: '" + (dir_ / "a.ply").string() + "' is the input"},
      {"sample" + q("a.ply") + " -o" + q("sub/../a.ply"), "is the input"},
      {"sample" + q("b.ply") + q("a.ply") + " -o" + q("./a.ply"), "is the input"},
      {"sample" + q("a.ply") + " -o" + q("hard.ply"), "is the input"},
      {"sample" + q("a.ply") + " -o" + q("soft.ply"), "is the input"},
      {"sample" + q("b.ply") + " --poses" + q("a.ply") + " -o" + q("a.ply"), "is the --poses file"},
      {"sample" + q("b.ply") + " --mode map --load-map" + q("x.hpdsmap") + " --save-map" + q("b.ply") + " -o" +
           q("o.ply"),
       "--save-map"},
      {"sample" + q("b.ply") + " -o" + q("out.ply") + " --mode map --save-map" + q("out_link.hpdsmap"),
       "--save-map: '" + (dir_ / "out_link.hpdsmap").string() + "' is also the output of -o"},
      {"sample" + q("b.ply") + " -o" + q("out.ply") + " --stats" + q("s.json") + " --config" + q("s.json"),
       "is the --config file"},
  };
  for (const Refusal &c : cases) {
    std::string log;
    EXPECT_EQ(test::runHpds(c.args, &log), 1) << c.args << "\n" << log;
    EXPECT_NE(log.find("hpds: error: "), std::string::npos) << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
  }
  EXPECT_EQ(test::readText(dir_ / "a.ply"), before) << "an input was written over";
  EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
  EXPECT_FALSE(fs::exists(dir_ / "o.ply"));

  // The same outputs are fine once they are distinct files, and an existing output file is replaced.
  std::string log;
  EXPECT_EQ(test::runHpds("sample" + q("b.ply") + " --mode map -o" + q("out.ply") + " --save-map" + q("m.hpdsmap") +
                              " --stats" + q("s.json") + " --config" + q("c.yaml"),
                          &log),
            0)
      << log;
  // A map is not updated in place either: its outputs are renamed into place one after another, so a run killed
  // after the map's rename and run again inserted its frames twice into the map it had already updated.
  const std::string map_before = test::readText(dir_ / "m.hpdsmap");
  EXPECT_EQ(test::runHpds("sample" + q("a.ply") + " --mode map -o" + q("out.ply") + " --load-map" + q("m.hpdsmap") +
                              " --save-map" + q("m.hpdsmap"),
                          &log),
            1)
      << log;
  EXPECT_NE(log.find("--save-map: '" + (dir_ / "m.hpdsmap").string() + "' is the --load-map file"), std::string::npos)
      << log;
  EXPECT_EQ(test::readText(dir_ / "m.hpdsmap"), map_before);
  EXPECT_EQ(test::runHpds("sample" + q("a.ply") + " --mode map -o" + q("out.ply") + " --load-map" + q("m.hpdsmap") +
                              " --save-map" + q("m2.hpdsmap"),
                          &log),
            0)
      << log;
  EXPECT_EQ(test::readText(dir_ / "a.ply"), before);
}

TEST_F(OutputSafety, UnwritableOrMisnamedOutputsAreRefusedBeforeAnyWork) {
  writeRandomCloud(dir_ / "a.ply", 2000);
  writeText(dir_ / "plain", "a file, not a folder");
  for (const char *path : {"synth_frames/frame_000001.pcd", "synth_poses/poses.txt"}) {
    fs::create_directories((dir_ / path).parent_path());
    ASSERT_EQ(::mkfifo((dir_ / path).c_str(), 0644), 0) << std::strerror(errno);
  }
  const auto q = [&](const std::string &name) { return " " + shellQuote(dir_ / name); };
  const std::string sample = "sample" + q("a.ply");
  const std::vector<Refusal> cases = {
      // Each after a valid -o: the PLY must not be written when a later output cannot be.
      {sample + " -o" + q("out.ply") + " --stats" + q("nodir/s.json"), "--stats: '" + (dir_ / "nodir/s.json").string() +
                                                                          "' is in folder '" +
                                                                          (dir_ / "nodir").string() +
                                                                          "', which does not exist"},
      {sample + " -o" + q("out.ply") + " --mode map --save-map" + q("nodir/m.hpdsmap"), "which does not exist"},
      {sample + " -o" + q("out.ply") + " --stats" + q("plain/s.json"), "which is not a folder"},
      {sample + " -o" + q("adir.ply/x.ply"), "does not exist"},
      {sample + " -o" + q("out.pcd"), "-o: '" + (dir_ / "out.pcd").string() + "' must end in .ply"},
      {sample + " -o" + q("out.ply") + " --stats" + q("s.txt"), "must end in .json"},
      {sample + " -o" + q("out.ply") + " --mode map --save-map" + q("m.ply"), "has the extension of another format"},
      {"render" + q("a.ply") + " -o" + q("plain/pictures"), "is not a folder"},
      {"analyze" + q("a.ply") + " --cell-size 4 -o" + q("plain"), "exists and is not a folder"},
      {"synth -o" + q("plain/frames"), "is not a folder"},
      // A symbolic link into a missing folder: refused before the work, not when the temporary is created after it.
      {sample + " -o" + q("dangling.ply"), "is in folder '" + (dir_ / "gone").string() + "', which does not exist"},
  };
  fs::create_directory(dir_ / "dir.ply");
  fs::create_symlink(dir_ / "gone" / "out.ply", dir_ / "dangling.ply");
  for (const Refusal &c : cases) {
    std::string log;
    EXPECT_EQ(test::runHpds(c.args, &log), 1) << c.args << "\n" << log;
    EXPECT_NE(log.find("hpds: error: "), std::string::npos) << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << c.args << ": the PLY was written before the refusal";
  }
  std::string log;
  EXPECT_EQ(test::runHpds(sample + " -o" + q("dir.ply"), &log), 1);
  EXPECT_NE(log.find("is a directory"), std::string::npos) << log;
  if (::geteuid() != 0) {  // root may write anywhere
    fs::create_directory(dir_ / "locked");
    fs::permissions(dir_ / "locked", fs::perms::owner_read | fs::perms::owner_exec);
    EXPECT_EQ(test::runHpds(sample + " -o" + q("locked/out.ply"), &log), 1);
    EXPECT_NE(log.find("which is not writable"), std::string::npos) << log;
    fs::permissions(dir_ / "locked", fs::perms::owner_all);
  }
  // A device is no file to lose: any name.
  EXPECT_EQ(test::runHpds(sample + " -o /dev/null", &log), 0) << log;
}

// An output is written whole under a temporary name and renamed into place, which a pipe cannot take. Written into
// directly, `-o FIFO` sampled everything and then waited for a reader that may never come, and a reader got a
// cloud even when a later output failed. Each run here has a deadline: a run that waits fails the test, not hangs.
TEST_F(OutputSafety, PipesAndOtherSpecialFilesAreRefusedAsOutputsBeforeAnyWork) {
  writeRandomCloud(dir_ / "a.ply", 2000);
  const fs::path fifo = dir_ / "fifo.ply";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0) << std::strerror(errno);
  fs::create_symlink(fifo, dir_ / "to_fifo.ply");
  fs::create_directory(dir_ / "pictures");
  ASSERT_EQ(::mkfifo((dir_ / "pictures" / "render_feature_top.png").c_str(), 0644), 0) << std::strerror(errno);
  for (const char *path : {"synth_frames/frame_000001.pcd", "synth_poses/poses.txt"}) {
    fs::create_directories((dir_ / path).parent_path());
    ASSERT_EQ(::mkfifo((dir_ / path).c_str(), 0644), 0) << std::strerror(errno);
  }
  const auto q = [&](const std::string &name) { return " " + shellQuote(dir_ / name); };
  const std::string deadline = "timeout -s KILL 30 " + test::cliPath() + " ";
  const std::string sample = deadline + "sample" + q("a.ply");
  const std::vector<Refusal> cases = {
      {sample + " -o" + q("fifo.ply"), "-o: '" + fifo.string() + "' is a pipe (FIFO)"},
      {sample + " -o" + q("to_fifo.ply"), "is a pipe (FIFO)"},
      {sample + " -o" + q("out.ply") + " --stats" + q("fifo.ply"), "--stats: '" + fifo.string() + "' is a pipe"},
      // The shell's pipe behind /dev/stdout (test::runCommand reads the output through one).
      {sample + " -o /dev/stdout", "-o: '/dev/stdout' is a pipe (FIFO)"},
      {deadline + "render" + q("a.ply") + " -o" + q("pictures"), "is a pipe (FIFO)"},
      // synth writes its frames and poses.txt into its folder: a pipe there under either name held the run.
      {deadline + "synth -o" + q("synth_frames") + " --frames 2", "frame_000001.pcd' is a pipe (FIFO)"},
      {deadline + "synth -o" + q("synth_poses") + " --frames 1", "poses.txt' is a pipe (FIFO)"},
  };
  for (const Refusal &c : cases) {
    std::string log;
    EXPECT_EQ(test::runCommand(c.args, &log), 1) << c.args << "\n" << log;
    EXPECT_NE(log.find("hpds: error: "), std::string::npos) << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
    EXPECT_NE(log.find("write to a file"), std::string::npos) << log;
    EXPECT_EQ(log.find("samples"), std::string::npos) << c.args << ": sampled before the refusal\n" << log;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << c.args;
  }
  EXPECT_TRUE(fs::is_fifo(fifo));
  EXPECT_FALSE(fs::exists(dir_ / "synth_frames" / "frame_000000.pcd")) << "synth wrote a frame before the refusal";
  // The null device discards an output under any name, as before.
  std::string log;
  EXPECT_EQ(test::runCommand(sample + " -o /dev/null", &log), 0) << log;
}

}  // namespace
}  // namespace hpds
