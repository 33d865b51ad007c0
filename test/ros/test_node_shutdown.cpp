// rostest node: the shutdown of the standalone node says what became of the map. This test starts hpds_node
// processes itself (output captured in a file), feeds them frames and stops them the ways a user does: Ctrl-C
// (SIGINT), roslaunch's escalation (SIGTERM) and `rosnode kill` (XML-RPC shutdown). With ros/save_map_on_shutdown
// the log must say "saved N samples" (and the file hold them) or, when the save fails, an ERROR line and exit
// status 1: never nothing, which is what happened while the save ran after roscpp had taken its logging down.
//
// Parameters: ~node_binary (the hpds_node executable), ~map_dir (created here).
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include "RosTestUtil.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/eval/SyntheticLidar.hpp"

namespace {

namespace fs = std::filesystem;
using hpds_test::Collector;
using hpds_test::contains;
using sensor_msgs::PointCloud2;

std::string readText(const fs::path &p) {
  const std::vector<std::uint8_t> b = hpds_test::readBytes(p);
  return std::string(b.begin(), b.end());
}

// Starts hpds_node (or, with `nodelet`, `nodelet standalone hpds/HpdsNodelet`) as `name` in map mode, saving to
// `map_file` on shutdown, with its output in `log`.
pid_t startNode(const std::string &name, const std::string &map_file, const fs::path &log, bool nodelet = false) {
  const std::string binary = ros::NodeHandle("~").param<std::string>("node_binary", "");
  std::vector<std::string> args = {binary};
  if (nodelet) args = {ros::NodeHandle("~").param<std::string>("nodelet_binary", "/usr/lib/nodelet/nodelet"),
                       "standalone", "hpds/HpdsNodelet"};
  const std::vector<std::string> rest = {"__name:=" + name,
                                         "_mode:=map",
                                         "_ros/fixed_frame:=odom",
                                         "_ros/local_map_rate:=0.0",
                                         "_ros/save_map_on_shutdown:=true",
                                         "_ros/map_file:=" + map_file,
                                         "_hierarchy/max_depth:=6",
                                         "_output/level:=4",
                                         "~input:=/" + name + "_points"};
  args.insert(args.end(), rest.begin(), rest.end());
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    std::vector<char *> argv;
    for (std::string &s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

// Exit status of `pid` (128 + signal when killed), or -1 when it does not end within `seconds`.
int waitExit(pid_t pid, double seconds) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (ros::WallTime::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return -1;
    }
    ros::WallDuration(0.02).sleep();
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

class NodeShutdown : public testing::Test {
 protected:
  void SetUp() override {
    std::string dir = ros::NodeHandle("~").param<std::string>("map_dir", "");
    if (dir.empty()) dir = (fs::temp_directory_path() / "hpds_test_shutdown").string();
    dir_ = dir;
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }

  // Starts the node, sends it three frames (waiting for each one's output), stops it with `stop`, and returns its
  // exit status and log.
  std::pair<int, std::string> runAndStop(const std::string &name, const std::string &map_file,
                                         const std::function<void(pid_t)> &stop, bool nodelet = false) {
    const fs::path log = dir_ / (name + ".log");
    const pid_t pid = startNode(name, map_file, log, nodelet);
    EXPECT_GT(pid, 0);
    Collector<PointCloud2> output(nh_, "/" + name + "/output");
    ros::Publisher pub = nh_.advertise<PointCloud2>("/" + name + "_points", 8);
    const bool up = hpds_test::waitFor([&] { return output.connected() && pub.getNumSubscribers() > 0; }, 60.0);
    EXPECT_TRUE(up) << name << " did not come up:\n" << readText(log);
    if (up) {
      hpds::SyntheticLidarConfig c;
      c.beams = 16;
      c.azimuth_steps = 600;
      c.frames = 3;
      c.emit_no_returns = false;
      const hpds::SyntheticLidar lidar(c);
      for (int i = 0; i < 3; ++i) {
        pub.publish(hpds_test::fixedFrameMsg(lidar, i, "odom", ros::Time(100 + i, 0)));
        EXPECT_TRUE(hpds_test::waitFor([&] { return output.size() >= std::size_t(i + 1); }, 60.0))
            << "no output for frame " << i << ":\n" << readText(log);
      }
    }
    stop(pid);
    const int status = waitExit(pid, 60.0);
    return {status, readText(log)};
  }

  // A run whose save must fail: the map's folder is there when the node starts (a missing one is refused at start)
  // and gone when it is stopped with SIGINT. Returns the exit status and log; `file` receives the map's path.
  std::pair<int, std::string> runWithVanishingFolder(const std::string &name, bool nodelet, std::string &file) {
    const fs::path folder = dir_ / ("vanishing_" + name);
    fs::create_directories(folder);
    file = (folder / "m.hpdsmap").string();
    return runAndStop(name, file, [&](pid_t pid) {
      fs::remove_all(folder);
      ::kill(pid, SIGINT);
    }, nodelet);
  }

  // The log says "hpds /<name>: shutdown: saved N samples ... to '<file>'" and the file holds N samples.
  void expectSaved(const std::string &log, const std::string &file, const std::string &name) {
    const std::string said = "hpds /" + name + ": shutdown: saved ";
    const std::size_t at = log.find(said);
    ASSERT_NE(at, std::string::npos) << "the shutdown save was not logged:\n" << log;
    EXPECT_TRUE(contains(log.substr(at), "to '" + file + "'")) << log;
    std::size_t samples = 0;
    ASSERT_EQ(std::sscanf(log.c_str() + at + said.size(), "%zu samples", &samples), 1) << log;
    EXPECT_GT(samples, 0u);
    const hpds::LoadedHierarchy loaded = hpds::loadHierarchy(file);
    EXPECT_EQ(loaded.hierarchy.sampleCount(), samples);
    EXPECT_EQ(loaded.next_frame, 3u);
  }

  fs::path dir_;
  ros::NodeHandle nh_;
};

TEST_F(NodeShutdown, CtrlCSavesTheMapAndSaysSo) {
  const std::string file = (dir_ / "sigint.hpdsmap").string();
  const auto [status, log] = runAndStop("hpds_shutdown_sigint", file, [](pid_t pid) { ::kill(pid, SIGINT); });
  EXPECT_EQ(status, 0) << log;
  expectSaved(log, file, "hpds_shutdown_sigint");
}

TEST_F(NodeShutdown, SigtermSavesTheMapAndSaysSo) {
  const std::string file = (dir_ / "sigterm.hpdsmap").string();
  const auto [status, log] = runAndStop("hpds_shutdown_sigterm", file, [](pid_t pid) { ::kill(pid, SIGTERM); });
  EXPECT_EQ(status, 0) << log;
  expectSaved(log, file, "hpds_shutdown_sigterm");
}

TEST_F(NodeShutdown, RosnodeKillSavesTheMapAndSaysSo) {
  const std::string file = (dir_ / "rosnode.hpdsmap").string();
  const auto [status, log] = runAndStop("hpds_shutdown_rosnode", file, [](pid_t) {
    EXPECT_EQ(std::system("rosnode kill /hpds_shutdown_rosnode > /dev/null 2>&1"), 0);
  });
  EXPECT_EQ(status, 0) << log;
  expectSaved(log, file, "hpds_shutdown_rosnode");
}

TEST_F(NodeShutdown, AFailedSaveIsAnErrorLineAndExitStatusOne) {
  std::string file;
  const auto [status, log] = runWithVanishingFolder("hpds_shutdown_fail", false, file);
  EXPECT_EQ(status, 1) << log;
  EXPECT_TRUE(contains(log, "[ERROR]") && contains(log, "hpds /hpds_shutdown_fail: shutdown: the map was not saved: saving the map failed: " +
                                                            file + ": cannot create a temporary file beside it"))
      << log;
}

// A nodelet is destroyed after its manager's ros::shutdown(), when rosconsole no longer prints: the save's outcome
// goes to stderr instead (it said nothing). The manager's exit status is its own.
TEST_F(NodeShutdown, ANodeletSaysWhatBecameOfTheMap) {
  const std::string file = (dir_ / "nodelet.hpdsmap").string();
  const auto [status, log] =
      runAndStop("hpds_shutdown_nodelet", file, [](pid_t pid) { ::kill(pid, SIGINT); }, true);
  EXPECT_GE(status, 0) << log;
  expectSaved(log, file, "hpds_shutdown_nodelet");
  std::string lost;
  const auto [status2, log2] = runWithVanishingFolder("hpds_shutdown_nodelet_fail", true, lost);
  EXPECT_GE(status2, 0) << log2;
  EXPECT_TRUE(contains(log2, "[ERROR]") && contains(log2, "hpds /hpds_shutdown_nodelet_fail: shutdown: the map was not saved")) << log2;
}

// A map file that names a folder passed the start-up check and failed at shutdown, after all the mapping.
TEST_F(NodeShutdown, AMapFileThatIsAFolderIsRefusedAtStart) {
  for (const std::string &path : {dir_.string(), (dir_ / "maps").string() + "/"}) {
    SCOPED_TRACE(path);
    fs::create_directories(dir_ / "maps");
    const fs::path log = dir_ / "folder.log";
    const pid_t pid = startNode("hpds_shutdown_folder", path, log);
    const int status = waitExit(pid, 60.0);
    const std::string text = readText(log);
    EXPECT_NE(status, 0) << text;
    EXPECT_NE(status, -1) << "the node did not stop by itself:\n" << text;
    EXPECT_TRUE(contains(text, "ros/map_file") && contains(text, "folder")) << text;
  }
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_shutdown"); }
