#include "hpds/eval/PngWriter.hpp"
#include "hpds/util/Crc32.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string_view>

#include "hpds/io/AtomicFile.hpp"

namespace hpds {

RgbImage::RgbImage(int w, int h, std::uint8_t r, std::uint8_t g, std::uint8_t b) : width(w), height(h) {
  if (w <= 0 || h <= 0) throw std::invalid_argument("RgbImage: width and height must be > 0");
  rgb.resize(3 * static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  for (std::size_t i = 0; i < rgb.size(); i += 3) rgb[i] = r, rgb[i + 1] = g, rgb[i + 2] = b;
}

std::uint32_t adler32(const std::uint8_t *data, std::size_t size) {
  std::uint32_t a = 1, b = 0;
  // 5552 is the longest run for which b cannot overflow 32 bits before the modulo (as zlib's NMAX).
  while (size > 0) {
    const std::size_t run = std::min<std::size_t>(size, 5552);
    for (std::size_t i = 0; i < run; ++i) a += data[i], b += a;
    a %= 65521u;
    b %= 65521u;
    data += run;
    size -= run;
  }
  return (b << 16) | a;
}

namespace {

class BitWriter {
 public:
  explicit BitWriter(std::vector<std::uint8_t> &out) : out_(out) {}
  /// Appends the low `n` bits of `v`, least significant first (deflate's order for everything but Huffman codes).
  void bits(std::uint32_t v, int n) {
    acc_ |= static_cast<std::uint64_t>(v) << count_;
    count_ += n;
    while (count_ >= 8) {
      out_.push_back(static_cast<std::uint8_t>(acc_ & 0xFFu));
      acc_ >>= 8;
      count_ -= 8;
    }
  }
  /// Huffman codes are defined most significant bit first.
  void code(std::uint32_t c, int n) {
    std::uint32_t r = 0;
    for (int i = 0; i < n; ++i) r |= ((c >> i) & 1u) << (n - 1 - i);
    bits(r, n);
  }
  void flush() {
    if (count_ > 0) out_.push_back(static_cast<std::uint8_t>(acc_ & 0xFFu));
    acc_ = 0;
    count_ = 0;
  }

 private:
  std::vector<std::uint8_t> &out_;
  std::uint64_t acc_ = 0;
  int count_ = 0;
};

// The fixed literal/length code of RFC 1951, 3.2.6.
void writeLiteralLength(BitWriter &w, int sym) {
  if (sym < 144)
    w.code(0x30u + sym, 8);
  else if (sym < 256)
    w.code(0x190u + (sym - 144), 9);
  else if (sym < 280)
    w.code(static_cast<std::uint32_t>(sym - 256), 7);
  else
    w.code(0xC0u + (sym - 280), 8);
}

constexpr std::array<int, 29> kLengthBase = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,  15,  17,  19,  23, 27,
                                             31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
constexpr std::array<int, 29> kLengthExtra = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                              2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
constexpr std::array<int, 30> kDistBase = {1,   2,   3,   4,   5,   7,    9,    13,   17,   25,   33,   49,   65,    97,    129,
                                           193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
constexpr std::array<int, 30> kDistExtra = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6,
                                            6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};

void writeMatch(BitWriter &w, int length, int distance) {
  int lc = 28;
  while (kLengthBase[static_cast<std::size_t>(lc)] > length) --lc;
  writeLiteralLength(w, 257 + lc);
  w.bits(static_cast<std::uint32_t>(length - kLengthBase[static_cast<std::size_t>(lc)]), kLengthExtra[static_cast<std::size_t>(lc)]);
  int dc = 29;
  while (kDistBase[static_cast<std::size_t>(dc)] > distance) --dc;
  w.code(static_cast<std::uint32_t>(dc), 5);
  w.bits(static_cast<std::uint32_t>(distance - kDistBase[static_cast<std::size_t>(dc)]), kDistExtra[static_cast<std::size_t>(dc)]);
}

}  // namespace

std::vector<std::uint8_t> zlibCompress(const std::vector<std::uint8_t> &data) {
  constexpr int kWindow = 32768, kMinMatch = 3, kMaxMatch = 258, kHashBits = 15, kMaxChain = 48;
  std::vector<std::uint8_t> out = {0x78, 0x01};  // deflate, 32 KiB window; 0x7801 % 31 == 0 as the header requires
  BitWriter w(out);
  w.bits(1, 1);  // final block
  w.bits(1, 2);  // fixed Huffman codes
  const std::size_t n = data.size();
  std::vector<std::int64_t> head(std::size_t{1} << kHashBits, -1);
  std::vector<std::int64_t> prev(kWindow, -1);
  auto hashAt = [&](std::size_t i) {
    const std::uint32_t v = data[i] | (data[i + 1] << 8) | (data[i + 2] << 16);
    return (v * 2654435761u) >> (32 - kHashBits);
  };
  auto insert = [&](std::size_t i) {
    if (i + kMinMatch > n) return;
    const std::uint32_t h = hashAt(i);
    prev[i % kWindow] = head[h];
    head[h] = static_cast<std::int64_t>(i);
  };
  std::size_t i = 0;
  while (i < n) {
    int best_len = 0, best_dist = 0;
    if (i + kMinMatch <= n) {
      const std::size_t limit = std::min<std::size_t>(kMaxMatch, n - i);
      std::int64_t cand = head[hashAt(i)];
      for (int chain = 0; cand >= 0 && chain < kMaxChain; ++chain) {
        const std::size_t c = static_cast<std::size_t>(cand);
        if (i - c > static_cast<std::size_t>(kWindow - 1)) break;
        std::size_t len = 0;
        while (len < limit && data[c + len] == data[i + len]) ++len;
        if (static_cast<int>(len) > best_len) {
          best_len = static_cast<int>(len);
          best_dist = static_cast<int>(i - c);
          if (len == limit) break;
        }
        const std::int64_t next = prev[c % kWindow];
        // A slot overwritten by a newer position would send the chain forward in the data: stop there.
        if (next >= cand) break;
        cand = next;
      }
    }
    if (best_len >= kMinMatch) {
      writeMatch(w, best_len, best_dist);
      for (int k = 0; k < best_len; ++k) insert(i + static_cast<std::size_t>(k));
      i += static_cast<std::size_t>(best_len);
    } else {
      writeLiteralLength(w, data[i]);
      insert(i);
      ++i;
    }
  }
  writeLiteralLength(w, 256);
  w.flush();
  const std::uint32_t a = adler32(data.data(), data.size());
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<std::uint8_t>((a >> s) & 0xFFu));
  return out;
}

namespace {

void putU32(std::vector<std::uint8_t> &v, std::uint32_t x) {
  for (int s = 24; s >= 0; s -= 8) v.push_back(static_cast<std::uint8_t>((x >> s) & 0xFFu));
}

void chunk(std::vector<std::uint8_t> &png, const char type[4], const std::vector<std::uint8_t> &payload) {
  putU32(png, static_cast<std::uint32_t>(payload.size()));
  const std::size_t start = png.size();
  png.insert(png.end(), type, type + 4);
  png.insert(png.end(), payload.begin(), payload.end());
  putU32(png, crc32(png.data() + start, png.size() - start));
}

int paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
}

}  // namespace

std::vector<std::uint8_t> encodePng(const RgbImage &image) {
  if (image.width <= 0 || image.height <= 0) throw std::invalid_argument("encodePng: empty image");
  const std::size_t stride = 3 * static_cast<std::size_t>(image.width);
  if (image.rgb.size() != stride * static_cast<std::size_t>(image.height))
    throw std::invalid_argument("encodePng: buffer size is not width * height * 3");
  std::vector<std::uint8_t> filtered;
  filtered.reserve((stride + 1) * static_cast<std::size_t>(image.height));
  std::vector<std::uint8_t> candidate[4];
  for (auto &c : candidate) c.resize(stride);
  const std::vector<std::uint8_t> zero_row(stride, 0);
  for (int y = 0; y < image.height; ++y) {
    const std::uint8_t *row = image.rgb.data() + stride * static_cast<std::size_t>(y);
    const std::uint8_t *up = y > 0 ? row - stride : zero_row.data();
    long best_cost = -1;
    int best = 0;
    for (int f = 0; f < 4; ++f) {  // 0 None, 1 Sub, 2 Up, 4 Paeth (stored as index 3)
      long cost = 0;
      for (std::size_t x = 0; x < stride; ++x) {
        const int a = x >= 3 ? row[x - 3] : 0, b = up[x], c = x >= 3 ? up[x - 3] : 0;
        const int pred = f == 0 ? 0 : f == 1 ? a : f == 2 ? b : paeth(a, b, c);
        const std::uint8_t r = static_cast<std::uint8_t>(row[x] - pred);
        candidate[f][x] = r;
        cost += r < 128 ? r : 256 - r;
      }
      if (best_cost < 0 || cost < best_cost) best_cost = cost, best = f;
    }
    filtered.push_back(static_cast<std::uint8_t>(best == 3 ? 4 : best));
    filtered.insert(filtered.end(), candidate[best].begin(), candidate[best].end());
  }

  std::vector<std::uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  std::vector<std::uint8_t> ihdr;
  putU32(ihdr, static_cast<std::uint32_t>(image.width));
  putU32(ihdr, static_cast<std::uint32_t>(image.height));
  ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});  // bit depth 8, truecolour, deflate, adaptive filtering, no interlace
  chunk(png, "IHDR", ihdr);
  chunk(png, "IDAT", zlibCompress(filtered));
  chunk(png, "IEND", {});
  return png;
}

void writePng(const std::string &path, const RgbImage &image) {
  const std::vector<std::uint8_t> bytes = encodePng(image);
  writeFileAtomically(path, std::string_view(reinterpret_cast<const char *>(bytes.data()), bytes.size()));
}

}  // namespace hpds
