// `hpds synth`: placeholder until SyntheticLidar lands.
#include "Commands.hpp"

namespace hpds::cli {
void addSynthCommand(CLI::App &) {}
}  // namespace hpds::cli
