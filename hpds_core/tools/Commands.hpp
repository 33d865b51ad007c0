// The `hpds` subcommands. Each registers itself on the app and runs from its callback; errors are thrown as
// exceptions and turned into "hpds: error: ..." with exit code 1 by main.
#pragma once

#include <CLI/CLI.hpp>

#include "SynthBag.hpp"

namespace hpds::cli {

void addSampleCommand(CLI::App &app);
void addVerifyCommand(CLI::App &app);
/// `open_bag`: the bag writer of a build with ROS (openSynthBag); without it, --bag fails with a clear error.
void addSynthCommand(CLI::App &app, SynthBagOpener open_bag = nullptr);
void addAnalyzeCommand(CLI::App &app);
void addRenderCommand(CLI::App &app);

}  // namespace hpds::cli
