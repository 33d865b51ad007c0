// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320): the checksum of map files and PNG chunks.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hpds {

/// CRC-32 of `size` bytes; pass the previous result as `crc` to continue over several pieces.
[[nodiscard]] std::uint32_t crc32(const void *data, std::size_t size, std::uint32_t crc = 0);

}  // namespace hpds
