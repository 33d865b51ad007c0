// PNG writer for 8-bit RGB images, with its own deflate encoder so the core needs no zlib.
//
// Contract
// - encodePng returns a complete PNG file: IHDR (8-bit truecolour, no interlace), one IDAT, IEND, with CRC-32 per
//   chunk. The zlib stream holds one fixed-Huffman deflate block (RFC 1951 section 3.2.6) fed by a greedy LZ77
//   matcher over a 32 KiB window and closed by the Adler-32 of the filtered scanlines; each scanline uses the PNG
//   filter (None, Sub, Up, Paeth) with the smallest sum of absolute residuals. Plots and renderings are mostly flat
//   colour, which this compresses well; photographs would compress less than with zlib, but stay valid.
// - writePng writes that file atomically (AtomicFile); std::runtime_error starting with the path on I/O failure.
// - Throws std::invalid_argument for an image whose width/height is not positive or whose buffer size is not
//   width * height * 3.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace hpds {

struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  ///< row-major, top row first, 3 bytes per pixel

  RgbImage() = default;
  RgbImage(int w, int h, std::uint8_t r = 255, std::uint8_t g = 255, std::uint8_t b = 255);
  void set(int x, int y, std::uint8_t r, std::uint8_t g, std::uint8_t b) {
    std::uint8_t *p = &rgb[3 * (static_cast<std::size_t>(y) * width + x)];
    p[0] = r, p[1] = g, p[2] = b;
  }
  [[nodiscard]] const std::uint8_t *at(int x, int y) const { return &rgb[3 * (static_cast<std::size_t>(y) * width + x)]; }
};

[[nodiscard]] std::vector<std::uint8_t> encodePng(const RgbImage &image);

void writePng(const std::string &path, const RgbImage &image);

/// zlib-format compression (deflate + Adler-32) of `data` with the encoder above; exposed for tests.
[[nodiscard]] std::vector<std::uint8_t> zlibCompress(const std::vector<std::uint8_t> &data);

/// Adler-32 of a byte range (the zlib trailer); exposed for tests. CRC-32 lives in hpds/util/Crc32.hpp.
[[nodiscard]] std::uint32_t adler32(const std::uint8_t *data, std::size_t size);

}  // namespace hpds
