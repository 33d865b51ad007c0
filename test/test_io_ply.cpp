// PLY files: round trips of every datatype, organisation and colour arrangement through writePly and the readers
// (PCL's and hpds's own vertex reader), and malformed PLY input.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "IoTestSupport.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace fs = std::filesystem;
using namespace hpds;
using hpds::test::ScratchDir;
using hpds::test::expectError;
using hpds::test::expectSameValues;
using hpds::test::makeAllTypesCloud;
using hpds::test::readBytes;
using hpds::test::sameBits;
using hpds::test::writeBytes;
using hpds::test::xyzLayout;

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

// PCL's packed colour (PointXYZRGB's float rgb, PointXYZRGBA's uint rgba) goes out as uchar red green blue [alpha],
// which viewers show as colours (a float rgb is a meaningless scalar to them), and comes back packed.
TEST(PlyRoundTrip, PackedRgbIsWrittenAsColourChannelsAndReadsBackPacked) {
  const ScratchDir scratch("io_ply_rgb");
  for (const bool alpha : {false, true}) {
    SCOPED_TRACE(alpha ? "rgba" : "rgb");
    const std::string name = alpha ? "rgba" : "rgb";
    PointLayout layout = xyzLayout();
    layout.append(name, alpha ? FieldType::UInt32 : FieldType::Float32);
    layout.append("intensity", FieldType::Float32);
    PointBuffer src(layout, 5);
    for (std::size_t i = 0; i < src.size(); ++i) {
      std::uint8_t *rec = src.record(i);
      for (int a = 0; a < 3; ++a) writeFromDouble(rec, layout.fields[a], double(i) + 0.5 * a);
      const std::uint8_t bgra[4] = {static_cast<std::uint8_t>(10 + i), static_cast<std::uint8_t>(100 + i),
                                    static_cast<std::uint8_t>(250 - i), static_cast<std::uint8_t>(alpha ? 7 * i : 255)};
      std::memcpy(rec + layout.find(name)->offset, bgra, 4);
      writeFromDouble(rec, *layout.find("intensity"), 3.0 * double(i));
    }
    const std::string path = (scratch.path / (name + ".ply")).string();
    writePly(path, src);
    const std::string bytes = readBytes(path);
    const std::string header = bytes.substr(0, bytes.find("end_header"));
    EXPECT_NE(header.find("property uchar red\nproperty uchar green\nproperty uchar blue\n" +
                          std::string(alpha ? "property uchar alpha\n" : "property float intensity\n")),
              std::string::npos)
        << header;
    EXPECT_EQ(header.find("property float rgb"), std::string::npos) << header;
    EXPECT_EQ(header.find("property uint rgba"), std::string::npos) << header;

    const PointBuffer back = readPointCloud(path);
    ASSERT_EQ(back.size(), src.size());
    const PointField *colour = back.layout().find(name);
    ASSERT_NE(colour, nullptr) << "read back as PCL's packed " << name;
    ASSERT_EQ(fieldTypeSize(colour->type), 4u);
    for (std::size_t i = 0; i < src.size(); ++i) {
      const std::uint8_t *want = src.record(i) + layout.find(name)->offset;
      const std::uint8_t *got = back.record(i) + colour->offset;
      EXPECT_EQ(std::memcmp(want, got, alpha ? 4 : 3), 0) << "point " << i;  // rgb's fourth byte is padding
      EXPECT_EQ(readAsDouble(back.record(i), *back.layout().find("intensity")), 3.0 * double(i));
    }
  }
}

// Both packed fields in one cloud would give the channels twice: both are then written as they are, and read back.
TEST(PlyRoundTrip, RgbAndRgbaTogetherStayPacked) {
  const ScratchDir scratch("io_ply_rgb_rgba");
  PointLayout layout = xyzLayout();
  layout.append("rgb", FieldType::Float32);
  layout.append("rgba", FieldType::UInt32);
  PointBuffer src(layout, 4);
  for (std::size_t i = 0; i < src.size(); ++i)
    for (std::size_t k = 0; k < layout.fields.size(); ++k)
      writeFromDouble(src.record(i), layout.fields[k], double(i * 31 + k * 7));
  const std::string path = (scratch.path / "both.ply").string();
  writePly(path, src);
  const std::string bytes = readBytes(path);
  EXPECT_EQ(bytes.find("property uchar red"), std::string::npos);
  const PointBuffer back = readPointCloud(path);
  ASSERT_EQ(back.size(), src.size());
  for (const char *name : {"rgb", "rgba"}) {
    const PointField *g = back.layout().find(name);
    ASSERT_NE(g, nullptr) << name;
    expectSameValues(src, *layout.find(name), back, *g);
  }
}

// The reader of those files walks elements before the vertex (with list properties), handles ascii and big-endian
// data and refuses what does not add up.
// Found: PCL reads nx ny nz as normal_x normal_y normal_z, so a cloud lost its own names and the output's warning
// about input fields it does not carry named a normal_x the file does not have.
TEST(PlyRead, NormalPropertiesKeepTheFilesNames) {
  const ScratchDir scratch("io_ply_nx");
  const fs::path &dir = scratch.path;
  writeBytes(dir / "nx.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                             "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
                             "end_header\n1 2 3 0 0 1\n4 5 6 0.6 0.8 0\n");
  const PointBuffer c = readPointCloud((dir / "nx.ply").string());
  ASSERT_EQ(c.size(), 2u);
  for (const char *name : {"nx", "ny", "nz"}) ASSERT_NE(c.layout().find(name), nullptr) << name;
  for (const char *name : {"normal_x", "normal_y", "normal_z"}) EXPECT_EQ(c.layout().find(name), nullptr) << name;
  EXPECT_EQ(readAsDouble(c.record(1), *c.layout().find("nx")), static_cast<double>(0.6f));
  EXPECT_EQ(readAsDouble(c.record(0), *c.layout().find("nz")), 1.0);
  // A file that names them normal_x ... (hpds's own output) keeps those names.
  writePly((dir / "round.ply").string(), c);
  EXPECT_NE(readPointCloud((dir / "round.ply").string()).layout().find("nx"), nullptr);
  writeBytes(dir / "normal_x.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                   "property float z\nproperty float normal_x\nend_header\n1 2 3 0.5\n");
  EXPECT_NE(readPointCloud((dir / "normal_x.ply").string()).layout().find("normal_x"), nullptr);
}

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
        {"line 8", "property 'red' declared twice"});
}

// ---------------------------------------------------------------------------------------------------------------------
// Malformed input: always std::runtime_error naming the path, never a crash, hang or huge allocation

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
  // A binary header that under-states the vertex count: PCL read the declared vertices and ignored the rest.
  check("binary_extra_vertices.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 2\n" + xyz_props + "end_header\n" + four,
        {"binary data holds 24 bytes (2 vertices of 12 bytes) beyond the header's 2 vertices", "under-states"});
  // Less than a vertex more (a final newline) is no vertex; what follows a list element is not counted.
  writeBytes(dir / "binary_newline.ply",
             "ply\nformat binary_little_endian 1.0\nelement vertex 4\n" + xyz_props + "end_header\n" + four + "\n");
  EXPECT_EQ(readPointCloud((dir / "binary_newline.ply").string()).size(), 4u);
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
  // One value too many on one line and one too few on the next (the same total): named by vertex and line, where
  // only PCL's "error -1" came before.
  check("ascii_shifted.ply", ascii_head + "1 2 3 4 5\n1 2 3\n",
        {"ascii vertex 0", "more values than the header's 4 properties", "'5' is one too many", "'1 2 3 4 5'"});
  check("ascii_short_line.ply", ascii_head + "1 2 3 4\n1 2 3\n",
        {"ascii vertex 1", "its line holds only 3 values for the header's 4 properties", "'1 2 3'"});
  check("ascii_values_over_lines.ply", ascii_head + "1 2\n3 4\n1 2 3 4\n", {"ascii vertex 0", "only 2 values"});
  // A blank line is an element without values (PCL refuses it too); CRLF line ends are fine.
  check("ascii_blank_line.ply", ascii_head + "1 2 3 4\n\n1 2 3 4\n", {"ascii vertex 1", "only 0 values"});
  writeBytes(dir / "crlf.ply", ascii_head + "1 2 3 4\r\n5 6 7 8\r\n");
  const PointBuffer crlf = readPointCloud((dir / "crlf.ply").string());
  ASSERT_EQ(crlf.size(), 2u);
  EXPECT_EQ(readAsDouble(crlf.record(1), *crlf.layout().find("x")), 5.0);
  EXPECT_EQ(readAsDouble(crlf.record(1), *crlf.layout().find("ring")), 8.0);

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

  // A header that under-states the vertex count: PCL read the declared vertices and dropped the rest silently.
  const std::string three = "ply\nformat ascii 1.0\nelement vertex 3\n" + xyz_props + "end_header\n";
  check("extra_vertices.ply", three + "1 1 1\n2 2 2\n3 3 3\n4 4 4\n5 5 5\n",
        {"more than the header's 3 vertices", "line 1 after", "under-states"});
  writeBytes(dir / "trailing_blank.ply", three + "1 1 1\n2 2 2\n3 3 3\n\n \r\n");
  EXPECT_EQ(readPointCloud((dir / "trailing_blank.ply").string()).size(), 3u) << "blank lines are no vertices";
  // What follows the vertices may be faces: not vertices, and not refused.
  writeBytes(dir / "faces_after.ply", "ply\nformat ascii 1.0\nelement vertex 3\n" + xyz_props +
                                          "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                          "1 1 1\n2 2 2\n3 3 3\n3 0 1 2\n");
  EXPECT_EQ(readPointCloud((dir / "faces_after.ply").string()).size(), 3u);
  // A property named twice: PCL said only "error -1".
  check("duplicate_property.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\n" + xyz_props +
            "property float intensity\nproperty float intensity\nend_header\n1 2 3 4 5\n",
        {"line 8", "property 'intensity' declared twice in element 'vertex'"});
  check("duplicate_x.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\n" + xyz_props + "property float x\nend_header\n" +
            std::string(16, '\0'),
        {"property 'x' declared twice"});
}

// ---------------------------------------------------------------------------------------------------------------------
// Writers refuse what no reader could read back, and failed writes leave nothing behind

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
