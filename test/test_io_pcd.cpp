// PCD files: round trips of fields, offsets, padding, organisation, wide headers and aliasing fields through
// writePcd; ascii and binary_compressed bodies; malformed PCD headers and bodies.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "IoTestSupport.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace fs = std::filesystem;
using namespace hpds;
using hpds::test::ScratchDir;
using hpds::test::bytesOf;
using hpds::test::expectError;
using hpds::test::expectSameValues;
using hpds::test::makeAllTypesCloud;
using hpds::test::pcdHeader;
using hpds::test::readBytes;
using hpds::test::writeBytes;
using hpds::test::xyzPcdHeader;

namespace {

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

// ---------------------------------------------------------------------------------------------------------------------
// Malformed input: always std::runtime_error naming the path, never a crash, hang or huge allocation

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
  // A header that under-states the count: PCL read the declared points and ignored the rest without a word.
  check("binary_extra_points.pcd", xyzPcdHeader(500, "binary") + xyzBody(1000),
        {"binary data holds 6000 bytes (500 points of 12 bytes) beyond the header's POINTS 500", "under-states"});
  check("binary_extra_point.pcd", xyzPcdHeader(2, "binary") + xyzBody(3), {"beyond the header's POINTS 2"});
  // Absurd sizes must be refused before anything is allocated.
  // Less than a point more (a final newline) is no point: read as declared.
  writeBytes(dir / "binary_newline.pcd", xyzPcdHeader(2, "binary") + xyzBody(2) + "\n");
  EXPECT_EQ(readPointCloud((dir / "binary_newline.pcd").string()).size(), 2u);
  writeBytes(dir / "binary_11_bytes.pcd", xyzPcdHeader(2, "binary") + xyzBody(2) + std::string(11, 'x'));
  EXPECT_EQ(readPointCloud((dir / "binary_11_bytes.pcd").string()).size(), 2u);
  // A WIDTH of 0 is named as such (the message used to say that no WIDTH was given).
  check("width_0.pcd", pcdHeader("x y z", "4 4 4", "F F F", "1 1 1", "0", "1", "2", "binary") + xyzBody(2),
        {"WIDTH 0 x HEIGHT 1 != POINTS 2"});
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
        {"no x/y/z fields", "'a' 'b' 'c'"});
  // A control byte inside a name is shown, not left to cut the message short (it read "(fields: x y z", as if z
  // were there).
  check("nul_in_name.pcd",
        pcdHeader(std::string("x y z") + '\0' + "w", "4 4 4", "F F F", "1 1 1", "2", "1", "2", "binary") + xyzBody(2),
        {"no x/y/z fields (fields: 'x' 'y' 'z?w')"});
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
  // A header that under-states the count: PCL read the first POINTS lines and dropped the rest with a warning only.
  check("ascii_extra_lines.pcd", xyzPcdHeader(2, "ascii") + "1 2 3\n4 5 6\n\n7 8 9\n",
        {"line 4", "beyond the header's POINTS 2", "under-states"});
  check("ascii_points_0.pcd", xyzPcdHeader(0, "ascii") + "1 2 3\n", {"line 1", "beyond the header's POINTS 0"});
  writeBytes(dir / "ascii_trailing_blank.pcd", xyzPcdHeader(2, "ascii") + "1 2 3\n4 5 6\n\n \t\r\n");
  EXPECT_EQ(readPointCloud((dir / "ascii_trailing_blank.pcd").string()).size(), 2u) << "blank lines are no points";
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
  // Sizes consistent but the stream itself is not valid LZF (a back reference before the start): named as such, not
  // as PCL's bare "error -1", and no overrun.
  std::string bad_stream(packed.size(), '\xff');
  check("lzf_bad_stream.pcd",
        head + u32le(std::uint32_t(bad_stream.size())) + u32le(std::uint32_t(raw.size())) + bad_stream,
        {"corrupt binary_compressed data", "LZF stream", "does not decode"});
}

// binary_compressed with "_" padding fields: some writers store the padding's columns, others (PCL's header with
// another writer's body) leave them out. PCL decoded the first into shifted garbage (x = -2.7e-153 among the samples
// of a real frame) and copied past its buffer on the second; both read as the same points here.
TEST(PcdRead, CompressedWithPaddingFieldsDecodesEitherLayout) {
  const ScratchDir scratch("io_pcd_padded_compressed");
  const std::size_t n = 7;
  std::vector<float> xs, ys, zs, intensity;
  std::vector<std::uint16_t> ring;
  for (std::size_t i = 0; i < n; ++i) {
    xs.push_back(float(i) + 0.5f);
    ys.push_back(-float(i));
    zs.push_back(float(i * i));
    intensity.push_back(float(100 + i));
    ring.push_back(static_cast<std::uint16_t>(3 * i));
  }
  const std::string pad4(4 * n, '\x5a'), pad6(6 * n, '\xa5');
  const std::string head = pcdHeader("x y z _ intensity ring _", "4 4 4 1 4 2 1", "F F F U F U U", "1 1 1 4 1 1 6",
                                     std::to_string(n), "1", std::to_string(n), "binary_compressed");
  const std::string stored = bytesOf(xs) + bytesOf(ys) + bytesOf(zs) + pad4 + bytesOf(intensity) + bytesOf(ring) + pad6;
  const std::string omitted = bytesOf(xs) + bytesOf(ys) + bytesOf(zs) + bytesOf(intensity) + bytesOf(ring);
  for (const auto &[name, raw] : {std::pair{"stored.pcd", stored}, std::pair{"omitted.pcd", omitted}}) {
    SCOPED_TRACE(name);
    const std::string packed = lzfLiterals(raw);
    const fs::path file = scratch.path / name;
    writeBytes(file, head + u32le(std::uint32_t(packed.size())) + u32le(std::uint32_t(raw.size())) + packed);
    const PointBuffer c = readPointCloud(file.string());
    ASSERT_EQ(c.size(), n);
    EXPECT_EQ(c.layout().point_step, 28u) << "the padding keeps its bytes in the record";
    ASSERT_EQ(c.layout().fields.size(), 5u) << "padding is no field";
    EXPECT_EQ(c.layout().find("intensity")->offset, 16u);
    EXPECT_EQ(c.layout().find("ring")->offset, 20u);
    for (std::size_t i = 0; i < n; ++i) {
      EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("x")), double(xs[i]));
      EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("y")), double(ys[i]));
      EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("z")), double(zs[i]));
      EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("intensity")), double(intensity[i]));
      EXPECT_EQ(readAsDouble(c.record(i), *c.layout().find("ring")), double(ring[i]));
    }
  }
  // Any other size is still refused, and so is a stream that does not decode.
  const std::string packed = lzfLiterals(stored);
  expectError(
      [&] {
        writeBytes(scratch.path / "odd.pcd", head + u32le(std::uint32_t(packed.size())) +
                                                 u32le(std::uint32_t(stored.size() - 2)) + packed);
        (void)readPointCloud((scratch.path / "odd.pcd").string());
      },
      "odd.pcd", {"uncompressed size"});
  const std::string bad(packed.size(), '\xff');
  expectError(
      [&] {
        writeBytes(scratch.path / "bad.pcd",
                   head + u32le(std::uint32_t(bad.size())) + u32le(std::uint32_t(omitted.size())) + bad);
        (void)readPointCloud((scratch.path / "bad.pcd").string());
      },
      "bad.pcd", {"LZF stream", "does not decode"});
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
