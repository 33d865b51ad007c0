// PointCloud2 <-> PointBuffer conversion: every datatype byte for byte, float64 xyz, organised clouds with NaN,
// row padding, and every malformed case refused without touching the output. No ROS master needed.
#include <gtest/gtest.h>

#include <array>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "hpds_node/CloudConversion.hpp"

namespace {

using hpds_node::CloudError;
using sensor_msgs::PointCloud2;
using sensor_msgs::PointField;

PointField field(const std::string &name, std::uint32_t offset, std::uint8_t datatype, std::uint32_t count = 1) {
  PointField f;
  f.name = name;
  f.offset = offset;
  f.datatype = datatype;
  f.count = count;
  return f;
}

std::size_t typeSize(std::uint8_t datatype) {
  return hpds::fieldTypeSize(static_cast<hpds::FieldType>(datatype));
}

// A cloud with x/y/z of `xyz_type` followed by one field of every PointCloud2 datatype and a count-3 field, at
// unaligned offsets so that nothing can work by accident of alignment; bytes filled with a pattern.
PointCloud2 makeCloud(std::uint8_t xyz_type, std::uint32_t width, std::uint32_t height, std::uint32_t row_pad = 0) {
  PointCloud2 msg;
  msg.header.frame_id = "lidar";
  msg.header.stamp.sec = 12;
  msg.header.stamp.nsec = 345;
  std::uint32_t off = 0;
  for (const char *axis : {"x", "y", "z"}) {
    msg.fields.push_back(field(axis, off, xyz_type));
    off += typeSize(xyz_type);
  }
  for (std::uint8_t t = PointField::INT8; t <= PointField::FLOAT64; ++t) {
    off += 1;  // deliberately misaligned
    msg.fields.push_back(field("f" + std::to_string(t), off, t));
    off += typeSize(t);
  }
  msg.fields.push_back(field("triple", off, PointField::UINT16, 3));
  off += 6;
  msg.point_step = off + 3;  // trailing padding inside the record
  msg.width = width;
  msg.height = height;
  msg.row_step = width * msg.point_step + row_pad;
  msg.data.resize(std::size_t(msg.row_step) * height);
  for (std::size_t i = 0; i < msg.data.size(); ++i) msg.data[i] = std::uint8_t(i * 131 + 7);
  // Real, finite coordinates so is_dense is meaningful.
  for (std::uint32_t r = 0; r < height; ++r)
    for (std::uint32_t c = 0; c < width; ++c) {
      std::uint8_t *rec = msg.data.data() + std::size_t(r) * msg.row_step + std::size_t(c) * msg.point_step;
      for (int a = 0; a < 3; ++a) {
        const double v = 0.5 * (r * width + c) + a;
        if (xyz_type == PointField::FLOAT64) {
          std::memcpy(rec + a * 8, &v, 8);
        } else {
          const float f = float(v);
          std::memcpy(rec + a * 4, &f, 4);
        }
      }
    }
  return msg;
}

void expectSameLayout(const PointCloud2 &msg, const hpds::PointBuffer &buf) {
  const hpds::PointLayout &layout = buf.layout();
  ASSERT_EQ(layout.point_step, msg.point_step);
  ASSERT_EQ(layout.fields.size(), msg.fields.size());
  for (std::size_t i = 0; i < msg.fields.size(); ++i) {
    EXPECT_EQ(layout.fields[i].name, msg.fields[i].name);
    EXPECT_EQ(layout.fields[i].offset, msg.fields[i].offset);
    EXPECT_EQ(static_cast<int>(layout.fields[i].type), msg.fields[i].datatype);
    EXPECT_EQ(layout.fields[i].count, msg.fields[i].count);
  }
  EXPECT_EQ(buf.width(), msg.width);
  EXPECT_EQ(buf.height(), msg.height);
}

TEST(CloudConversion, EveryDatatypeKeepsItsBytes) {
  for (std::uint8_t xyz : {PointField::FLOAT32, PointField::FLOAT64}) {
    const PointCloud2 msg = makeCloud(xyz, 17, 1);
    hpds::PointBuffer buf;
    std::string why;
    ASSERT_EQ(hpds_node::fromRosCloud(msg, buf, &why), CloudError::None) << why;
    expectSameLayout(msg, buf);
    ASSERT_EQ(buf.bytes(), msg.data);

    PointCloud2 back;
    hpds_node::toRosCloud(buf, msg.header, back);
    EXPECT_EQ(back.header.frame_id, "lidar");
    EXPECT_EQ(back.header.stamp, msg.header.stamp);
    EXPECT_EQ(back.fields, msg.fields);
    EXPECT_EQ(back.point_step, msg.point_step);
    EXPECT_EQ(back.row_step, msg.row_step);
    EXPECT_EQ(back.width, msg.width);
    EXPECT_EQ(back.height, msg.height);
    EXPECT_FALSE(back.is_bigendian);
    // Dense in PCL's meaning: every floating-point field of every point finite (f7 and f8 hold arbitrary bytes).
    bool finite = true;
    for (std::size_t i = 0; i < buf.size(); ++i)
      for (const hpds::PointField &f : buf.layout().fields)
        if (f.type == hpds::FieldType::Float32 || f.type == hpds::FieldType::Float64)
          finite = finite && std::isfinite(hpds::readAsDouble(buf.record(i), f));
    EXPECT_EQ(back.is_dense, finite);
    EXPECT_EQ(back.data, msg.data);
  }
}

TEST(CloudConversion, ValuesOfEveryTypeReadBack) {
  PointCloud2 msg = makeCloud(PointField::FLOAT64, 3, 1);
  hpds::PointBuffer buf;
  ASSERT_EQ(hpds_node::fromRosCloud(msg, buf), CloudError::None);
  const hpds::PointField *x = buf.layout().find("x");
  ASSERT_NE(x, nullptr);
  EXPECT_EQ(x->type, hpds::FieldType::Float64);
  EXPECT_DOUBLE_EQ(hpds::readAsDouble(buf.record(2), *x), 1.0);
  // Each typed field reads what its bytes say, through the same memcpy path as the pipeline.
  for (std::uint8_t t = PointField::INT8; t <= PointField::FLOAT64; ++t) {
    const hpds::PointField *f = buf.layout().find("f" + std::to_string(t));
    ASSERT_NE(f, nullptr);
    const std::uint8_t *src = msg.data.data() + msg.point_step + f->offset;
    double expected = 0;
    switch (t) {
      case PointField::INT8: { std::int8_t v; std::memcpy(&v, src, 1); expected = v; break; }
      case PointField::UINT8: { std::uint8_t v; std::memcpy(&v, src, 1); expected = v; break; }
      case PointField::INT16: { std::int16_t v; std::memcpy(&v, src, 2); expected = v; break; }
      case PointField::UINT16: { std::uint16_t v; std::memcpy(&v, src, 2); expected = v; break; }
      case PointField::INT32: { std::int32_t v; std::memcpy(&v, src, 4); expected = v; break; }
      case PointField::UINT32: { std::uint32_t v; std::memcpy(&v, src, 4); expected = v; break; }
      case PointField::FLOAT32: { float v; std::memcpy(&v, src, 4); expected = v; break; }
      case PointField::FLOAT64: { double v; std::memcpy(&v, src, 8); expected = v; break; }
    }
    const double got = hpds::readAsDouble(buf.record(1), *f);
    if (std::isnan(expected)) {
      EXPECT_TRUE(std::isnan(got));
    } else {
      EXPECT_EQ(got, expected) << "datatype " << int(t);
    }
  }
}

TEST(CloudConversion, ANanInAnyFloatFieldMakesTheCloudNotDense) {
  // x y z finite everywhere; one point's normal_x NaN (an invalid normal, as hpds outputs it) or the second element
  // of a float array Inf: not dense, as PCL means it. All finite: dense.
  hpds::PointLayout l;
  for (const char *a : {"x", "y", "z", "normal_x"}) l.append(a, hpds::FieldType::Float32);
  l.append("pair", hpds::FieldType::Float64, 2);
  l.append("ring", hpds::FieldType::UInt16);
  for (int bad = -1; bad < 2; ++bad) {
    hpds::PointBuffer buf(l, 20);
    for (std::size_t i = 0; i < buf.size(); ++i)
      for (std::size_t f = 0; f < 4; ++f) hpds::writeFromDouble(buf.record(i), l.fields[f], 0.5 * double(i) + double(f));
    for (std::size_t i = 0; i < buf.size(); ++i) {
      const double pair[2] = {1.0, 2.0};
      std::memcpy(buf.record(i) + l.find("pair")->offset, pair, sizeof pair);
    }
    if (bad == 0) hpds::writeFromDouble(buf.record(7), *l.find("normal_x"), std::numeric_limits<double>::quiet_NaN());
    if (bad == 1) {
      const double inf = std::numeric_limits<double>::infinity();
      std::memcpy(buf.record(13) + l.find("pair")->offset + 8, &inf, sizeof inf);
    }
    PointCloud2 back;
    hpds_node::toRosCloud(buf, std_msgs::Header(), back);
    EXPECT_EQ(back.is_dense, bad < 0) << "case " << bad;
  }
}

TEST(CloudConversion, OrganizedWithNanKeepsShapeAndNan) {
  PointCloud2 msg = makeCloud(PointField::FLOAT32, 8, 4);
  msg.is_dense = false;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i : {std::size_t(0), std::size_t(9), std::size_t(31)})
    for (int a = 0; a < 3; ++a) std::memcpy(msg.data.data() + i * msg.point_step + 4 * a, &nan, 4);
  hpds::PointBuffer buf;
  ASSERT_EQ(hpds_node::fromRosCloud(msg, buf), CloudError::None);
  expectSameLayout(msg, buf);
  EXPECT_EQ(buf.size(), 32u);
  EXPECT_EQ(buf.bytes(), msg.data);
  EXPECT_TRUE(std::isnan(hpds::readAsDouble(buf.record(9), *buf.layout().find("y"))));
  PointCloud2 back;
  hpds_node::toRosCloud(buf, msg.header, back);
  EXPECT_FALSE(back.is_dense);
  EXPECT_EQ(back.height, 4u);
  EXPECT_EQ(back.width, 8u);
}

TEST(CloudConversion, RowPaddingIsRemoved) {
  const PointCloud2 msg = makeCloud(PointField::FLOAT32, 5, 3, /*row_pad=*/11);
  hpds::PointBuffer buf;
  ASSERT_EQ(hpds_node::fromRosCloud(msg, buf), CloudError::None);
  ASSERT_EQ(buf.size(), 15u);
  for (std::uint32_t r = 0; r < 3; ++r)
    for (std::uint32_t c = 0; c < 5; ++c)
      EXPECT_EQ(0, std::memcmp(buf.record(r * 5 + c),
                               msg.data.data() + std::size_t(r) * msg.row_step + std::size_t(c) * msg.point_step,
                               msg.point_step));
}

TEST(CloudConversion, PclPaddingFieldsAreLeftOut) {
  PointCloud2 msg = makeCloud(PointField::FLOAT32, 2, 1);
  msg.fields.push_back(field("_", 12, PointField::UINT8, 1));
  msg.fields.push_back(field("_", 13, PointField::UINT8, 1));
  hpds::PointBuffer buf;
  ASSERT_EQ(hpds_node::fromRosCloud(msg, buf), CloudError::None);
  EXPECT_EQ(buf.layout().find("_"), nullptr);
  EXPECT_EQ(buf.layout().fields.size(), msg.fields.size() - 2);
  EXPECT_EQ(buf.bytes(), msg.data);
  // A nameless field is padding too: no output field named ''.
  PointCloud2 nameless = makeCloud(PointField::FLOAT32, 2, 1);
  nameless.fields.push_back(field("", 12, PointField::UINT8, 1));
  ASSERT_EQ(hpds_node::fromRosCloud(nameless, buf), CloudError::None);
  EXPECT_EQ(buf.layout().find(""), nullptr);
  EXPECT_EQ(buf.layout().fields.size(), nameless.fields.size() - 1);
}

TEST(CloudConversion, ZeroSizeCloudIsEmptyNotAnError) {
  for (std::uint32_t w : {0u, 5u}) {
    PointCloud2 msg = makeCloud(PointField::FLOAT32, w, 0);
    if (w == 0) msg.height = 1;
    msg.data.clear();
    msg.row_step = w * msg.point_step;
    if (w == 5) msg.height = 0;
    hpds::PointBuffer buf;
    ASSERT_EQ(hpds_node::fromRosCloud(msg, buf), CloudError::None);
    EXPECT_TRUE(buf.empty());
  }
  // No fields at all and no points (a default-constructed message, or one with only width or height set): an
  // empty x y z cloud, whatever point_step and row_step say; with points it is still a cloud without x.
  for (const auto &[w, h, step, row] : {std::array<std::uint32_t, 4>{0, 0, 0, 0}, {5, 0, 7, 40}, {0, 3, 0, 0}}) {
    PointCloud2 msg;
    msg.width = w;
    msg.height = h;
    msg.point_step = step;
    msg.row_step = row;
    hpds::PointBuffer buf;
    ASSERT_EQ(hpds_node::fromRosCloud(msg, buf), CloudError::None) << w << " x " << h;
    EXPECT_TRUE(buf.empty());
    for (const char *axis : {"x", "y", "z"}) EXPECT_NE(buf.layout().find(axis), nullptr) << axis;
    EXPECT_NO_THROW(buf.layout().validate());
  }
  PointCloud2 points_without_fields;
  points_without_fields.width = points_without_fields.height = 1;
  points_without_fields.point_step = points_without_fields.row_step = 4;
  points_without_fields.data.resize(4);
  hpds::PointBuffer untouched;
  EXPECT_EQ(hpds_node::fromRosCloud(points_without_fields, untouched), CloudError::MissingXyz);
}

struct MalformedCase {
  const char *name;
  CloudError expected;
  void (*mutate)(PointCloud2 &);
};

const MalformedCase kMalformed[] = {
    {"big endian", CloudError::BigEndian, [](PointCloud2 &m) { m.is_bigendian = true; }},
    {"datatype 0", CloudError::BadDatatype, [](PointCloud2 &m) { m.fields[4].datatype = 0; }},
    {"datatype 9", CloudError::BadDatatype, [](PointCloud2 &m) { m.fields[0].datatype = 9; }},
    {"count 0", CloudError::BadCount, [](PointCloud2 &m) { m.fields[5].count = 0; }},
    {"field beyond point_step", CloudError::FieldOutsidePoint,
     [](PointCloud2 &m) { m.fields.back().offset = m.point_step - 1; }},
    {"huge offset", CloudError::FieldOutsidePoint, [](PointCloud2 &m) { m.fields[1].offset = 0xFFFFFFFFu; }},
    {"huge count", CloudError::BadCount, [](PointCloud2 &m) { m.fields[6].count = 0xFFFFFFFFu; }},
    {"count 2^20 + 1", CloudError::BadCount, [](PointCloud2 &m) { m.fields[6].count = hpds::kMaxFieldCount + 1; }},
    // No points, so every size matches, yet the fields' sizes would wrap a 32-bit output point_step.
    {"empty cloud, huge count inside a huge point_step", CloudError::BadCount,
     [](PointCloud2 &m) {
       m.fields.back().count = 0xFFFFFFE4u;
       m.point_step = 0xFFFFFFF0u;
       m.width = 0;
       m.row_step = 0;
       m.data.clear();
     }},
    {"point_step 0", CloudError::FieldOutsidePoint, [](PointCloud2 &m) { m.point_step = 0; }},
    {"duplicate name", CloudError::DuplicateField, [](PointCloud2 &m) { m.fields[4].name = "x"; }},
    {"no z", CloudError::MissingXyz, [](PointCloud2 &m) { m.fields[2].name = "w"; }},
    {"no fields", CloudError::MissingXyz, [](PointCloud2 &m) { m.fields.clear(); }},
    {"x count 2", CloudError::BadXyz, [](PointCloud2 &m) { m.fields[0].count = 2; }},
    {"x and y at one offset", CloudError::OverlappingXyz, [](PointCloud2 &m) { m.fields[1].offset = 0; }},
    {"y starting inside x", CloudError::OverlappingXyz, [](PointCloud2 &m) { m.fields[1].offset = 2; }},
    {"z starting inside y", CloudError::OverlappingXyz, [](PointCloud2 &m) { m.fields[2].offset = 6; }},
    {"row_step too small", CloudError::BadRowStep, [](PointCloud2 &m) { m.row_step -= 1; }},
    {"truncated data", CloudError::DataSize, [](PointCloud2 &m) { m.data.resize(m.data.size() - 1); }},
    {"trailing data", CloudError::DataSize, [](PointCloud2 &m) { m.data.push_back(0); }},
    {"height too big", CloudError::DataSize, [](PointCloud2 &m) { m.height += 1; }},
    {"wrapping sizes", CloudError::DataSize,
     [](PointCloud2 &m) {
       // 2^32 * point_step rows would wrap 32- or 64-bit products back to a small number.
       m.width = 1;
       m.height = 0x80000000u;
       m.row_step = m.point_step * 2;
     }},
    {"wrapping row", CloudError::BadRowStep,
     [](PointCloud2 &m) {
       m.width = 0xFFFFFFFFu;
       m.row_step = 0xFFFFFFFFu;
     }},
};

TEST(CloudConversion, MalformedMessagesAreRefusedAndOutputUntouched) {
  for (const MalformedCase &c : kMalformed) {
    PointCloud2 msg = makeCloud(PointField::FLOAT32, 6, 2);
    c.mutate(msg);
    hpds::PointLayout sentinel_layout;
    sentinel_layout.append("sentinel", hpds::FieldType::UInt8);
    hpds::PointBuffer buf(sentinel_layout, 3);
    std::string why;
    EXPECT_EQ(hpds_node::fromRosCloud(msg, buf, &why), c.expected) << c.name << ": " << why;
    EXPECT_EQ(hpds_node::validateCloud(msg), c.expected) << c.name;
    EXPECT_FALSE(why.empty()) << c.name;
    EXPECT_EQ(buf.size(), 3u) << c.name;
    EXPECT_NE(buf.layout().find("sentinel"), nullptr) << c.name;
    EXPECT_STRNE(hpds_node::toString(c.expected), "unknown");
  }
}

// Other overlaps are a cloud's own business (PCL's rgb inside rgba, a driver's packed flags, a view of x's bits):
// taken as they are.
TEST(CloudConversion, OverlapsOtherThanAmongXyzAreKept) {
  for (const auto &[first, second] : {std::pair<std::size_t, std::size_t>{3, 4}, {0, 5}, {2, 3}}) {
    PointCloud2 msg = makeCloud(PointField::FLOAT32, 6, 2);
    msg.fields[second].offset = msg.fields[first].offset;
    hpds::PointBuffer buf;
    std::string why;
    ASSERT_EQ(hpds_node::fromRosCloud(msg, buf, &why), CloudError::None) << why;
    EXPECT_EQ(buf.layout().find(msg.fields[second].name)->offset, msg.fields[first].offset);
    EXPECT_EQ(hpds::xyzOverlap(buf.layout()), "");
  }
}

// Random header mutations: every outcome is either a refusal or a buffer consistent with the message.
TEST(CloudConversion, FuzzedHeadersNeverCrash) {
  std::mt19937 rng(42);
  const PointCloud2 base = makeCloud(PointField::FLOAT32, 9, 3);
  std::uniform_int_distribution<std::uint32_t> any;
  int accepted = 0;
  for (int iter = 0; iter < 20000; ++iter) {
    PointCloud2 msg = base;
    const int edits = 1 + int(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      PointField &f = msg.fields[rng() % msg.fields.size()];
      switch (rng() % 9) {
        case 0: f.datatype = std::uint8_t(rng()); break;
        case 1: f.offset = rng() % 2 ? any(rng) : rng() % 64; break;
        case 2: f.count = rng() % 2 ? any(rng) : rng() % 4; break;
        case 3: msg.point_step = rng() % 2 ? any(rng) : rng() % 80; break;
        case 4: msg.row_step = rng() % 2 ? any(rng) : msg.width * msg.point_step + rng() % 8; break;
        case 5: msg.width = rng() % 2 ? any(rng) : rng() % 16; break;
        case 6: msg.height = rng() % 2 ? any(rng) : rng() % 6; break;
        case 7: msg.data.resize(rng() % (base.data.size() + 64)); break;
        case 8: msg.fields.erase(msg.fields.begin() + rng() % msg.fields.size()); if (msg.fields.empty()) msg.fields.push_back(base.fields[0]); break;
      }
    }
    hpds::PointBuffer buf;
    if (hpds_node::fromRosCloud(msg, buf) == CloudError::None) {
      ++accepted;
      ASSERT_EQ(buf.size(), std::size_t(msg.width) * msg.height);
      ASSERT_NO_THROW(buf.layout().validate());
    }
  }
  EXPECT_GT(accepted, 0);
}

}  // namespace
