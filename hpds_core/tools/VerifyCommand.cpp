// `hpds verify`: placeholder until SamplingVerifier lands.
#include "Commands.hpp"

namespace hpds::cli {
void addVerifyCommand(CLI::App &) {}
}  // namespace hpds::cli
