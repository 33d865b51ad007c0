// File I/O: round trips through every writer, the real lidar frames, and malformed input of every kind.

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "TestData.hpp"
#include "hpds/points/PointBuffer.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"

namespace fs = std::filesystem;
using namespace hpds;

namespace {

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

void writeBytes(const fs::path &path, const std::string &bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

std::string readBytes(const fs::path &path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

template <typename T>
std::string bytesOf(const std::vector<T> &values) {
  return std::string(reinterpret_cast<const char *>(values.data()), values.size() * sizeof(T));
}

// x, y, z of `type`, in that order from offset 0.
PointLayout xyzLayout(FieldType type = FieldType::Float32) {
  PointLayout layout;
  for (const char *axis : {"x", "y", "z"}) layout.append(axis, type);
  return layout;
}

// Runs `fn`, which must throw std::runtime_error mentioning the path and every one of `parts`.
void expectError(const std::function<void()> &fn, const std::string &path, std::vector<std::string> parts = {}) {
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

// Reads a file that may be valid or not: either outcome is fine, anything else (crash, other exception) is not.
void readSurvives(const std::string &path) {
  try {
    const PointBuffer cloud = readPointCloud(path);
    EXPECT_TRUE(cloud.layout().find("x"));
  } catch (const std::runtime_error &e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

// Bit-exact comparison: NaN payloads and -0.0 must survive a byte-copying round trip too.
bool sameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

void expectSameValues(const PointBuffer &a, const PointField &fa, const PointBuffer &b, const PointField &fb) {
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

constexpr FieldType kAllTypes[] = {FieldType::Int8,  FieldType::UInt8,  FieldType::Int16,   FieldType::UInt16,
                                   FieldType::Int32, FieldType::UInt32, FieldType::Float32, FieldType::Float64};

double extremeValue(FieldType t, int which) {
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
PointBuffer makeAllTypesCloud(std::size_t n, std::uint32_t seed) {
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

std::string pcdHeader(const std::string &fields, const std::string &size, const std::string &type,
                      const std::string &count, const std::string &width, const std::string &height,
                      const std::string &points, const std::string &data) {
  return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " + size + "\nTYPE " +
         type + "\nCOUNT " + count + "\nWIDTH " + width + "\nHEIGHT " + height + "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
         points + "\nDATA " + data + "\n";
}

std::string xyzPcdHeader(std::size_t n, const std::string &data) {
  return pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", std::to_string(n), "1", std::to_string(n), data);
}

std::string xyzBody(std::size_t n) {
  std::vector<float> v;
  for (std::size_t i = 0; i < n; ++i) {
    v.push_back(float(i));
    v.push_back(float(i) * 0.5f);
    v.push_back(-float(i));
  }
  return bytesOf(v);
}

// LZF stream made only of literal runs (control byte len-1, then up to 32 bytes): valid input for any LZF decoder.
std::string lzfLiterals(const std::string &raw) {
  std::string out;
  for (std::size_t i = 0; i < raw.size(); i += 32) {
    const std::size_t len = std::min<std::size_t>(32, raw.size() - i);
    out += static_cast<char>(len - 1);
    out += raw.substr(i, len);
  }
  return out;
}

std::string u32le(std::uint32_t v) { return std::string(reinterpret_cast<const char *>(&v), 4); }

}  // namespace

// ---------------------------------------------------------------------------------------------------------------------
// Round trips

TEST(PlyRoundTrip, AllDatatypesAndArraysKeepTheirValues) {
  const ScratchDir scratch("io_ply");
  const fs::path &dir = scratch.path;
  const std::string path = (dir / "all.ply").string();
  const PointBuffer src = makeAllTypesCloud(257, 7);
  writePly(path, src);
  const std::string text = readBytes(path);
  ASSERT_EQ(text.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  EXPECT_NE(text.find("element vertex 257\n"), std::string::npos);
  for (const char *prop : {"property char v_int8\n", "property uchar v_uint8\n", "property short v_int16\n",
                           "property ushort v_uint16\n", "property int v_int32\n", "property uint v_uint32\n",
                           "property float v_float32\n", "property double v_float64\n", "property double arr_f64_2\n",
                           "property char arr_i8_1\n", "property ushort arr_u16_3\n"})
    EXPECT_NE(text.find(prop), std::string::npos) << prop;

  const PointBuffer back = readPointCloud(path);
  ASSERT_EQ(back.size(), src.size());
  EXPECT_EQ(back.width(), 257u);
  EXPECT_EQ(back.height(), 1u);
  for (const PointField &f : src.layout().fields) {
    if (f.count == 1) {
      const PointField *g = back.layout().find(f.name);
      ASSERT_NE(g, nullptr) << f.name;
      EXPECT_EQ(g->type, f.type) << f.name;
      EXPECT_EQ(g->count, 1u);
      expectSameValues(src, f, back, *g);
    } else {
      for (std::uint32_t c = 0; c < f.count; ++c) {
        const PointField *g = back.layout().find(f.name + "_" + std::to_string(c));
        ASSERT_NE(g, nullptr) << f.name << "_" << c;
        EXPECT_EQ(g->type, f.type);
        for (std::size_t i = 0; i < src.size(); ++i)
          ASSERT_TRUE(sameBits(readAsDouble(src.record(i), f, c), readAsDouble(back.record(i), *g)))
              << f.name << "_" << c << " point " << i;
      }
    }
  }
}

TEST(PlyRoundTrip, OrganisationUint8IntensityAndEmptyCloud) {
  const ScratchDir scratch("io_ply_org");
  const fs::path &dir = scratch.path;
  PointLayout layout;
  layout.append("x", FieldType::Float64);
  layout.append("y", FieldType::Float64);
  layout.append("z", FieldType::Float64);
  layout.append("intensity", FieldType::UInt8);  // PCL's reader widens this one to float; it must come back uint8
  PointBuffer src(layout, 12);
  for (std::size_t i = 0; i < 12; ++i) {
    writeFromDouble(src.record(i), layout.fields[0], 0.1 * double(i));
    writeFromDouble(src.record(i), layout.fields[1], -1e-300 * double(i));
    writeFromDouble(src.record(i), layout.fields[2], std::numeric_limits<double>::quiet_NaN());
    writeFromDouble(src.record(i), layout.fields[3], double(i * 21));
  }
  src.setOrganization(4, 3);
  const std::string path = (dir / "org.PLY").string();  // extension matching is case-insensitive
  writePly(path, src);
  const PointBuffer back = readPointCloud(path);
  EXPECT_EQ(back.width(), 4u);
  EXPECT_EQ(back.height(), 3u);
  const PointField *intensity = back.layout().find("intensity");
  ASSERT_NE(intensity, nullptr);
  EXPECT_EQ(intensity->type, FieldType::UInt8);
  for (const PointField &f : layout.fields) expectSameValues(src, f, back, *back.layout().find(f.name));

  PointBuffer empty(layout, 0);
  const std::string empty_path = (dir / "empty.ply").string();
  writePly(empty_path, empty);
  const PointBuffer empty_back = readPointCloud(empty_path);
  EXPECT_EQ(empty_back.size(), 0u);
  EXPECT_NE(empty_back.layout().find("z"), nullptr);
}

// PCL packs uchar red/green/blue only as a run red, green, blue (+ alpha); other arrangements (found by fuzz_pcd: a
// lone `red`) are read by hpds itself, which keeps every property as declared: name, type and bytes.
TEST(PlyRoundTrip, ColoursPclCannotPackKeepTheirFieldsAndBytes) {
  const ScratchDir scratch("io_ply_colours");
  const fs::path &dir = scratch.path;
  // A lone channel, another order, an incomplete set, a name clash with PCL's "rgb", an alpha before the colours
  // (PCL asserts), another property inside the run.
  const std::vector<std::vector<std::string>> arrangements = {
      {"red"},         {"diffuse_green"},         {"alpha"}, {"blue", "green", "red"}, {"red", "blue"},
      {"red", "green", "blue", "rgb"}, {"alpha", "red", "green", "blue"}, {"red", "intensity", "green", "blue"},
  };
  int variant = 0;
  for (const auto &extra : arrangements) {
    SCOPED_TRACE(::testing::PrintToString(extra));
    PointLayout layout;
    layout.append("x", FieldType::Float64);
    for (const auto &name : extra) layout.append(name, FieldType::UInt8);
    layout.append("y", FieldType::Float32);
    layout.append("z", FieldType::Int16);
    PointBuffer src(layout, 12);
    for (std::size_t i = 0; i < src.size(); ++i)
      for (std::size_t k = 0; k < layout.fields.size(); ++k)
        writeFromDouble(src.record(i), layout.fields[k], double(i * 37 + k * 11) - (k == 0 ? 100.25 : 0.0));
    if (variant++ % 2) src.setOrganization(4, 3);
    const std::string path = (dir / "colours.ply").string();
    writePly(path, src);
    const PointBuffer back = readPointCloud(path);
    ASSERT_EQ(back.size(), src.size());
    EXPECT_EQ(back.width(), src.width());
    EXPECT_EQ(back.height(), src.height());
    ASSERT_EQ(back.layout().fields.size(), layout.fields.size());
    for (const PointField &f : layout.fields) {
      const PointField *g = back.layout().find(f.name);
      ASSERT_NE(g, nullptr) << f.name;
      EXPECT_EQ(g->type, f.type) << f.name;
      EXPECT_EQ(g->count, 1u) << f.name;
      expectSameValues(src, f, back, *g);
    }
  }
}

// The reader of those files walks elements before the vertex (with list properties), handles ascii and big-endian
// data and refuses what does not add up.
TEST(PlyRead, OwnVertexReaderFormatsAndBadInput) {
  const ScratchDir scratch("io_ply_own");
  const fs::path &dir = scratch.path;
  const std::string face_then_vertex =
      "element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\nelement vertex 2\n"
      "property float x\nproperty float y\nproperty double z\nproperty uchar red\nproperty short _\n";

  writeBytes(dir / "ascii.ply", "ply\nformat ascii 1.0\n" + face_then_vertex + "end_header\n3 0 1 2 7\n0 8\n" +
                                    "1 2 3 4 -5\n-1.5 nan 1e999 255 6\n");
  const PointBuffer a = readPointCloud((dir / "ascii.ply").string());
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a.layout().point_step, 4u + 4 + 8 + 1 + 2);
  EXPECT_EQ(a.layout().find("_"), nullptr);  // padding, as PCL's "_" fields
  const PointField &red = *a.layout().find("red");
  EXPECT_EQ(red.type, FieldType::UInt8);
  EXPECT_EQ(readAsDouble(a.record(0), *a.layout().find("x")), 1.0);
  EXPECT_EQ(readAsDouble(a.record(0), *a.layout().find("z")), 3.0);
  EXPECT_EQ(readAsDouble(a.record(0), red), 4.0);
  EXPECT_EQ(readAsDouble(a.record(1), *a.layout().find("x")), -1.5);
  EXPECT_TRUE(std::isnan(readAsDouble(a.record(1), *a.layout().find("y"))));
  EXPECT_EQ(readAsDouble(a.record(1), *a.layout().find("z")), std::numeric_limits<double>::infinity());
  EXPECT_EQ(readAsDouble(a.record(1), red), 255.0);

  // The same cloud in big-endian binary, with a face list of an int size type in front.
  auto be = [](auto v) {
    std::string b(reinterpret_cast<const char *>(&v), sizeof v);
    std::reverse(b.begin(), b.end());
    return b;
  };
  const std::string be_head = "ply\nformat binary_big_endian 1.0\nelement face 1\nproperty list int uchar idx\n"
                              "element vertex 2\nproperty float x\nproperty float y\nproperty double z\n"
                              "property uchar red\nend_header\n";
  const std::string be_faces = be(std::int32_t(3)) + "\x01\x02\x03";
  const std::string be_vertices = be(1.0f) + be(2.0f) + be(3.0) + "\x04" + be(-1.5f) + be(0.25f) + be(-7.0) + "\xff";
  writeBytes(dir / "be.ply", be_head + be_faces + be_vertices);
  const PointBuffer b = readPointCloud((dir / "be.ply").string());
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(readAsDouble(b.record(1), *b.layout().find("x")), -1.5);
  EXPECT_EQ(readAsDouble(b.record(1), *b.layout().find("y")), 0.25);
  EXPECT_EQ(readAsDouble(b.record(1), *b.layout().find("z")), -7.0);
  EXPECT_EQ(readAsDouble(b.record(1), *b.layout().find("red")), 255.0);
  EXPECT_EQ(readAsDouble(b.record(0), *b.layout().find("red")), 4.0);

  auto check = [&](const std::string &name, const std::string &content, std::vector<std::string> parts) {
    writeBytes(dir / name, content);
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, parts);
  };
  check("be_cut.ply", be_head + be_faces + be_vertices.substr(0, be_vertices.size() - 1), {"truncated"});
  check("be_negative_list.ply", be_head + be(std::int32_t(-3)) + be_vertices + "\x01\x02\x03", {"negative list size"});
  check("be_long_list.ply", be_head + be(std::int32_t(40)) + "\x01\x02\x03" + be_vertices, {"truncated"});
  check("ascii_red_256.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nend_header\n1 2 3 256\n",
        {"'256'", "red"});
  check("red_no_z.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty uchar red\n"
        "end_header\n1 2 3\n",
        {"no x/y/z fields"});
  check("red_twice.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar red\nend_header\n1 2 3 4 5\n",
        {"invalid point layout"});
}

TEST(PcdRoundTrip, KeepsFieldsOffsetsPaddingAndOrganisation) {
  const ScratchDir scratch("io_pcd");
  const fs::path &dir = scratch.path;
  PointBuffer src = makeAllTypesCloud(6 * 5, 11);
  src.setOrganization(6, 5);
  const std::string path = (dir / "org.pcd").string();
  writePcd(path, src);
  const PointBuffer back = readPointCloud(path);
  EXPECT_EQ(back.layout(), src.layout());  // names, offsets, types, counts and point_step (padding as "_")
  EXPECT_EQ(back.width(), 6u);
  EXPECT_EQ(back.height(), 5u);
  for (const PointField &f : src.layout().fields) expectSameValues(src, f, back, *back.layout().find(f.name));
}

TEST(PcdRoundTrip, HeaderLongerThanAMemoryPage) {
  // PCL's own binary writer assumes the header fits in one page; hundreds of fields make it longer.
  const ScratchDir scratch("io_pcd_wide");
  PointLayout layout;
  for (const char *axis : {"x", "y", "z"}) layout.append(axis, FieldType::Float32);
  for (int i = 0; i < 600; ++i) layout.append("feature_histogram_bin_" + std::to_string(i), FieldType::UInt8);
  PointBuffer src(layout, 4);
  for (std::size_t p = 0; p < 4; ++p)
    for (const auto &f : layout.fields) writeFromDouble(src.record(p), f, double((p * 7 + f.offset) % 251));
  const std::string path = (scratch.path / "wide.pcd").string();
  writePcd(path, src);
  const PointBuffer back = readPointCloud(path);
  EXPECT_EQ(back.layout(), layout);
  EXPECT_EQ(back.bytes(), src.bytes());
  EXPECT_EQ(readBytes(path).size(), readBytes(path).find("DATA binary\n") + 12 + src.bytes().size());
}

TEST(PcdRoundTrip, FieldsOutOfOffsetOrderAndEmptyCloud) {
  const ScratchDir scratch("io_pcd_order");
  const fs::path &dir = scratch.path;
  PointLayout layout;
  layout.fields = {{"z", 8, FieldType::Float32, 1},
                   {"ring", 12, FieldType::UInt16, 1},
                   {"x", 0, FieldType::Float32, 1},
                   {"y", 4, FieldType::Float32, 1}};
  layout.point_step = 16;
  PointBuffer src(layout, 3);
  for (std::size_t i = 0; i < 3; ++i)
    for (const auto &f : layout.fields) writeFromDouble(src.record(i), f, double(i * 10 + f.offset));
  const std::string path = (dir / "order.pcd").string();
  writePcd(path, src);
  const PointBuffer back = readPointCloud(path);
  for (const PointField &f : layout.fields) {
    const PointField *g = back.layout().find(f.name);
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(*g, f);
    expectSameValues(src, f, back, *g);
  }
  EXPECT_EQ(back.layout().point_step, 16u);

  const std::string empty_path = (dir / "empty.pcd").string();
  writePcd(empty_path, PointBuffer(layout, 0));
  const PointBuffer empty = readPointCloud(empty_path);
  EXPECT_EQ(empty.size(), 0u);
  EXPECT_NE(empty.layout().find("ring"), nullptr);
}

// A PointBuffer may give two fields the same bytes (a uint32 view of x); PCL cannot, so toPclCloud2 repacks each
// field into its own bytes: the PCD keeps every field with its value and type, x's bits in the alias.
TEST(PcdRoundTrip, AliasingFieldsAreRepackedWithTheirValues) {
  const ScratchDir scratch("io_pcd_alias");
  PointLayout layout;
  layout.fields = {{"x", 0, FieldType::Float32, 1},
                   {"y", 4, FieldType::Float32, 1},
                   {"z", 8, FieldType::Float32, 1},
                   {"x_bits", 0, FieldType::UInt32, 1}};
  layout.point_step = 12;
  PointBuffer src(layout, 3);
  for (std::size_t i = 0; i < 3; ++i)
    for (int a = 0; a < 3; ++a) writeFromDouble(src.record(i), layout.fields[a], 1.5 * double(i) + a);
  const std::string path = (scratch.path / "alias.pcd").string();
  writePcd(path, src);
  const PointBuffer back = readPointCloud(path);
  EXPECT_EQ(back.layout().point_step, 16u);
  for (const PointField &f : layout.fields) {
    const PointField *g = back.layout().find(f.name);
    ASSERT_NE(g, nullptr) << f.name;
    EXPECT_EQ(g->type, f.type);
    expectSameValues(src, f, back, *g);
  }
}

TEST(PcdRead, AsciiWithNanAndBinaryCompressed) {
  const ScratchDir scratch("io_pcd_formats");
  const fs::path &dir = scratch.path;
  const std::string ascii = (dir / "a.pcd").string();
  writeBytes(ascii, pcdHeader("x y z ring", "4 4 4 2", "F F F U", "1 1 1 1", "2", "1", "2", "ascii") +
                        "1.5 -2 3e2 7\r\n\nnan nan nan 65535\n");
  const PointBuffer a = readPointCloud(ascii);
  ASSERT_EQ(a.size(), 2u);
  const PointField &x = *a.layout().find("x");
  const PointField &ring = *a.layout().find("ring");
  EXPECT_EQ(readAsDouble(a.record(0), x), 1.5);
  EXPECT_EQ(readAsDouble(a.record(0), *a.layout().find("z")), 300.0);
  EXPECT_EQ(readAsDouble(a.record(0), ring), 7.0);
  EXPECT_TRUE(std::isnan(readAsDouble(a.record(1), x)));
  EXPECT_EQ(readAsDouble(a.record(1), ring), 65535.0);

  // binary_compressed stores each field's column contiguously.
  const std::size_t n = 5;
  std::vector<float> xs, ys, zs;
  for (std::size_t i = 0; i < n; ++i) {
    xs.push_back(float(i));
    ys.push_back(float(i) + 0.25f);
    zs.push_back(-float(i));
  }
  const std::string raw = bytesOf(xs) + bytesOf(ys) + bytesOf(zs);
  const std::string packed = lzfLiterals(raw);
  const std::string compressed = (dir / "c.pcd").string();
  writeBytes(compressed, xyzPcdHeader(n, "binary_compressed") + u32le(std::uint32_t(packed.size())) +
                             u32le(std::uint32_t(raw.size())) + packed);
  const PointBuffer c = readPointCloud(compressed);
  ASSERT_EQ(c.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("x")), double(xs[i]));
    EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("y")), double(ys[i]));
    EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("z")), double(zs[i]));
  }
}

TEST(KittiBin, RoundTripConvertsAnyTypesAndDefaultsIntensity) {
  const ScratchDir scratch("io_kitti");
  const fs::path &dir = scratch.path;
  PointLayout layout;
  layout.append("intensity", FieldType::UInt16);
  layout.append("z", FieldType::Float64);
  layout.append("x", FieldType::Int32);
  layout.append("y", FieldType::Float32);
  PointBuffer src(layout, 100);
  for (std::size_t i = 0; i < 100; ++i) {
    writeFromDouble(src.record(i), *layout.find("x"), double(i) - 50);
    writeFromDouble(src.record(i), *layout.find("y"), 0.5 * double(i));
    writeFromDouble(src.record(i), *layout.find("z"), 1.25 * double(i));
    writeFromDouble(src.record(i), *layout.find("intensity"), double(i * 3));
  }
  src.setOrganization(10, 10);
  const std::string path = (dir / "scan.bin").string();
  writeKittiBin(path, src);
  EXPECT_EQ(fs::file_size(path), 100u * 16u);
  const PointBuffer back = readPointCloud(path);
  ASSERT_EQ(back.size(), 100u);
  EXPECT_EQ(back.layout().point_step, 16u);
  for (const char *name : {"x", "y", "z", "intensity"}) {
    const PointField *g = back.layout().find(name);
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(g->type, FieldType::Float32);
    expectSameValues(src, *src.layout().find(name), back, *g);
  }

  PointLayout xyz = xyzLayout();
  PointBuffer plain(xyz, 2);
  writeFromDouble(plain.record(1), xyz.fields[0], 4.0);
  const std::string plain_path = (dir / "plain.BIN").string();
  writeKittiBin(plain_path, plain);
  const PointBuffer plain_back = readKittiBin(plain_path);
  EXPECT_EQ(readAsDouble(plain_back.record(1), *plain_back.layout().find("x")), 4.0);
  EXPECT_EQ(readAsDouble(plain_back.record(1), *plain_back.layout().find("intensity")), 0.0);

  PointLayout no_xyz;
  no_xyz.append("x", FieldType::Float32);
  expectError([&] { writeKittiBin((dir / "bad.bin").string(), PointBuffer(no_xyz, 1)); }, "bad.bin", {"x/y/z"});
}

TEST(WritePointCloud, DispatchesOnExtension) {
  const ScratchDir scratch("io_dispatch");
  const fs::path &dir = scratch.path;
  const PointBuffer src = makeAllTypesCloud(9, 3);
  for (const char *name : {"a.pcd", "a.ply", "a.bin"}) {
    const std::string path = (dir / name).string();
    writePointCloud(path, src);
    EXPECT_EQ(readPointCloud(path).size(), 9u) << name;
  }
  expectError([&] { writePointCloud((dir / "a.las").string(), src); }, "a.las", {"unsupported extension"});
  expectError([&] { writePcd((dir / "no_such_dir" / "a.pcd").string(), src); }, "a.pcd", {"directory"});
  expectError([&] { writePly((dir / "no_such_dir" / "a.ply").string(), src); }, "a.ply",
              {"cannot create a temporary file beside it"});
}

TEST(Poses, RoundTripIsBitExact) {
  const ScratchDir scratch("io_poses");
  const fs::path &dir = scratch.path;
  std::mt19937_64 rng(42);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Eigen::Isometry3d> poses;
  poses.push_back(Eigen::Isometry3d::Identity());
  for (int i = 0; i < 200; ++i) {
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
    p.translation() = Eigen::Vector3d(g(rng) * 1e3, g(rng) * 1e-9, std::ldexp(g(rng), 40));
    poses.push_back(p);
  }
  const std::string path = (dir / "poses.txt").string();
  writeKittiPoses(path, poses);
  const auto back = readKittiPoses(path);
  ASSERT_EQ(back.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i)
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        ASSERT_TRUE(sameBits(back[i].matrix()(r, c), poses[i].matrix()(r, c)))
            << "pose " << i << " (" << r << "," << c << ")";
}

TEST(Poses, KittiPrecisionIsAcceptedAndMadeExactlyOrthonormal) {
  const ScratchDir scratch("io_poses_kitti");
  const fs::path &dir = scratch.path;
  const std::string path = (dir / "00.txt").string();
  // Two lines in the style of KITTI odometry poses (7 significant digits), a blank line between them.
  writeBytes(path,
             "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 "
             "3.330669e-16 2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16\n"
             "  \n"
             "9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 -1.154865e-03 "
             "-2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01\r\n");
  const auto poses = readKittiPoses(path);
  ASSERT_EQ(poses.size(), 2u);
  for (const auto &p : poses) {
    const Eigen::Matrix3d r = p.linear();
    EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-14);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-14);
  }
  EXPECT_DOUBLE_EQ(poses[1].translation().z(), 8.586941e-01);
  EXPECT_NEAR(poses[1].linear()(0, 1), 5.272628e-04, 1e-6);
}

TEST(ReadPointCloud, ConcurrentReadsOfEveryFormat) {
  const ScratchDir scratch("io_threads");
  const PointBuffer src = makeAllTypesCloud(500, 17);
  std::vector<std::string> paths;
  for (const char *name : {"a.pcd", "a.ply", "a.bin"}) {
    paths.push_back((scratch.path / name).string());
    writePointCloud(paths.back(), src);
  }
  paths.push_back((scratch.path / "missing.pcd").string());  // failing reads run concurrently too
  std::vector<std::thread> threads;
  std::atomic<int> good{0}, failed{0};
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int k = 0; k < 20; ++k) {
        try {
          good += readPointCloud(paths[(t + k) % paths.size()]).size() == 500;
        } catch (const std::runtime_error &) {
          ++failed;
        }
      }
    });
  for (auto &th : threads) th.join();
  EXPECT_EQ(good.load(), 60);
  EXPECT_EQ(failed.load(), 20);
}

// ---------------------------------------------------------------------------------------------------------------------
// Real frames

TEST(RealFrames, EveryFileReadsWithItsPointCountAndFields) {
  HPDS_REQUIRE_SHARED_DATA();
  const fs::path dir = test::sharedLidarDir();
  struct Expect {
    const char *file;
    std::size_t points;
    std::vector<std::string> fields;
  };
  const std::vector<std::string> xyz = {"x", "y", "z"};
  const std::vector<Expect> expected = {
      {"hdl32_a.pcd", 69088, {"x", "y", "z", "intensity"}},
      {"hdl32_b.pcd", 69792, {"x", "y", "z", "intensity"}},
      {"velodyne_vlp16.pcd",
       14831,
       {"x", "y", "z", "intensity", "return_type", "channel", "azimuth", "elevation", "distance", "time_stamp"}},
      {"velodyne_vlp32.pcd", 26216, xyz},
      {"velodyne_vls128.pcd", 208680, xyz},
      {"hesai_xt32.pcd", 63021, xyz},
      {"hesai_64.pcd", 93591, xyz},
      {"hesai_ot128.pcd", 72240, xyz},
  };
  for (const auto &e : expected) {
    SCOPED_TRACE(e.file);
    const PointBuffer cloud = readPointCloud((dir / e.file).string());
    EXPECT_EQ(cloud.size(), e.points);
    EXPECT_EQ(cloud.width(), e.points);
    EXPECT_EQ(cloud.height(), 1u);
    ASSERT_EQ(cloud.layout().fields.size(), e.fields.size());
    for (std::size_t i = 0; i < e.fields.size(); ++i) EXPECT_EQ(cloud.layout().fields[i].name, e.fields[i]);
    std::size_t finite = 0;
    const PointField &x = *cloud.layout().find("x");
    for (std::size_t i = 0; i < cloud.size(); ++i) finite += std::isfinite(readAsDouble(cloud.record(i), x));
    EXPECT_GT(finite, cloud.size() / 2);
  }
}

TEST(RealFrames, Hdl32HasItsNoReturnPointsAtTheOrigin) {
  HPDS_REQUIRE_SHARED_DATA();
  const PointBuffer cloud = readPointCloud((test::sharedLidarDir() / "hdl32_a.pcd").string());
  ASSERT_EQ(cloud.size(), 69088u);
  const PointField &x = *cloud.layout().find("x");
  const PointField &y = *cloud.layout().find("y");
  const PointField &z = *cloud.layout().find("z");
  std::size_t at_origin = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::uint8_t *r = cloud.record(i);
    at_origin += readAsDouble(r, x) == 0.0 && readAsDouble(r, y) == 0.0 && readAsDouble(r, z) == 0.0;
  }
  EXPECT_EQ(at_origin, 5032u);
}

TEST(RealFrames, Vlp16KeepsItsTypedFieldsAndRoundTripsThroughEveryFormat) {
  HPDS_REQUIRE_SHARED_DATA();
  const PointBuffer cloud = readPointCloud((test::sharedLidarDir() / "velodyne_vlp16.pcd").string());
  ASSERT_EQ(cloud.size(), 14831u);
  const PointLayout &l = cloud.layout();
  EXPECT_EQ(l.point_step, 32u);
  EXPECT_EQ(l.find("intensity")->type, FieldType::UInt8);
  EXPECT_EQ(l.find("return_type")->type, FieldType::UInt8);
  EXPECT_EQ(l.find("time_stamp")->type, FieldType::UInt32);
  const PointField &channel = *l.find("channel");
  EXPECT_EQ(channel.type, FieldType::UInt16);
  EXPECT_EQ(channel.offset, 14u);
  std::vector<int> seen(16, 0);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const double c = readAsDouble(cloud.record(i), channel);
    ASSERT_GE(c, 0.0);
    ASSERT_LE(c, 15.0);
    seen[static_cast<int>(c)] = 1;
  }
  EXPECT_GE(std::count(seen.begin(), seen.end(), 1), 12);  // a frame need not hit every ring, but most

  const ScratchDir scratch("io_vlp16");
  const fs::path &dir = scratch.path;
  for (const char *name : {"vlp16.pcd", "vlp16.ply"}) {
    SCOPED_TRACE(name);
    const std::string path = (dir / name).string();
    writePointCloud(path, cloud);
    const PointBuffer back = readPointCloud(path);
    ASSERT_EQ(back.size(), cloud.size());
    for (const PointField &f : l.fields) {
      const PointField *g = back.layout().find(f.name);
      ASSERT_NE(g, nullptr) << f.name;
      EXPECT_EQ(g->type, f.type) << f.name;
      expectSameValues(cloud, f, back, *g);
    }
  }
}

// ---------------------------------------------------------------------------------------------------------------------
// Malformed input: always std::runtime_error naming the path, never a crash, hang or huge allocation

TEST(BadInput, MissingEmptyAndUnknownFiles) {
  const ScratchDir scratch("io_bad_basic");
  const fs::path &dir = scratch.path;
  for (const char *name : {"missing.pcd", "missing.ply", "missing.bin"})
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, {"file not found"});
  for (const char *name : {"empty.pcd", "empty.ply", "empty.bin"}) {
    writeBytes(dir / name, "");
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, {"empty"});
  }
  writeBytes(dir / "cloud.xyz", "1 2 3\n");
  expectError([&] { (void)readPointCloud((dir / "cloud.xyz").string()); }, "cloud.xyz", {"unsupported extension"});
  writeBytes(dir / "noext", "1 2 3\n");
  expectError([&] { (void)readPointCloud((dir / "noext").string()); }, "noext", {"unsupported extension"});
  fs::create_directories(dir / "dir.pcd");
  expectError([&] { (void)readPointCloud((dir / "dir.pcd").string()); }, "dir.pcd", {"not a regular file"});
  writeBytes(dir / "odd.bin", std::string(17, '\0'));
  expectError([&] { (void)readPointCloud((dir / "odd.bin").string()); }, "odd.bin", {"17", "multiple of 16"});
}

TEST(BadInput, GarbageBytesNeverCrash) {
  const ScratchDir scratch("io_bad_garbage");
  const fs::path &dir = scratch.path;
  for (std::uint32_t seed = 1; seed <= 12; ++seed) {
    std::mt19937 rng(seed);
    std::string bytes(1 + rng() % 5000, '\0');
    for (char &c : bytes) c = static_cast<char>(rng());
    for (const char *ext : {".pcd", ".ply"}) {
      const std::string name = "garbage" + std::to_string(seed) + ext;
      writeBytes(dir / name, bytes);
      expectError([&] { (void)readPointCloud((dir / name).string()); }, name,
                  {std::string("not a ") + (ext[1] == 'p' && ext[2] == 'c' ? "PCD" : "PLY") + " file"});
    }
    // Garbage behind a valid magic line gets past the first check but must still be refused.
    writeBytes(dir / "magic.ply", "ply\n" + bytes);
    expectError([&] { (void)readPointCloud((dir / "magic.ply").string()); }, "magic.ply");
    writeBytes(dir / "magic.pcd", "# .PCD v0.7\nVERSION 0.7\n" + bytes);
    expectError([&] { (void)readPointCloud((dir / "magic.pcd").string()); }, "magic.pcd");
  }
  writeBytes(dir / "text.pcd", "hello world\n");
  expectError([&] { (void)readPointCloud((dir / "text.pcd").string()); }, "text.pcd", {"not a PCD file"});
  writeBytes(dir / "isply.pcd", "ply\nformat ascii 1.0\n");
  expectError([&] { (void)readPointCloud((dir / "isply.pcd").string()); }, "isply.pcd", {"not a PCD file"});
}

TEST(BadInput, PcdHeaderProblems) {
  const ScratchDir scratch("io_bad_pcd_header");
  const fs::path &dir = scratch.path;
  auto check = [&](const std::string &name, const std::string &content, std::vector<std::string> parts) {
    writeBytes(dir / name, content);
    const auto t0 = std::chrono::steady_clock::now();
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, parts);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0) << name;
  };
  // Header only: the DATA line is there, the body is not.
  check("header_only.pcd", xyzPcdHeader(10, "binary"), {"truncated", "10 points of 12 bytes", "holds 0 bytes"});
  check("header_no_data.pcd", xyzPcdHeader(10, "binary").substr(0, xyzPcdHeader(10, "binary").find("DATA")),
        {"no DATA"});
  check("header_cut.pcd", "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4", {"SIZE"});
  check("truncated_body.pcd", xyzPcdHeader(100, "binary") + xyzBody(99) + "abc",
        {"truncated: header says 100 points of 12 bytes but data holds 1191 bytes"});
  // Absurd sizes must be refused before anything is allocated.
  check("huge_points.pcd",
        pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", "4000000000", "1", "4000000000", "binary") + xyzBody(10),
        {"truncated", "4000000000 points"});
  check("huge_height.pcd", pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", "65536", "65536", "4294967296", "binary"),
        {"2^32"});
  check("huge_count.pcd", pcdHeader("x y z", "4 4 4", "F F F", "1 1 4000000000", "1", "1", "1", "binary"), {"COUNT"});
  check("negative_width.pcd", pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", "-1", "1", "1", "binary"), {"WIDTH"});
  check("wh_mismatch.pcd", pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", "5", "2", "11", "binary") + xyzBody(11),
        {"!= POINTS"});
  check("size_mismatch.pcd", pcdHeader("x y z", "4 4", "F F F", "1 1 1", "1", "1", "1", "binary"), {"SIZE"});
  check("bad_size.pcd", pcdHeader("x y z", "4 4 3", "F F F", "1 1 1", "1", "1", "1", "binary"), {"SIZE"});
  check("int64.pcd",
        pcdHeader("x y z t", "4 4 4 8", "F F F U", "1 1 1 1", "1", "1", "1", "binary") + std::string(20, '\0'),
        {"'t'", "64-bit"});
  check("bad_type.pcd", pcdHeader("x y z", "4 4 4", "F F Q", "1 1 1", "1", "1", "1", "binary"), {"TYPE"});
  check("bad_data.pcd", xyzPcdHeader(1, "zipped") + xyzBody(1), {"DATA"});
  check("no_xyz.pcd", pcdHeader("a b c", "4 4 4", "F F F", "1 1 1", "2", "1", "2", "binary") + xyzBody(2),
        {"no x/y/z fields", "a b c"});
  check("dup_field.pcd", pcdHeader("x y x", "4 4 4", "F F F", "1 1 1", "1", "1", "1", "binary") + xyzBody(1),
        {"twice"});
  check("blank_line.pcd", "# .PCD v0.7\nVERSION 0.7\n  \nFIELDS x y z\n", {"blank"});
  // Binary data that PCL would keep parsing as header keywords.
  check("keyword_body.pcd", xyzPcdHeader(1, "binary") + "POINTS 99999999999\n", {"header keyword"});
}

TEST(BadInput, PcdAsciiAndCompressedBodies) {
  const ScratchDir scratch("io_bad_pcd_body");
  const fs::path &dir = scratch.path;
  auto check = [&](const std::string &name, const std::string &content, std::vector<std::string> parts) {
    writeBytes(dir / name, content);
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, parts);
  };
  check("ascii_word.pcd", xyzPcdHeader(2, "ascii") + "1 2 3\n4 abc 6\n", {"'abc'", "not a number"});
  check("ascii_suffix.pcd", xyzPcdHeader(1, "ascii") + "1 2 3x\n", {"'3x'"});
  check("ascii_short_line.pcd", xyzPcdHeader(2, "ascii") + "1 2 3\n4 5\n", {"2 values, expected 3"});
  check("ascii_long_line.pcd", xyzPcdHeader(1, "ascii") + "1 2 3 4\n", {"4 values, expected 3"});
  check("ascii_few_lines.pcd", xyzPcdHeader(3, "ascii") + "1 2 3\n4 5 6\n", {"truncated", "3 points", "holds 2"});
  check("ascii_blank_line.pcd", xyzPcdHeader(2, "ascii") + "1 2 3\n \n4 5 6\n", {"0 values"});
  // Integer fields take plain integers of their type's range: PCL read "1e2" as 1 on the first line and 100 later
  // (its stream keeps its state), and wrapped values beyond the type.
  const std::string ring = "VERSION 0.7\nFIELDS x y z ring\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\n"
                           "HEIGHT 1\nPOINTS 2\nDATA ascii\n";
  check("ascii_int_exponent.pcd", ring + "1 2 3 1e2\n4 5 6 1e2\n",
        {"line 1", "'1e2' is not an integer in 0..65535, as field 'ring' (TYPE U, SIZE 2) needs"});
  check("ascii_int_decimal.pcd", ring + "1 2 3 7\n4 5 6 1.5\n", {"line 2", "'1.5' is not an integer"});
  check("ascii_int_range.pcd", ring + "1 2 3 70000\n4 5 6 1\n", {"'70000' is not an integer in 0..65535"});
  check("ascii_int_negative.pcd", ring + "1 2 3 -1\n4 5 6 1\n", {"'-1' is not an integer in 0..65535"});
  check("ascii_int_nan.pcd", ring + "1 2 3 nan\n4 5 6 1\n", {"'nan' is not an integer"});
  writeBytes(dir / "ascii_int_ok.pcd", ring + "1 2 3 +65535\n1e2 5 6 100\n");
  const PointBuffer ok = readPointCloud((dir / "ascii_int_ok.pcd").string());
  ASSERT_EQ(ok.size(), 2u);
  const PointField *fr = ok.layout().find("ring"), *fx = ok.layout().find("x");
  EXPECT_EQ(readAsDouble(ok.record(0), *fr), 65535.0);
  EXPECT_EQ(readAsDouble(ok.record(1), *fr), 100.0);
  EXPECT_EQ(readAsDouble(ok.record(1), *fx), 100.0) << "float fields take any number";

  const std::string raw = xyzBody(4);
  const std::string packed = lzfLiterals(raw);
  const std::string head = xyzPcdHeader(4, "binary_compressed");
  check("lzf_no_sizes.pcd", head + "abc", {"truncated", "size prefix"});
  check("lzf_wrong_uncompressed.pcd", head + u32le(std::uint32_t(packed.size())) + u32le(4000000000u) + packed,
        {"uncompressed size 4000000000"});
  check("lzf_wrong_compressed.pcd", head + u32le(4000000000u) + u32le(std::uint32_t(raw.size())) + packed,
        {"truncated", "4000000000"});
  check("lzf_cut.pcd",
        head + u32le(std::uint32_t(packed.size())) + u32le(std::uint32_t(raw.size())) +
            packed.substr(0, packed.size() - 5),
        {"truncated"});
  check("lzf_implausible.pcd", xyzPcdHeader(100000, "binary_compressed") + u32le(1) + u32le(1200000) + "x",
        {"corrupt"});
  // Sizes consistent but the stream itself is not valid LZF: PCL's decoder must report it, not overrun.
  std::string bad_stream(packed.size(), '\xff');
  check("lzf_bad_stream.pcd",
        head + u32le(std::uint32_t(bad_stream.size())) + u32le(std::uint32_t(raw.size())) + bad_stream, {"PCL"});
}

TEST(BadInput, PlyProblems) {
  const ScratchDir scratch("io_bad_ply");
  const fs::path &dir = scratch.path;
  auto check = [&](const std::string &name, const std::string &content, std::vector<std::string> parts) {
    writeBytes(dir / name, content);
    expectError([&] { (void)readPointCloud((dir / name).string()); }, name, parts);
  };
  PointLayout layout = xyzLayout();
  PointBuffer cloud(layout, 50);
  writePly((dir / "good.ply").string(), cloud);
  const std::string good = readBytes(dir / "good.ply");
  const std::string header = good.substr(0, good.find("end_header\n") + 11);
  check("cut.ply", good.substr(0, good.size() - 7),
        {"truncated: header says 50 points of 12 bytes but data holds 593"});
  check("header_only.ply", header, {"truncated", "holds 0 bytes"});
  check("no_end_header.ply", header.substr(0, header.size() - 11), {"no end_header"});
  check("huge_count.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n" +
            std::string(100, '\0'),
        {"truncated", "4000000000 points"});
  check("huge_face.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nelement range_grid 3000000000\nproperty list uchar int vertex_indices\nend_header\n" +
            std::string(12, '\0'),
        {"truncated"});
  check("no_props.ply", "ply\nformat ascii 1.0\nelement range_grid 3000000000\nend_header\n", {"no properties"});
  check("bad_format.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n", {"format"});
  check("bad_type.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n1\n", {"float128"});
  check("vertex_list.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        "property list uchar float w\nend_header\n1 2 3 2 4 5\n",
        {"list"});
  check("obj_info.ply",
        "ply\nformat binary_little_endian 1.0\nobj_info num_cols 100000\nobj_info num_rows 100000\n"
        "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n" +
            std::string(12, '\0'),
        {"num_cols"});
  const std::string xyz_props = "property float x\nproperty float y\nproperty float z\n";
  // fuzz_ply: obj_info after the vertex element still resizes PCL's cloud (num_cols 299999999999 wraps to 3.6e9
  // points: a 36 GB allocation); a size other than the vertex count is refused wherever obj_info stands.
  const std::string four = std::string(48, '\0');
  check("obj_info_after_vertex.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 4\n" + xyz_props + "obj_info num_cols 1000\nend_header\n" +
            four,
        {"num_cols", "1000 x 1", "element vertex has 4"});
  check("obj_info_rows_after_vertex.ply",
        "ply\nformat binary_little_endian 1.0\nobj_info num_cols 2\nelement vertex 4\n" + xyz_props +
            "obj_info num_rows 3\nend_header\n" + four,
        {"4 x 3"});
  check("obj_info_wraps.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 4\n" + xyz_props +
            "obj_info num_cols 299999999999\nend_header\n" + four,
        {"3647256575 x 1"});
  // What PCL leaves alone is fine: a lone num_cols before the vertex (reset to count x 1), a complete pair after it,
  // an obj_info value PCL does not split off (carriage return inside the line).
  for (const std::string &info : {std::string("obj_info num_cols 7\nelement vertex 4\n") + xyz_props,
                                  std::string("element vertex 4\n") + xyz_props + "obj_info num_cols 2\nobj_info num_rows 2\n",
                                  std::string("element vertex 4\n") + xyz_props + "obj_info num_cols\r9\n"}) {
    writeBytes(dir / "obj_ok.ply", "ply\nformat binary_little_endian 1.0\n" + info + "end_header\n" + four);
    const PointBuffer c = readPointCloud((dir / "obj_ok.ply").string());
    EXPECT_EQ(c.size(), 4u) << info;
  }
  {
    // PCL's header parse is quadratic in the properties (fuzz_cloud_conversion: a 24 s PLY round trip).
    std::string many = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n" + xyz_props;
    for (int i = 3; i <= 8192; ++i) many += "property uchar p" + std::to_string(i) + "\n";
    const auto t0 = std::chrono::steady_clock::now();
    check("many_props.ply", many + "end_header\n" + std::string(12 + 8190, '\0'), {"more than 8192 properties"});
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
    // 8192 is still read.
    const std::string at_limit = many.substr(0, many.rfind("property uchar p8192\n"));
    writeBytes(dir / "limit_props.ply", at_limit + "end_header\n" + std::string(12 + 8189, '\0'));
    EXPECT_EQ(readPointCloud((dir / "limit_props.ply").string()).layout().fields.size(), 8192u);
  }
  // Inputs that make PCL's PLY reader abort on an assertion (Debian builds keep them) when not caught beforehand.
  check("indented_obj_info.ply",
        "ply\nformat ascii 1.0\n obj_info num_cols 1\nelement vertex 1\n" + xyz_props + "end_header\n1 2 3\n",
        {"obj_info"});
  // (Incomplete or misordered uchar colour sets, which also made PCL abort, are read by hpds's own reader now:
  // PlyRoundTrip.ColoursPclCannotPackKeepTheirFieldsAndBytes.)
  // PCL applies a camera element's viewport as width x height after sizing the cloud from the vertex count.
  check("camera_viewport.ply",
        "ply\nformat ascii 1.0\nelement camera 1\nproperty int viewportx\nproperty int viewporty\nelement vertex 1\n" +
            xyz_props + "end_header\n100000 100000\n1 2 3\n",
        {"inconsistent cloud", "100000x100000"});
  check("no_xyz.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n",
        {"no x/y/z fields"});
  check("no_vertex.ply",
        "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "3 0 1 2\n",
        {"no x/y/z fields"});
  const std::string ascii_head =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar ring\nend_header\n";
  check("ascii_word.ply", ascii_head + "1 2 3 4\n1 abc 3 4\n", {"'abc'"});
  check("ascii_int_as_float.ply", ascii_head + "1 2 3 4\n1 2 3 4.0\n", {"'4.0'", "ring"});
  check("ascii_out_of_range.ply", ascii_head + "1 2 3 256\n1 2 3 4\n", {"'256'"});
  check("ascii_cut.ply", ascii_head + "1 2 3 4\n1 2", {"truncated"});

  // Complete colour sets are fine: PCL packs them into "rgb".
  writeBytes(dir / "rgb.ply", "ply\nformat ascii 1.0\nelement vertex 1\n" + xyz_props +
                                  "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
                                  "1 2 3 4 5 6\n");
  const PointBuffer rgb = readPointCloud((dir / "rgb.ply").string());
  ASSERT_NE(rgb.layout().find("rgb"), nullptr);
  const double packed = readAsDouble(rgb.record(0), *rgb.layout().find("rgb"));
  std::uint32_t bits = 0;
  const float packed_f = static_cast<float>(packed);
  std::memcpy(&bits, &packed_f, 4);
  EXPECT_EQ(bits, (4u << 16) | (5u << 8) | 6u);

  // A valid ASCII PLY reads, with values, as a sanity check of the validator.
  writeBytes(dir / "ascii.ply", ascii_head + "1 2 3 4\n-1.5 nan 1e3 255\n");
  const PointBuffer a = readPointCloud((dir / "ascii.ply").string());
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(readAsDouble(a.record(1), *a.layout().find("x")), -1.5);
  EXPECT_TRUE(std::isnan(readAsDouble(a.record(1), *a.layout().find("y"))));
  EXPECT_EQ(readAsDouble(a.record(1), *a.layout().find("ring")), 255.0);
}

TEST(BadInput, EveryTruncationAndHeaderMutationIsHandled) {
  const ScratchDir scratch("io_bad_fuzz");
  const fs::path &dir = scratch.path;
  const PointBuffer src = makeAllTypesCloud(20, 5);
  const std::string pcd_path = (dir / "src.pcd").string();
  const std::string ply_path = (dir / "src.ply").string();
  writePcd(pcd_path, src);
  writePly(ply_path, src);
  writeBytes(dir / "ascii_src.pcd", xyzPcdHeader(3, "ascii") + "1 2 3\n4 5 6\n7 8 9\n");
  // A lone colour channel: read by hpds's own PLY reader rather than PCL's.
  PointLayout red_layout = src.layout();
  red_layout.append("red", FieldType::UInt8);
  PointBuffer red(red_layout, src.size());
  for (std::size_t i = 0; i < src.size(); ++i) std::memcpy(red.record(i), src.record(i), src.layout().point_step);
  writePly((dir / "red_src.ply").string(), red);
  for (const std::string &name :
       {std::string("src.pcd"), std::string("src.ply"), std::string("ascii_src.pcd"), std::string("red_src.ply")}) {
    const std::string original = readBytes(dir / name);
    const std::string ext = fs::path(name).extension().string();
    // Every cut through the header and a sample of cuts through the body.
    // An ASCII file cut just before its final newline is still complete.
    const std::size_t end = ext == ".pcd" && name.rfind("ascii", 0) == 0 ? original.size() - 1 : original.size();
    for (std::size_t len = 1; len < end; len += (len < 1200 ? 1 : 97)) {
      SCOPED_TRACE(name + " cut to " + std::to_string(len) + " of " + std::to_string(original.size()) + " bytes");
      const std::string cut = "cut" + ext;
      writeBytes(dir / cut, original.substr(0, len));
      expectError([&] { (void)readPointCloud((dir / cut).string()); }, cut);
    }
    // Random byte mutations inside the header: may read or fail, must never crash.
    const std::size_t header_end = std::min<std::size_t>(original.size(), 600);
    std::mt19937 rng(99);
    const char interesting[] = {'0', '9', ' ', '\n', '\r', '-', 'x', '\0', '\xff', '#', '_'};
    for (int trial = 0; trial < 300; ++trial) {
      std::string mutated = original;
      for (int k = 0; k < 1 + trial % 3; ++k)
        mutated[rng() % header_end] = trial % 2 ? interesting[rng() % sizeof interesting] : static_cast<char>(rng());
      const std::string mut = "mut" + ext;
      writeBytes(dir / mut, mutated);
      readSurvives((dir / mut).string());
    }
  }
}

// fuzz_pcd found x with COUNT 2 accepted by the reader (the pipeline sampled its first element and the PLY written
// from it had no x); the reader refuses vector-valued coordinates itself, naming the file and the field.
TEST(BadInput, VectorValuedCoordinatesAreRefusedOnReading) {
  const ScratchDir scratch("io_bad_xyz_count");
  const fs::path &dir = scratch.path;
  writeBytes(dir / "x2.pcd", pcdHeader("x y z", "4 4 4", "F F F", "2 1 1", "1", "1", "1", "ascii") + "1 2 3 4\n");
  expectError([&] { (void)readPointCloud((dir / "x2.pcd").string()); }, "x2.pcd", {"field 'x'", "count 2"});
  writeBytes(dir / "z3.pcd", pcdHeader("x y z i", "4 4 8 1", "F F F U", "1 1 3 1", "2", "1", "2", "binary") +
                                 std::string(2 * (4 + 4 + 24 + 1), '\0'));
  expectError([&] { (void)readPointCloud((dir / "z3.pcd").string()); }, "z3.pcd", {"field 'z'", "count 3"});
  // Other fields may be vectors.
  writeBytes(dir / "i2.pcd", pcdHeader("x y z i", "4 4 4 4", "F F F F", "1 1 1 2", "1", "1", "1", "ascii") +
                                 "1 2 3 4 5\n");
  EXPECT_EQ(readPointCloud((dir / "i2.pcd").string()).layout().find("i")->count, 2u);
}

// A field's count becomes that many PLY properties; fuzz_cloud_conversion found writePly spending hours on a (0-point)
// cloud declaring 4e9. Writers refuse counts beyond what the readers accept (2^20), at once.
TEST(WritePointCloud, FieldCountsBeyondTheReadersLimitAreRefusedAtOnce) {
  const ScratchDir scratch("io_write_count");
  const fs::path &dir = scratch.path;
  auto cloudWithCount = [](std::uint32_t count) {
    PointLayout layout = xyzLayout();
    layout.append("f", FieldType::UInt8, count);
    return PointBuffer(layout, 0);
  };
  for (const char *name : {"huge.ply", "huge.pcd"}) {
    const auto t0 = std::chrono::steady_clock::now();
    expectError([&] { writePointCloud((dir / name).string(), cloudWithCount(4000000000u)); }, name,
                {"field 'f'", "count 4000000000", "1048576"});
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
    expectError([&] { writePointCloud((dir / name).string(), cloudWithCount((1u << 20) + 1)); }, name,
                {"count 1048577"});
    EXPECT_FALSE(fs::exists(dir / name));
  }
  // At the limit PCD writes and reads back; PLY (one property per element) would pass the property limit readers
  // apply, so it is refused too rather than written unreadable; so is a header beyond 1 MiB.
  writePcd((dir / "limit.pcd").string(), cloudWithCount(1u << 20));
  EXPECT_EQ(readPointCloud((dir / "limit.pcd").string()).layout().find("f")->count, 1u << 20);
  expectError([&] { writePly((dir / "limit.ply").string(), cloudWithCount(1u << 20)); }, "limit.ply",
              {"more than 8192 properties"});
  PointLayout long_name = xyzLayout();
  long_name.append(std::string(1 << 20, 'n'), FieldType::UInt8);
  expectError([&] { writePly((dir / "long.ply").string(), PointBuffer(long_name, 1)); }, "long.ply",
              {"header would exceed 1048576 bytes"});
  // Below the header limit a vector field still round-trips through PLY as numbered properties.
  writePly((dir / "ok.ply").string(), cloudWithCount(1000));
  EXPECT_NE(readPointCloud((dir / "ok.ply").string()).layout().find("f_999"), nullptr);
}

// The PLY readers refuse header bytes that are not printable ASCII; the writer refuses such names first (found by
// fuzz_pcd: a PCD field name with a byte 0x8b was written into a PLY header nothing could read back).
TEST(WritePointCloud, PlyRefusesPropertyNamesThatAreNotPrintableAscii) {
  const ScratchDir scratch("io_write_names");
  const fs::path &dir = scratch.path;
  for (const std::string &bad : {std::string("intensit\x8b"), std::string("caf\xc3\xa9"), std::string("a b"),
                                std::string("del\x7f"), std::string("")}) {
    PointLayout layout = xyzLayout();
    layout.append(bad, FieldType::UInt8);
    SCOPED_TRACE(bad);
    expectError([&] { writePly((dir / "n.ply").string(), PointBuffer(layout, 2)); }, "n.ply",
                {"is not a valid PLY property name"});
    EXPECT_FALSE(fs::exists(dir / "n.ply"));
  }
}

// A failed write removes the partial file, but never what a path only leads to: writing through a link to a full
// device fails with "write failed", and both the link and the device are left alone.
TEST(WritePointCloud, FailedWritesRemoveOnlyRegularFiles) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const ScratchDir scratch("io_write_full");
  const fs::path &dir = scratch.path;
  PointLayout layout = xyzLayout();
  const PointBuffer cloud(layout, 100);
  const std::vector<std::pair<std::string, std::function<void(const std::string &)>>> writers = {
      {"a.ply", [&](const std::string &p) { writePly(p, cloud); }},
      {"a.pcd", [&](const std::string &p) { writePcd(p, cloud); }},
      {"a.bin", [&](const std::string &p) { writeKittiBin(p, cloud); }},
      {"poses.txt", [&](const std::string &p) { writeKittiPoses(p, {Eigen::Isometry3d::Identity()}); }},
  };
  for (const auto &[name, write] : writers) {
    SCOPED_TRACE(name);
    const fs::path link = dir / name;
    fs::create_symlink("/dev/full", link);
    expectError([&] { write(link.string()); }, name, {"write failed"});
    EXPECT_TRUE(fs::is_symlink(link));
    EXPECT_TRUE(fs::exists("/dev/full"));
  }
}

TEST(BadInput, PoseFiles) {
  const ScratchDir scratch("io_bad_poses");
  const fs::path &dir = scratch.path;
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  auto check = [&](const std::string &name, const std::string &content, std::vector<std::string> parts) {
    writeBytes(dir / name, content);
    expectError([&] { (void)readKittiPoses((dir / name).string()); }, name, parts);
  };
  check("eleven.txt", good + "1 0 0 0 0 1 0 0 0 0 1\n", {":2:", "expected 12 numbers, found 11"});
  check("thirteen.txt", good + good + "1 0 0 0 0 1 0 0 0 0 1 0 5\n", {":3:", "found 13"});
  check("abc.txt", good + "\n1 0 0 0 0 1 0 abc 0 0 1 0\n", {":3:", "'abc' is not a number"});
  check("comma.txt", "1,0 0 0 0 1 0 0 0 0 1 0\n", {":1:", "'1,0'"});
  check("nan.txt", "1 0 0 nan 0 1 0 0 0 0 1 0\n", {":1:", "non-finite"});
  check("inf.txt", "1 0 0 0 0 1 0 -inf 0 0 1 0\n", {":1:", "non-finite"});
  check("huge.txt", "1 0 0 1e999 0 1 0 0 0 0 1 0\n", {":1:", "out of range"});
  check("scaled.txt", "2 0 0 0 0 2 0 0 0 0 2 0\n", {":1:", "not a rotation"});
  check("reflection.txt", "-1 0 0 0 0 1 0 0 0 0 1 0\n", {":1:", "not a rotation", "det = -1"});
  check("sheared.txt", "1 0.01 0 0 0 1 0 0 0 0 1 0\n", {":1:", "not a rotation"});
  expectError([&] { (void)readKittiPoses((dir / "missing.txt").string()); }, "missing.txt", {"file not found"});

  writeBytes(dir / "empty.txt", "");
  EXPECT_TRUE(readKittiPoses((dir / "empty.txt").string()).empty());

  Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
  bad.translation().x() = std::numeric_limits<double>::quiet_NaN();
  expectError([&] { writeKittiPoses((dir / "out.txt").string(), {bad}); }, "out.txt", {"non-finite"});
  expectError([&] { writeKittiPoses((dir / "no_dir" / "out.txt").string(), {}); }, "out.txt",
              {"cannot create a temporary file beside it"});
}
