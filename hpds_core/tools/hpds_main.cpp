// hpds: command-line front end. Errors go to stderr as "hpds: error: ..." with exit code 1 (2 for bad usage).
#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>

#include "Commands.hpp"
#include "hpds/util/FrameMemory.hpp"
#ifdef HPDS_WITH_ROS
#include "ReplayCommand.hpp"
#endif

int main(int argc, char **argv) {
  // Streams of dense frames (`sample` with several inputs, `replay`) reuse each frame's freed memory.
  hpds::keepFreedFrameMemory();
  CLI::App app{"hpds: hierarchical additive Poisson-disk sampling of lidar point clouds"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "hpds " HPDS_VERSION);
  // A bad command line is said like every other error (README: "hpds: error: ..."), with exit code 2.
  app.failure_message([](const CLI::App *, const CLI::Error &e) {
    return std::string("hpds: error: ") + e.what() + "\nRun with --help for more information.\n";
  });
  hpds::cli::addSampleCommand(app);
  hpds::cli::addVerifyCommand(app);
#ifdef HPDS_WITH_ROS
  hpds::cli::addSynthCommand(app, hpds::cli::openSynthBag);
#else
  hpds::cli::addSynthCommand(app);
#endif
  hpds::cli::addAnalyzeCommand(app);
  hpds::cli::addRenderCommand(app);
#ifdef HPDS_WITH_ROS
  hpds::cli::addReplayCommand(app);
#endif
  // CLI11 answers a mistyped command with "A subcommand is required"; say which word was not one.
  std::string names;
  bool known = false;
  for (const CLI::App *sub : app.get_subcommands([](const CLI::App *) { return true; })) {
    names += (names.empty() ? "" : ", ") + sub->get_name();
    known = known || (argc > 1 && sub->check_name(argv[1]));
  }
  if (argc > 1 && argv[1][0] != '-' && !known) {
    std::cerr << "hpds: error: unknown command '" << argv[1] << "': one of " << names
              << "\nRun with --help for more information.\n";
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::RuntimeError &e) {
    return e.get_exit_code();
  } catch (const CLI::ParseError &e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const std::exception &e) {
    std::cerr << "hpds: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
