#include "hpds/io/KittiBin.hpp"

#include "io/FileAccess.hpp"

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <system_error>
#include <vector>

namespace hpds {
namespace {

using io_detail::fail;
using io_detail::FilePtr;
using io_detail::requireRegularFile;

constexpr std::size_t kRecordBytes = 16;

PointLayout kittiLayout() {
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  layout.append("intensity", FieldType::Float32);
  return layout;
}

// A coordinate no sensor-frame scan holds: beyond 100 km, or a subnormal-sized nonzero value. Real float32 records
// have none; the low halves of float64 values read as float32 are mostly such (their exponent bits are mantissa).
bool implausible(double v) {
  const double a = std::fabs(v);
  return std::isfinite(v) && (a > 1e5 || (a != 0.0 && a < 1e-30));
}

// numpy's default dtype is float64, so `points.tofile("x.bin")` writes 32-byte records that also pass the size
// check; read as float32 they are garbage that would be sampled without a word. Said only when the file reads
// plausibly as float64 x y z intensity, so that noise or odd-but-real float32 data is still just points.
void refuseFloat64Records(const std::string &path, const PointBuffer &cloud) {
  const std::size_t n = cloud.size();
  if (n < 2 || n % 2 != 0) return;
  std::size_t as_f32 = 0, as_f64 = 0;
  for (std::size_t i = 0; i < n; ++i) {
    float f[3];
    std::memcpy(f, cloud.record(i), sizeof f);
    as_f32 += implausible(f[0]) || implausible(f[1]) || implausible(f[2]) ? 1 : 0;
  }
  for (std::size_t i = 0; i < n / 2; ++i) {
    double d[4];
    std::memcpy(d, cloud.record(2 * i), sizeof d);
    as_f64 += !(std::isfinite(d[0]) && std::isfinite(d[1]) && std::isfinite(d[2])) || implausible(d[0]) ||
                      implausible(d[1]) || implausible(d[2])
                  ? 1
                  : 0;
  }
  if (as_f32 * 10 > n && as_f64 * 100 <= n / 2)
    fail(path, "not a KITTI .bin file: " + std::to_string(as_f32) + " of " + std::to_string(n) +
                   " float32 records have a coordinate beyond 100 km or subnormal, but read as float64 x y z "
                   "intensity " + std::to_string(n / 2 - as_f64) + " of its " + std::to_string(n / 2) +
                   " points are plausible; KITTI .bin is float32 "
                   "(with numpy: points.astype(numpy.float32).tofile(path))");
}

}  // namespace

PointBuffer readKittiBin(const std::string &path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  requireRegularFile(path);
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) fail(path, "cannot determine file size: " + ec.message());
  if (size == 0) fail(path, "empty file (0 bytes)");
  if (size % kRecordBytes != 0)
    fail(path, "not a KITTI .bin file: size " + std::to_string(size) + " bytes is not a multiple of " +
                   std::to_string(kRecordBytes) + " (float32 x y z intensity records)");

  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) fail(path, std::string("cannot open: ") + std::strerror(errno));
  const std::size_t n = static_cast<std::size_t>(size / kRecordBytes);
  PointBuffer cloud(kittiLayout(), n);
  // The record layout is exactly the file's, so the bytes go straight into the buffer.
  if (std::fread(cloud.bytes().data(), 1, cloud.bytes().size(), file.get()) != cloud.bytes().size())
    fail(path, std::string("read failed (file changed while reading?): ") +
                   (std::ferror(file.get()) ? std::strerror(errno) : "unexpected end of file"));
  refuseFloat64Records(path, cloud);
  return cloud;
}

void writeKittiBin(const std::string &path, const PointBuffer &cloud) {
  const PointLayout &layout = cloud.layout();
  const PointField *fx = layout.find("x");
  const PointField *fy = layout.find("y");
  const PointField *fz = layout.find("z");
  const PointField *fi = layout.find("intensity");
  if (!fx || !fy || !fz) fail(path, "cannot write KITTI .bin: the cloud has no x/y/z fields");

  io_detail::OutputFile file(path);

  // Converted in chunks so that memory stays bounded for huge clouds while fwrite calls stay few.
  constexpr std::size_t kChunkPoints = 1 << 16;
  std::vector<float> chunk;
  chunk.reserve(kChunkPoints * 4);
  const std::size_t n = cloud.size();
  for (std::size_t begin = 0; begin < n; begin += kChunkPoints) {
    const std::size_t end = std::min(n, begin + kChunkPoints);
    chunk.clear();
    for (std::size_t i = begin; i < end; ++i) {
      const std::uint8_t *rec = cloud.record(i);
      chunk.push_back(static_cast<float>(readAsDouble(rec, *fx)));
      chunk.push_back(static_cast<float>(readAsDouble(rec, *fy)));
      chunk.push_back(static_cast<float>(readAsDouble(rec, *fz)));
      chunk.push_back(fi ? static_cast<float>(readAsDouble(rec, *fi)) : 0.0f);
    }
    file.write(chunk.data(), chunk.size() * sizeof(float));
  }
  file.close();
}

}  // namespace hpds
