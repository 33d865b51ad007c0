#include "hpds_node/CloudConversion.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <set>
#include <vector>

namespace hpds_node {

namespace {

CloudError fail(CloudError error, std::string *why, const std::string &text) {
  if (why) *why = text;
  return error;
}

// Builds the layout while checking it; `layout` is only meaningful when None is returned.
CloudError checkLayout(const sensor_msgs::PointCloud2 &msg, hpds::PointLayout &layout, std::string *why) {
  if (msg.is_bigendian) return fail(CloudError::BigEndian, why, "is_bigendian is true (only little-endian data)");
  layout.fields.clear();
  // A default-constructed message (no fields, no points: what some drivers publish for a blocked or idle sensor)
  // is an empty frame, counted as such, not a cloud without x.
  if (msg.fields.empty() && msg.data.empty() && (msg.width == 0 || msg.height == 0)) {
    layout.point_step = 12;
    for (std::uint32_t i = 0; i < 3; ++i)
      layout.fields.push_back(hpds::PointField{std::string(1, char('x' + i)), 4 * i, hpds::FieldType::Float32, 1});
    return CloudError::None;
  }
  layout.point_step = msg.point_step;
  std::set<std::string> names;
  for (const sensor_msgs::PointField &f : msg.fields) {
    if (!hpds::isValidFieldType(f.datatype))
      return fail(CloudError::BadDatatype, why,
                  "field '" + f.name + "' has datatype " + std::to_string(int(f.datatype)) + " (valid: 1..8)");
    if (f.count == 0) return fail(CloudError::BadCount, why, "field '" + f.name + "' has count 0");
    if (f.count > hpds::kMaxFieldCount)
      return fail(CloudError::BadCount, why,
                  "field '" + f.name + "' has count " + std::to_string(f.count) + ", more than the " +
                      std::to_string(hpds::kMaxFieldCount) + " elements a field may have");
    const auto type = static_cast<hpds::FieldType>(f.datatype);
    const std::uint64_t end = std::uint64_t(f.offset) + std::uint64_t(f.count) * hpds::fieldTypeSize(type);
    if (end > msg.point_step)
      return fail(CloudError::FieldOutsidePoint, why,
                  "field '" + f.name + "' ends at byte " + std::to_string(end) + " beyond point_step " +
                      std::to_string(msg.point_step));
    // PCL's padding; a nameless field (seen from hand-made messages) no reader can find by name either, and a field
    // named '' in the output would break PCL's own conversions of it: both are padding.
    if (f.name == "_" || f.name.empty()) continue;
    if (!names.insert(f.name).second)
      return fail(CloudError::DuplicateField, why, "field '" + f.name + "' appears twice");
    layout.fields.push_back(hpds::PointField{f.name, f.offset, type, f.count});
  }
  for (const char *axis : {"x", "y", "z"}) {
    const hpds::PointField *f = layout.find(axis);
    if (!f) return fail(CloudError::MissingXyz, why, std::string("no '") + axis + "' field");
    if (f->count != 1)
      return fail(CloudError::BadXyz, why,
                  std::string("field '") + axis + "' has count " + std::to_string(f->count) + " (must be 1)");
  }
  if (std::string overlap = hpds::xyzOverlap(layout); !overlap.empty())
    return fail(CloudError::OverlappingXyz, why, overlap);
  return CloudError::None;
}

// Each size is a product of two uint32 header values, exact in 64 bits: a hostile header cannot wrap around to a
// small number that then "matches" data.size(). Checking row_step before height keeps width * height * point_step
// (which could exceed 64 bits) out of the picture.
CloudError checkSizes(const sensor_msgs::PointCloud2 &msg, std::string *why) {
  const std::uint64_t min_row = std::uint64_t(msg.width) * msg.point_step;
  if (msg.row_step < min_row)
    return fail(CloudError::BadRowStep, why,
                "row_step " + std::to_string(msg.row_step) + " < width " + std::to_string(msg.width) +
                    " * point_step " + std::to_string(msg.point_step));
  const std::uint64_t expected = std::uint64_t(msg.row_step) * msg.height;
  if (expected != msg.data.size())
    return fail(CloudError::DataSize, why,
                "data holds " + std::to_string(msg.data.size()) + " bytes, row_step " +
                    std::to_string(msg.row_step) + " * height " + std::to_string(msg.height) + " = " +
                    std::to_string(expected));
  return CloudError::None;
}

}  // namespace

const char *toString(CloudError error) {
  switch (error) {
    case CloudError::None:
      return "none";
    case CloudError::BigEndian:
      return "big_endian";
    case CloudError::BadDatatype:
      return "bad_datatype";
    case CloudError::BadCount:
      return "bad_count";
    case CloudError::FieldOutsidePoint:
      return "field_outside_point";
    case CloudError::DuplicateField:
      return "duplicate_field";
    case CloudError::MissingXyz:
      return "missing_xyz";
    case CloudError::BadXyz:
      return "bad_xyz";
    case CloudError::BadRowStep:
      return "bad_row_step";
    case CloudError::DataSize:
      return "data_size";
    case CloudError::OverlappingXyz:
      return "overlapping_xyz";
  }
  return "unknown";
}

CloudError validateCloud(const sensor_msgs::PointCloud2 &msg, std::string *why) {
  hpds::PointLayout layout;
  const CloudError e = checkLayout(msg, layout, why);
  return e != CloudError::None ? e : checkSizes(msg, why);
}

CloudError fromRosCloud(const sensor_msgs::PointCloud2 &msg, hpds::PointBuffer &out, std::string *why) {
  hpds::PointLayout layout;
  CloudError e = checkLayout(msg, layout, why);
  if (e == CloudError::None) e = checkSizes(msg, why);
  if (e != CloudError::None) return e;

  hpds::PointBuffer cloud(std::move(layout));
  std::vector<std::uint8_t> &bytes = cloud.bytes();
  const std::size_t row_bytes = std::size_t(msg.width) * msg.point_step;
  if (msg.row_step == row_bytes) {
    bytes.assign(msg.data.begin(), msg.data.end());
  } else if (row_bytes > 0) {  // zero-width rows: nothing to copy, and empty vectors may hold null pointers
    bytes.resize(row_bytes * msg.height);
    for (std::uint32_t row = 0; row < msg.height; ++row)
      std::memcpy(bytes.data() + row * row_bytes, msg.data.data() + std::size_t(row) * msg.row_step, row_bytes);
  }
  cloud.setOrganization(msg.width, msg.height);
  out = std::move(cloud);
  return CloudError::None;
}

void toRosCloud(const hpds::PointBuffer &cloud, const std_msgs::Header &header, sensor_msgs::PointCloud2 &out) {
  const hpds::PointLayout &layout = cloud.layout();
  out.header = header;
  out.height = cloud.height();
  out.width = cloud.width();
  out.fields.clear();
  out.fields.reserve(layout.fields.size());
  for (const hpds::PointField &f : layout.fields) {
    sensor_msgs::PointField pf;
    pf.name = f.name;
    pf.offset = f.offset;
    pf.datatype = static_cast<std::uint8_t>(f.type);
    pf.count = f.count;
    out.fields.push_back(std::move(pf));
  }
  out.is_bigendian = false;
  out.point_step = layout.point_step;
  out.row_step = cloud.width() * layout.point_step;
  out.data = cloud.bytes();

  // PCL's meaning: no point has a NaN or Inf in any floating-point field. An invalid normal (NaN) makes the cloud
  // not dense, so that PCL code which skips its finiteness checks on dense clouds does not read it as a number.
  std::vector<hpds::PointField> floats;
  for (const hpds::PointField &f : layout.fields)
    if (f.type == hpds::FieldType::Float32 || f.type == hpds::FieldType::Float64)
      for (std::uint32_t e = 0; e < f.count; ++e)
        floats.push_back(hpds::PointField{f.name, f.offset + e * static_cast<std::uint32_t>(hpds::fieldTypeSize(f.type)),
                                          f.type, 1});
  bool dense = true;
  for (std::size_t i = 0, n = cloud.size(); i < n && dense; ++i) {
    const std::uint8_t *r = cloud.record(i);
    for (const hpds::PointField &f : floats) dense = dense && std::isfinite(hpds::readAsDouble(r, f));
  }
  out.is_dense = dense;
}

}  // namespace hpds_node
