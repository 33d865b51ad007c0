// loadHierarchyBytes on the fuzzer's bytes, as they are and with both CRC-32s recomputed (so that mutations reach the
// checks behind the checksums): only std::runtime_error may come out; a loaded map must save and load back equal.
#include <cstring>
#include <stdexcept>
#include <vector>

#include "FuzzSupport.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/util/Crc32.hpp"

namespace {

void loadAndCheck(const std::uint8_t *data, std::size_t size) {
  hpds::LoadedHierarchy loaded{hpds::Hierarchy(1.0, 0), 0};
  try {
    loaded = hpds::loadHierarchyBytes(data, size, "fuzz");
  } catch (const std::runtime_error &) {
    return;
  }
  const std::string path = hpds::fuzz::writeTemp("again.hpdsmap", nullptr, 0);
  hpds::saveHierarchy(path, loaded.hierarchy, loaded.next_frame);
  const hpds::LoadedHierarchy back = hpds::loadHierarchy(path);
  if (back.hierarchy.sampleCount() != loaded.hierarchy.sampleCount() || back.next_frame != loaded.next_frame ||
      !(back.hierarchy.recordLayout() == loaded.hierarchy.recordLayout()))
    hpds::fuzz::violated("map save/load round trip changed the map");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
  loadAndCheck(data, size);
  std::uint32_t header_size = 0;
  if (size < 20) return 0;
  std::memcpy(&header_size, data + 12, 4);
  if (header_size < 20 || std::uint64_t(header_size) + 4 > size) return 0;
  std::vector<std::uint8_t> fixed(data, data + size);
  const std::uint32_t h = hpds::crc32(fixed.data(), header_size - 4);
  std::memcpy(fixed.data() + header_size - 4, &h, 4);
  const std::uint32_t b = hpds::crc32(fixed.data() + header_size, size - header_size - 4);
  std::memcpy(fixed.data() + size - 4, &b, 4);
  loadAndCheck(fixed.data(), fixed.size());
  return 0;
}
