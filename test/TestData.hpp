// Helpers shared by the tests: where the real lidar frames are, and scratch directories.
#pragma once

#include <filesystem>
#include <string>

namespace hpds::test {

/// ../shared/data/lidar beside the clone, or empty when it is absent (a user's clone has no shared/).
std::filesystem::path sharedLidarDir();

/// Puts `GTEST_SKIP()` in the caller when the shared data is absent; use as `HPDS_REQUIRE_SHARED_DATA();`.
#define HPDS_REQUIRE_SHARED_DATA()                                                                         \
  do {                                                                                                     \
    if (::hpds::test::sharedLidarDir().empty())                                                            \
      GTEST_SKIP() << "../shared/data/lidar is absent: real-frame test skipped (CI has it; clones do not)"; \
  } while (0)

/// A fresh empty directory under the system temp dir, unique per test.
std::filesystem::path scratchDir(const std::string &tag);

/// Path of the built `hpds` executable.
std::string cliPath();

/// Runs a shell command, returns its exit status (0..255) and captures stdout+stderr into `output`.
int runCommand(const std::string &command, std::string *output = nullptr);

/// `path` single-quoted for a shell command line.
std::string shellQuote(const std::filesystem::path &path);

/// Runs `hpds ARGS` (the built CLI), as runCommand.
int runHpds(const std::string &args, std::string *output = nullptr);

/// The whole file as text ("" when it cannot be read).
std::string readText(const std::filesystem::path &path);

}  // namespace hpds::test
