// The `hpds` subcommands. Each registers itself on the app and runs from its callback; errors are thrown as
// exceptions and turned into "hpds: error: ..." with exit code 1 by main.
#pragma once

#include <CLI/CLI.hpp>

namespace hpds::cli {

void addSampleCommand(CLI::App &app);
void addVerifyCommand(CLI::App &app);
void addSynthCommand(CLI::App &app);
void addAnalyzeCommand(CLI::App &app);
void addRenderCommand(CLI::App &app);

}  // namespace hpds::cli
