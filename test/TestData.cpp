#include "TestData.hpp"

#include <stdexcept>

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace hpds::test {

std::filesystem::path sharedLidarDir() {
  const std::filesystem::path dir(HPDS_SHARED_DATA_DIR);
  std::error_code ec;
  if (std::filesystem::is_directory(dir, ec) && std::filesystem::exists(dir / "hdl32_a.pcd", ec)) return dir;
  return {};
}

namespace {

// The scratch folders of this test process, removed when it exits unless a test failed (they are then what there is
// to look at) or HPDS_KEEP_TEST_SCRATCH is set: every `make test` left some 200 MB in /tmp.
struct ScratchRegistry {
  std::vector<std::filesystem::path> dirs;
  ~ScratchRegistry() {
    if (std::getenv("HPDS_KEEP_TEST_SCRATCH") || ::testing::UnitTest::GetInstance()->Failed()) return;
    std::error_code ec;
    for (const auto &d : dirs) std::filesystem::remove_all(d, ec);
  }
};

}  // namespace

std::filesystem::path scratchDir(const std::string &tag) {
  static ScratchRegistry registry;  // constructed after gtest's UnitTest, so destroyed before it
  static std::mt19937_64 rng(std::random_device{}());
  const auto dir = std::filesystem::temp_directory_path() /
                   ("hpds_test_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(rng() % 1000000));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  registry.dirs.push_back(dir);
  return dir;
}

#ifdef HPDS_CLI_PATH
std::string cliPath() { return HPDS_CLI_PATH; }
#else
std::string cliPath() { throw std::logic_error("this build has no hpds tool (built without PCL)"); }
#endif

int runCommand(const std::string &command, std::string *output) {
  FILE *pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  std::array<char, 4096> buf{};
  std::string out;
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) out.append(buf.data(), n);
  const int status = ::pclose(pipe);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

std::string shellQuote(const std::filesystem::path &path) { return "'" + path.string() + "'"; }

int runHpds(const std::string &args, std::string *output) { return runCommand(cliPath() + " " + args, output); }

std::string readText(const std::filesystem::path &path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

}  // namespace hpds::test
