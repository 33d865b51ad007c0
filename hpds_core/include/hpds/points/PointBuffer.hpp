// PointBuffer: a point cloud with an arbitrary per-point record layout.
//
// Contract
// - Modelled on sensor_msgs/PointCloud2 (and pcl::PCLPointCloud2) so that adapters copy bytes, never reinterpret:
//   every point is a record of `layout.point_step` bytes; fields sit at byte offsets with a datatype numbered as in
//   PointCloud2 (INT8=1 ... FLOAT64=8) and an element count.
// - Records are stored densely (row_step == width * point_step) and little-endian (the host order on every target we
//   build for). `width`/`height` keep the organisation of the source (height > 1: organised); size() = width*height.
// - Values are read through `readAsDouble`, which memcpy's the bytes: no alignment or type assumptions.
// - A PointBuffer owns its bytes; it is a value type, not thread-safe for concurrent mutation.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

namespace hpds {

/// Element datatypes, numbered exactly as sensor_msgs::PointField / pcl::PCLPointField.
enum class FieldType : std::uint8_t {
  Int8 = 1,
  UInt8 = 2,
  Int16 = 3,
  UInt16 = 4,
  Int32 = 5,
  UInt32 = 6,
  Float32 = 7,
  Float64 = 8,
};

/// Bytes of one element of `type`; 0 for a value outside the enum.
[[nodiscard]] std::size_t fieldTypeSize(FieldType type);
/// True when `raw` is one of the eight PointCloud2 datatypes.
[[nodiscard]] bool isValidFieldType(std::uint8_t raw);
/// "float32", "uint8", ... (for messages).
[[nodiscard]] const char *fieldTypeName(FieldType type);

struct PointField {
  std::string name;
  std::uint32_t offset = 0;  ///< byte offset inside the record
  FieldType type = FieldType::Float32;
  std::uint32_t count = 1;  ///< elements (1 for scalars)

  [[nodiscard]] std::size_t byteSize() const { return fieldTypeSize(type) * count; }
  bool operator==(const PointField &o) const {
    return name == o.name && offset == o.offset && type == o.type && count == o.count;
  }
};

/// Elements one field may have (a PCD COUNT, a PointCloud2 field's count): real fields hold a few (rgb, a
/// descriptor); a count beyond this is a malformed header, and sums of such counts could wrap a 32-bit point_step.
inline constexpr std::uint32_t kMaxFieldCount = 1u << 20;

struct PointLayout {
  std::vector<PointField> fields;
  std::uint32_t point_step = 0;  ///< bytes per record (>= end of the last field; may include padding)

  [[nodiscard]] const PointField *find(const std::string &name) const;
  /// Appends a field at the current end of the record and grows point_step. Throws std::invalid_argument for a count
  /// of 0 or above kMaxFieldCount, or when point_step would pass 2^32 - 1 (nothing is appended then).
  void append(const std::string &name, FieldType type, std::uint32_t count = 1);
  /// Throws std::invalid_argument when a field overlaps the record end, has a bad type, count 0 or above
  /// kMaxFieldCount, a name repeats, or two of x, y and z share bytes (xyzOverlap).
  void validate() const;
  bool operator==(const PointLayout &o) const { return fields == o.fields && point_step == o.point_step; }
  bool operator!=(const PointLayout &o) const { return !(*this == o); }
};

/// Where two of x, y and z share bytes (x and y at one offset, a z that starts inside y): the sentence that names the
/// pair, or "" when they stand apart. A position read through such bytes is garbage; PointLayout::validate refuses
/// it. Other fields may overlap anything (rgb inside rgba, a uint32 view of x's bits).
[[nodiscard]] std::string xyzOverlap(const PointLayout &layout);

/// "x y z intensity as float32 float32 float32 float32, 16 bytes": what tells two layouts apart in an error message.
[[nodiscard]] std::string describeFields(const PointLayout &layout);

class PointBuffer {
 public:
  PointBuffer() = default;
  explicit PointBuffer(PointLayout layout, std::size_t n = 0) : layout_(std::move(layout)) { resize(n); }
  PointBuffer(const PointBuffer &) = default;
  PointBuffer &operator=(const PointBuffer &) = default;
  /// The moved-from buffer is left empty and unorganised (no layout, 0 x 1), so width * height = size() holds.
  PointBuffer(PointBuffer &&o) noexcept
      : layout_(std::move(o.layout_)), data_(std::move(o.data_)), width_(o.width_), height_(o.height_) {
    o.reset();
  }
  PointBuffer &operator=(PointBuffer &&o) noexcept {
    if (this != &o) {
      layout_ = std::move(o.layout_);
      data_ = std::move(o.data_);
      width_ = o.width_;
      height_ = o.height_;
      o.reset();
    }
    return *this;
  }

  [[nodiscard]] const PointLayout &layout() const { return layout_; }
  [[nodiscard]] std::size_t size() const { return layout_.point_step ? data_.size() / layout_.point_step : 0; }
  [[nodiscard]] bool empty() const { return size() == 0; }
  [[nodiscard]] std::uint32_t width() const { return width_; }
  [[nodiscard]] std::uint32_t height() const { return height_; }
  /// Sets the organisation; width*height must equal size().
  void setOrganization(std::uint32_t width, std::uint32_t height);

  /// Resizes to n records (new bytes zeroed); organisation becomes n x 1. A layout of point_step 0 holds no record:
  /// the buffer stays 0 x 1. Throws std::length_error for more than 2^32 - 1 records (a width, as in PointCloud2)
  /// or n * point_step beyond the address space; nothing changes then.
  void resize(std::size_t n);
  /// As resize, without changing the records; the same std::length_error.
  void reserve(std::size_t n);
  /// Appends one record copied from `record` (point_step bytes); organisation becomes size() x 1. Throws
  /// std::length_error past 2^32 - 1 records.
  void pushBack(const std::uint8_t *record);

  [[nodiscard]] std::uint8_t *record(std::size_t i) { return data_.data() + i * layout_.point_step; }
  [[nodiscard]] const std::uint8_t *record(std::size_t i) const { return data_.data() + i * layout_.point_step; }
  [[nodiscard]] std::vector<std::uint8_t> &bytes() { return data_; }
  [[nodiscard]] const std::vector<std::uint8_t> &bytes() const { return data_; }

 private:
  void reset() noexcept {
    layout_ = PointLayout{};
    data_.clear();
    width_ = 0;
    height_ = 1;
  }

  PointLayout layout_;
  std::vector<std::uint8_t> data_;
  std::uint32_t width_ = 0;
  std::uint32_t height_ = 1;
};

/// Reads element `element` of `field` in `record` converted to double (memcpy, any alignment).
[[nodiscard]] double readAsDouble(const std::uint8_t *record, const PointField &field, std::uint32_t element = 0);
/// Writes `value` converted to the field's type (saturating/rounding for integer types).
void writeFromDouble(std::uint8_t *record, const PointField &field, double value, std::uint32_t element = 0);

/// Copies one record's bytes of `src_field` into `dst_field` of another record; both fields must have equal
/// type and count.
inline void copyFieldBytes(std::uint8_t *dst_record, const PointField &dst_field, const std::uint8_t *src_record,
                           const PointField &src_field) {
  std::memcpy(dst_record + dst_field.offset, src_record + src_field.offset, src_field.byteSize());
}

/// `from`'s records in layout `to`, same organisation: every field of `to` that `from` has (by name) copied byte for
/// byte, the others and the padding zero. Throws std::invalid_argument when such a pair differs in type or count.
[[nodiscard]] PointBuffer withLayout(const PointBuffer &from, const PointLayout &to);

}  // namespace hpds
