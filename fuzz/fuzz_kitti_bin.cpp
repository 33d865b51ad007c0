// readPointCloud on a .bin file holding the fuzzer's bytes: only std::runtime_error may come out, and an accepted
// cloud must hold up in the pipeline and the PLY writer (FuzzSupport::exercise).
#include <stdexcept>

#include "FuzzSupport.hpp"
#include "hpds/io/PointCloudFile.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
  const std::string path = hpds::fuzz::writeTemp("input.bin", data, size);
  hpds::PointBuffer cloud;
  try {
    cloud = hpds::readPointCloud(path);
  } catch (const std::runtime_error &) {
    return 0;
  }
  hpds::fuzz::exercise(cloud);
  return 0;
}
