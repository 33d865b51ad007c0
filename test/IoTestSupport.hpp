// Helpers of the cloud-file tests (test_io_*.cpp): self-removing scratch directories, raw bytes in and out, the
// error every reader and writer must give, bit-exact value comparison, a cloud of every datatype, PCD headers.
// Core only (no PCL), so it suits any test of the readers and writers.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "TestData.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds::test {

namespace fs = std::filesystem;

// A scratch directory that is removed when the test ends, so repeated runs do not fill /tmp.
struct ScratchDir {
  explicit ScratchDir(const std::string &tag) : path(test::scratchDir(tag)) {}
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  ScratchDir(const ScratchDir &) = delete;
  ScratchDir &operator=(const ScratchDir &) = delete;
  fs::path path;
};

inline void writeBytes(const fs::path &path, const std::string &bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

inline std::string readBytes(const fs::path &path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

template <typename T>
inline std::string bytesOf(const std::vector<T> &values) {
  return std::string(reinterpret_cast<const char *>(values.data()), values.size() * sizeof(T));
}

// x, y, z of `type`, in that order from offset 0.
inline PointLayout xyzLayout(FieldType type = FieldType::Float32) {
  PointLayout layout;
  for (const char *axis : {"x", "y", "z"}) layout.append(axis, type);
  return layout;
}

// Runs `fn`, which must throw std::runtime_error mentioning the path and every one of `parts`.
inline void expectError(const std::function<void()> &fn, const std::string &path,
                        std::vector<std::string> parts = {}) {
  try {
    fn();
  } catch (const std::runtime_error &e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << "message does not name the path: " << msg;
    for (const auto &p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "missing '" << p << "' in: " << msg;
    return;
  } catch (const std::exception &e) {
    ADD_FAILURE() << "expected std::runtime_error, got another exception: " << e.what();
    return;
  }
  ADD_FAILURE() << "no exception for " << path;
}

// Bit-exact comparison: NaN payloads and -0.0 must survive a byte-copying round trip too.
inline bool sameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

inline void expectSameValues(const PointBuffer &a, const PointField &fa, const PointBuffer &b, const PointField &fb) {
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(fa.count, fb.count);
  for (std::size_t i = 0; i < a.size(); ++i)
    for (std::uint32_t c = 0; c < fa.count; ++c) {
      const double va = readAsDouble(a.record(i), fa, c);
      const double vb = readAsDouble(b.record(i), fb, c);
      if (std::isnan(va)) {
        EXPECT_TRUE(std::isnan(vb)) << fa.name << " point " << i;
      } else {
        ASSERT_TRUE(sameBits(va, vb)) << fa.name << "[" << c << "] point " << i << ": " << va << " vs " << vb;
      }
    }
}

inline constexpr FieldType kAllTypes[] = {FieldType::Int8,  FieldType::UInt8,  FieldType::Int16,   FieldType::UInt16,
                                   FieldType::Int32, FieldType::UInt32, FieldType::Float32, FieldType::Float64};

inline double extremeValue(FieldType t, int which) {
  auto pick = [which](auto lo, auto hi) -> double {
    const double vals[] = {double(lo), double(hi), 0.0, 1.0};
    return vals[which % 4];
  };
  switch (t) {
    case FieldType::Int8:
      return pick(std::numeric_limits<std::int8_t>::min(), std::numeric_limits<std::int8_t>::max());
    case FieldType::UInt8:
      return pick(0, std::numeric_limits<std::uint8_t>::max());
    case FieldType::Int16:
      return pick(std::numeric_limits<std::int16_t>::min(), std::numeric_limits<std::int16_t>::max());
    case FieldType::UInt16:
      return pick(0, std::numeric_limits<std::uint16_t>::max());
    case FieldType::Int32:
      return pick(std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::max());
    case FieldType::UInt32:
      return pick(0u, std::numeric_limits<std::uint32_t>::max());
    case FieldType::Float32:
      return pick(-std::numeric_limits<float>::max(), std::numeric_limits<float>::denorm_min());
    case FieldType::Float64:
      return pick(-std::numeric_limits<double>::max(), std::numeric_limits<double>::denorm_min());
  }
  return 0;
}

// A cloud with every datatype, count > 1 fields, and padding gaps inside the record.
inline PointBuffer makeAllTypesCloud(std::size_t n, std::uint32_t seed) {
  PointLayout layout = xyzLayout();
  layout.point_step += 3;  // gap
  for (FieldType t : kAllTypes) {
    layout.append(std::string("v_") + fieldTypeName(t), t);
    layout.point_step += 1;  // odd gaps make every later field unaligned
  }
  layout.append("arr_f64", FieldType::Float64, 3);
  layout.append("arr_i8", FieldType::Int8, 2);
  layout.append("arr_u16", FieldType::UInt16, 4);
  layout.point_step += 5;
  layout.validate();

  PointBuffer cloud(layout, n);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(-1000.0, 1000.0);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint8_t *rec = cloud.record(i);
    std::memset(rec, 0xAB, layout.point_step);  // padding garbage must not matter
    for (const PointField &f : layout.fields)
      for (std::uint32_t c = 0; c < f.count; ++c) {
        // The first points carry each type's extremes, the rest random values (saturated into the type).
        const double v = i < 4 ? extremeValue(f.type, int(i + c)) : uni(rng) * (f.type == FieldType::Float64 ? 1e6 : 1);
        writeFromDouble(rec, f, v, c);
      }
  }
  return cloud;
}

inline std::string pcdHeader(const std::string &fields, const std::string &size, const std::string &type,
                      const std::string &count, const std::string &width, const std::string &height,
                      const std::string &points, const std::string &data) {
  return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " + size + "\nTYPE " +
         type + "\nCOUNT " + count + "\nWIDTH " + width + "\nHEIGHT " + height + "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
         points + "\nDATA " + data + "\n";
}

inline std::string xyzPcdHeader(std::size_t n, const std::string &data) {
  return pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", std::to_string(n), "1", std::to_string(n), data);
}

}  // namespace hpds::test
