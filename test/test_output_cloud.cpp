// The output cloud's layout: x y z first, every field at a multiple of its element size, point_step a multiple of 4
// (and of the largest element), no field overlapping another, every input field carried byte for byte, for inputs
// of any layout (packed 1-byte fields, odd offsets, float64, arrays, padding).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <set>
#include <vector>

#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/sampling/Hierarchy.hpp"

namespace hpds {
namespace {

// withLayout: the fields by name into another layout (other order, offsets, padding), the organisation kept,
// fields the source lacks zero, and a field of another type refused.
TEST(WithLayout, CopiesFieldsByNameIntoAnotherLayout) {
  PointLayout from;
  from.fields = {PointField{"x", 0}, PointField{"y", 4}, PointField{"z", 8}, PointField{"ring", 16, FieldType::UInt16}};
  from.point_step = 20;
  PointBuffer a(from, 6);
  a.setOrganization(3, 2);
  for (std::size_t i = 0; i < a.size(); ++i) {
    writeFromDouble(a.record(i), *from.find("x"), 1.0 + double(i));
    writeFromDouble(a.record(i), *from.find("z"), -2.0 * double(i));
    writeFromDouble(a.record(i), *from.find("ring"), 7.0 + double(i));
  }
  PointLayout to;
  to.fields = {PointField{"ring", 0, FieldType::UInt16}, PointField{"x", 4}, PointField{"y", 8}, PointField{"z", 12},
               PointField{"t", 16}};
  to.point_step = 20;
  const PointBuffer b = withLayout(a, to);
  ASSERT_EQ(b.size(), a.size());
  EXPECT_EQ(b.width(), 3u);
  EXPECT_EQ(b.height(), 2u);
  for (std::size_t i = 0; i < b.size(); ++i) {
    EXPECT_EQ(readAsDouble(b.record(i), *to.find("x")), 1.0 + double(i));
    EXPECT_EQ(readAsDouble(b.record(i), *to.find("z")), -2.0 * double(i));
    EXPECT_EQ(readAsDouble(b.record(i), *to.find("ring")), 7.0 + double(i));
    EXPECT_EQ(readAsDouble(b.record(i), *to.find("t")), 0.0) << "a field the source lacks";
  }
  PointLayout other = to;
  other.fields[0].type = FieldType::UInt8;
  EXPECT_THROW((void)withLayout(a, other), std::invalid_argument);
}

constexpr FieldType kTypes[] = {FieldType::Int8,   FieldType::UInt8,  FieldType::Int16,   FieldType::UInt16,
                                FieldType::Int32,  FieldType::UInt32, FieldType::Float32, FieldType::Float64};

// Independent check of the alignment rules, byte by byte; x y z first, of type `xyz`.
void expectAligned(const PointLayout &out, FieldType xyz = FieldType::Float32) {
  ASSERT_GE(out.fields.size(), 3u);
  const char *axes[] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(out.fields[a].name, axes[a]);
    EXPECT_EQ(out.fields[a].type, xyz);
    EXPECT_EQ(out.fields[a].offset, static_cast<std::uint32_t>(fieldTypeSize(xyz)) * a);
  }
  EXPECT_EQ(out.point_step % 4, 0u) << "point_step " << out.point_step;
  std::vector<int> owner(out.point_step, -1);
  for (std::size_t i = 0; i < out.fields.size(); ++i) {
    const PointField &f = out.fields[i];
    const std::size_t size = fieldTypeSize(f.type);
    EXPECT_EQ(f.offset % size, 0u) << f.name << " at " << f.offset << " (element size " << size << ")";
    EXPECT_EQ(out.point_step % size, 0u) << "point_step " << out.point_step << " with " << f.name;
    ASSERT_LE(f.offset + f.byteSize(), out.point_step) << f.name;
    for (std::size_t b = f.offset; b < f.offset + f.byteSize(); ++b) {
      EXPECT_EQ(owner[b], -1) << f.name << " overlaps " << (owner[b] >= 0 ? out.fields[owner[b]].name : "");
      owner[b] = static_cast<int>(i);
    }
  }
}

// A packed input layout: x y z (float32 or float64) at random places among random fields at unaligned offsets.
PointLayout randomInputLayout(std::mt19937 &rng) {
  std::vector<PointField> fields;
  const FieldType xyz = rng() % 4 == 0 ? FieldType::Float64 : FieldType::Float32;
  for (const char *axis : {"x", "y", "z"}) fields.push_back(PointField{axis, 0, xyz, 1});
  const int extra = static_cast<int>(rng() % 7);
  for (int i = 0; i < extra; ++i)
    fields.push_back(PointField{"f" + std::to_string(i), 0, kTypes[rng() % 8],
                                static_cast<std::uint32_t>(rng() % 5 == 0 ? 1 + rng() % 3 : 1)});
  if (rng() % 3 == 0) fields.push_back(PointField{"level", 0, FieldType::Float32, 1});  // one of the output's names
  // Names the output writes only with normals or covariances (carried when it does not), and frame (reserved always:
  // `hpds verify` reads it as hpds's scan-frame index).
  if (rng() % 3 == 0) fields.push_back(PointField{"curvature", 0, FieldType::Float64, 1});
  if (rng() % 3 == 0) fields.push_back(PointField{"frame", 0, FieldType::UInt16, 1});
  if (rng() % 3 == 0) fields.push_back(PointField{"cov_xx", 0, FieldType::Float32, 1});
  std::shuffle(fields.begin(), fields.end(), rng);
  PointLayout in;
  in.point_step = rng() % 3;  // an odd start
  for (const PointField &f : fields) {
    in.append(f.name, f.type, f.count);
    in.point_step += rng() % 2;  // unused bytes between fields
  }
  return in;
}

TEST(OutputCloud, LayoutIsAlignedForPackedInputs) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 300; ++trial) {
    const PointLayout in = randomInputLayout(rng);
    ASSERT_NO_THROW(in.validate());
    for (const bool normals : {false, true})
      for (const bool frame : {false, true})
        for (const bool covariances : {false, true})
        for (const XyzType xyz : {XyzType::AsInput, XyzType::Float32, XyzType::Float64}) {
          if (covariances && !normals) continue;  // covariances come with normals
          SCOPED_TRACE("trial " + std::to_string(trial) + (normals ? " normals" : "") + (frame ? " frame" : "") +
                       (covariances ? " covariances" : "") + " xyz " + std::to_string(static_cast<int>(xyz)));
          const PointLayout out = outputLayout(in, normals, frame, covariances, xyz);
          ASSERT_NO_THROW(out.validate());
          // By default x y z keep the input's digits (float64 when its are); a forced type is what was asked for,
          // at the same aligned offsets.
          const bool input_doubles = in.find("x")->type == FieldType::Float64;
          const bool doubles = xyz == XyzType::Float64 || (xyz == XyzType::AsInput && input_doubles);
          expectAligned(out, doubles ? FieldType::Float64 : FieldType::Float32);
          // Every field is there with its type and count: ours, and each input field not replaced by one of ours.
          std::set<std::string> expected = {"x", "y", "z", "level"};
          if (normals) expected.insert({"normal_x", "normal_y", "normal_z", "curvature"});
          if (covariances) expected.insert({"cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"});
          if (frame) expected.insert("frame");
          // The output's own fields replace inputs of those names; so does its reserved frame name.
          std::set<std::string> own = expected;
          own.insert("frame");
          std::vector<std::string> replaced;
          for (const PointField &f : in.fields) {
            if (own.count(f.name)) {
              if (f.name != "x" && f.name != "y" && f.name != "z") replaced.push_back(f.name);
              continue;
            }
            expected.insert(f.name);
            const PointField *g = out.find(f.name);
            ASSERT_NE(g, nullptr) << f.name;
            EXPECT_EQ(g->type, f.type);
            EXPECT_EQ(g->count, f.count);
          }
          std::set<std::string> names;
          for (const PointField &f : out.fields) names.insert(f.name);
          EXPECT_EQ(names, expected);
          EXPECT_EQ(out.find("level")->type, FieldType::UInt8);
          EXPECT_EQ(fieldsNotCarried(in, normals, covariances), replaced);
        }
  }
}

TEST(OutputCloud, PackedOneByteFieldsKeepTheirBytes) {
  // x y z float32 after three packed 1-byte fields (x at offset 3: unaligned), then an int16 at an odd offset
  // and a float64 at offset 17, as a hand-made driver might send.
  PointLayout in;
  in.append("ring", FieldType::UInt8);
  in.append("flags", FieldType::Int8);
  in.append("return_type", FieldType::UInt8);
  in.append("x", FieldType::Float32);
  in.append("y", FieldType::Float32);
  in.append("z", FieldType::Float32);
  in.append("code", FieldType::Int16);
  in.append("time", FieldType::Float64);
  ASSERT_EQ(in.find("time")->offset, 17u);
  ASSERT_EQ(in.point_step, 25u);

  Hierarchy h(4.0, 3);
  h.setRecordLayout(in);
  std::vector<std::uint8_t> records(5 * in.point_step);
  for (std::size_t i = 0; i < records.size(); ++i) records[i] = static_cast<std::uint8_t>(i * 37 + 11);
  std::vector<double> xyz;
  std::vector<std::uint32_t> order;
  for (int i = 0; i < 5; ++i) {
    xyz.insert(xyz.end(), {10.0 * i, 0.5 * i, 1.0});
    order.push_back(static_cast<std::uint32_t>(i));
    float p[3] = {float(10.0 * i), float(0.5 * i), 1.0f};
    for (int a = 0; a < 3; ++a) std::memcpy(&records[i * in.point_step + 3 + 4 * a], &p[a], 4);
  }
  InsertBatch batch;
  batch.xyz = xyz.data();
  batch.size = 5;
  batch.order = order.data();
  batch.order_size = order.size();
  batch.records = records.data();
  batch.record_step = in.point_step;
  const InsertResult inserted = h.insert(batch);
  ASSERT_EQ(inserted.accepted.size(), 5u);  // 10 m apart: all at level 0

  const std::vector<SampleNormal> normals(5);
  for (const bool with_normals : {false, true}) {
    const PointBuffer cloud = buildOutputCloud(h, inserted.accepted, with_normals ? &normals : nullptr, true);
    expectAligned(cloud.layout());
    ASSERT_EQ(cloud.size(), 5u);
    std::vector<bool> covered(cloud.layout().point_step, false);
    for (const PointField &f : cloud.layout().fields)
      for (std::size_t b = f.offset; b < f.offset + f.byteSize(); ++b) covered[b] = true;
    for (std::size_t s = 0; s < cloud.size(); ++s) {
      const std::uint8_t *out = cloud.record(s);
      const std::uint8_t *src = records.data() + inserted.accepted[s] * in.point_step;  // ids follow the order here
      for (const char *name : {"ring", "flags", "return_type", "code", "time"}) {
        const PointField *fi = in.find(name), *fo = cloud.layout().find(name);
        ASSERT_NE(fo, nullptr) << name;
        EXPECT_EQ(std::memcmp(out + fo->offset, src + fi->offset, fi->byteSize()), 0) << name << " of sample " << s;
      }
      EXPECT_EQ(readAsDouble(out, *cloud.layout().find("x")), 10.0 * s);
      for (std::size_t b = 0; b < covered.size(); ++b) {
        if (!covered[b]) {
          EXPECT_EQ(out[b], 0) << "padding byte " << b << " of sample " << s;
        }
      }
    }
  }
}

// An input's own normals (PointXYZINormal; a PLY from another estimator) are kept when hpds writes none: `hpds sample
// --no-normals` on such a file used to drop them, with a warning that hpds wrote its own.
TEST(OutputCloud, InputNormalsAreCarriedWhenHpdsWritesNone) {
  PointLayout in;
  for (const char *n : {"x", "y", "z", "intensity", "normal_x", "normal_y", "normal_z", "curvature"})
    in.append(n, FieldType::Float32);
  Hierarchy h(4.0, 2);
  h.setRecordLayout(in);
  std::vector<float> records;
  std::vector<double> xyz;
  std::vector<std::uint32_t> order;
  for (int i = 0; i < 3; ++i) {
    const float x = 10.0f * static_cast<float>(i);
    records.insert(records.end(), {x, 0.0f, 1.0f, 7.0f, 0.6f, 0.0f, 0.8f, 0.01f * static_cast<float>(i + 1)});
    xyz.insert(xyz.end(), {x, 0.0, 1.0});
    order.push_back(static_cast<std::uint32_t>(i));
  }
  InsertBatch batch;
  batch.xyz = xyz.data();
  batch.size = 3;
  batch.order = order.data();
  batch.order_size = order.size();
  batch.records = reinterpret_cast<const std::uint8_t *>(records.data());
  batch.record_step = in.point_step;
  const InsertResult inserted = h.insert(batch);
  ASSERT_EQ(inserted.accepted.size(), 3u);

  EXPECT_EQ(fieldsNotCarried(in, false, false), std::vector<std::string>{});
  EXPECT_EQ(fieldsNotCarried(in, true, false),
            (std::vector<std::string>{"normal_x", "normal_y", "normal_z", "curvature"}));
  const std::vector<SampleNormal> ours(3, SampleNormal{{0.0f, 0.0f, 1.0f}, 0.5f, true});
  for (const bool with_normals : {false, true}) {
    const PointBuffer cloud = buildOutputCloud(h, inserted.accepted, with_normals ? &ours : nullptr, false);
    const PointLayout &out = cloud.layout();
    for (std::size_t s = 0; s < cloud.size(); ++s) {
      const float *src = records.data() + 8 * inserted.accepted[s];
      EXPECT_EQ(readAsDouble(cloud.record(s), *out.find("intensity")), 7.0);
      EXPECT_EQ(readAsDouble(cloud.record(s), *out.find("normal_x")), with_normals ? 0.0 : double(src[4]));
      EXPECT_EQ(readAsDouble(cloud.record(s), *out.find("normal_z")), with_normals ? 1.0 : double(src[6]));
      EXPECT_EQ(readAsDouble(cloud.record(s), *out.find("curvature")), with_normals ? 0.5 : double(src[7]));
    }
  }
}

TEST(OutputCloud, TypicalLidarLayoutNeedsNoPaddingInside) {
  // x y z intensity ring time (the velodyne driver's fields), normals on: 12 + 16 + 4 + 4 + 2 + 1 = 39 -> 40 bytes.
  PointLayout in;
  for (const char *n : {"x", "y", "z", "intensity"}) in.append(n, FieldType::Float32);
  in.append("ring", FieldType::UInt16);
  in.append("time", FieldType::Float32);
  const PointLayout out = outputLayout(in, true, false);
  expectAligned(out);
  EXPECT_EQ(out.point_step, 40u);
  const std::vector<std::string> order = {"x",         "y",         "z",    "normal_x", "normal_y",
                                          "normal_z",  "curvature", "intensity", "time", "ring", "level"};
  ASSERT_EQ(out.fields.size(), order.size());
  for (std::size_t i = 0; i < order.size(); ++i) EXPECT_EQ(out.fields[i].name, order[i]);
}

}  // namespace
}  // namespace hpds
