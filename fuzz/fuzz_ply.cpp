// readPointCloud on a .ply file holding the fuzzer's bytes: only std::runtime_error may come out, and an accepted
// cloud must hold up in the pipeline and the PLY writer (FuzzSupport::fuzzPointFile).
#include "FuzzSupport.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
  return hpds::fuzz::fuzzPointFile(data, size, ".ply");
}
