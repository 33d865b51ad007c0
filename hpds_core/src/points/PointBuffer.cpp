#include "hpds/points/PointBuffer.hpp"

#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>

namespace hpds {

std::size_t fieldTypeSize(FieldType type) {
  switch (type) {
    case FieldType::Int8:
    case FieldType::UInt8:
      return 1;
    case FieldType::Int16:
    case FieldType::UInt16:
      return 2;
    case FieldType::Int32:
    case FieldType::UInt32:
    case FieldType::Float32:
      return 4;
    case FieldType::Float64:
      return 8;
  }
  return 0;
}

bool isValidFieldType(std::uint8_t raw) { return raw >= 1 && raw <= 8; }

std::string describeFields(const PointLayout &l) {
  std::string names, types;
  for (const PointField &f : l.fields) {
    names += (names.empty() ? "" : " ") + f.name;
    types += std::string(types.empty() ? "" : " ") + fieldTypeName(f.type) +
             (f.count > 1 ? "[" + std::to_string(f.count) + "]" : "");
  }
  return (names.empty() ? "none" : names) + " as " + (types.empty() ? "-" : types) + ", " +
         std::to_string(l.point_step) + " bytes";
}

const char *fieldTypeName(FieldType type) {
  switch (type) {
    case FieldType::Int8:
      return "int8";
    case FieldType::UInt8:
      return "uint8";
    case FieldType::Int16:
      return "int16";
    case FieldType::UInt16:
      return "uint16";
    case FieldType::Int32:
      return "int32";
    case FieldType::UInt32:
      return "uint32";
    case FieldType::Float32:
      return "float32";
    case FieldType::Float64:
      return "float64";
  }
  return "invalid";
}

const PointField *PointLayout::find(const std::string &name) const {
  for (const auto &f : fields)
    if (f.name == name) return &f;
  return nullptr;
}

void PointLayout::append(const std::string &name, FieldType type, std::uint32_t count) {
  if (count == 0 || count > kMaxFieldCount)
    throw std::invalid_argument("field '" + name + "' has count " + std::to_string(count) + " (1.." +
                                std::to_string(kMaxFieldCount) + ")");
  PointField f;
  f.name = name;
  f.offset = point_step;
  f.type = type;
  f.count = count;
  const std::uint64_t end = std::uint64_t(point_step) + f.byteSize();
  if (end > UINT32_MAX)
    throw std::invalid_argument("field '" + name + "' would end at byte " + std::to_string(end) +
                                ", beyond the 32-bit point_step");
  point_step = static_cast<std::uint32_t>(end);
  fields.push_back(std::move(f));
}

void PointLayout::validate() const {
  std::set<std::string> names;
  for (const auto &f : fields) {
    if (!isValidFieldType(static_cast<std::uint8_t>(f.type)))
      throw std::invalid_argument("field '" + f.name + "' has an invalid datatype " +
                                  std::to_string(static_cast<int>(f.type)));
    if (f.count == 0) throw std::invalid_argument("field '" + f.name + "' has count 0");
    if (f.count > kMaxFieldCount)
      throw std::invalid_argument("field '" + f.name + "' has count " + std::to_string(f.count) + ", more than the " +
                                  std::to_string(kMaxFieldCount) + " elements a field may have");
    const std::uint64_t end = std::uint64_t(f.offset) + std::uint64_t(f.count) * fieldTypeSize(f.type);
    if (end > point_step)
      throw std::invalid_argument("field '" + f.name + "' ends at byte " + std::to_string(end) +
                                  " beyond point_step " + std::to_string(point_step));
    if (!names.insert(f.name).second) throw std::invalid_argument("field '" + f.name + "' appears twice");
  }
  if (std::string overlap = xyzOverlap(*this); !overlap.empty()) throw std::invalid_argument(overlap);
}

std::string xyzOverlap(const PointLayout &layout) {
  // Only x, y and z among themselves: another field over x's bytes is a view of them (a uint32 of x's bits).
  const PointField *f[3] = {layout.find("x"), layout.find("y"), layout.find("z")};
  for (int i = 0; i < 3; ++i)
    for (int j = i + 1; j < 3; ++j) {
      if (!f[i] || !f[j]) continue;
      const std::uint64_t a0 = f[i]->offset, a1 = a0 + f[i]->byteSize(), b0 = f[j]->offset, b1 = b0 + f[j]->byteSize();
      if (a0 < b1 && b0 < a1)
        return "field '" + f[i]->name + "' (bytes " + std::to_string(a0) + ".." + std::to_string(a1 - 1) +
               ") overlaps field '" + f[j]->name + "' (bytes " + std::to_string(b0) + ".." + std::to_string(b1 - 1) +
               "): a position read through shared bytes is garbage";
    }
  return {};
}

void PointBuffer::setOrganization(std::uint32_t width, std::uint32_t height) {
  if (std::uint64_t(width) * height != size())
    throw std::invalid_argument("organisation " + std::to_string(width) + "x" + std::to_string(height) +
                                " does not match " + std::to_string(size()) + " points");
  width_ = width;
  height_ = height;
}

namespace {
// Bytes of n records, or std::length_error: the width is 32 bits (PointCloud2's), and n * step must not wrap.
std::size_t bytesFor(std::size_t n, std::uint32_t step) {
  if (step == 0) return 0;
  if (n > 0xFFFFFFFFull) throw std::length_error("point buffer: more than 2^32 - 1 points (" + std::to_string(n) + ")");
  if (n > std::numeric_limits<std::size_t>::max() / step)
    throw std::length_error("point buffer: " + std::to_string(n) + " points of " + std::to_string(step) +
                            " bytes exceed the address space");
  return n * step;
}
}  // namespace

void PointBuffer::resize(std::size_t n) {
  data_.resize(bytesFor(n, layout_.point_step), 0);
  width_ = layout_.point_step ? static_cast<std::uint32_t>(n) : 0;
  height_ = 1;
}

void PointBuffer::reserve(std::size_t n) { data_.reserve(bytesFor(n, layout_.point_step)); }

void PointBuffer::pushBack(const std::uint8_t *record) {
  (void)bytesFor(size() + 1, layout_.point_step);
  data_.insert(data_.end(), record, record + layout_.point_step);
  width_ = static_cast<std::uint32_t>(size());
  height_ = 1;
}

namespace {
template <typename T>
T loadAs(const std::uint8_t *p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}
template <typename T>
void storeSaturated(std::uint8_t *p, double value) {
  T v;
  if constexpr (std::is_floating_point_v<T>) {
    v = static_cast<T>(value);
  } else {
    if (std::isnan(value)) {
      v = 0;
    } else {
      const double lo = static_cast<double>(std::numeric_limits<T>::lowest());
      const double hi = static_cast<double>(std::numeric_limits<T>::max());
      const double r = std::nearbyint(value);
      v = r <= lo ? std::numeric_limits<T>::lowest()
                  : (r >= hi ? std::numeric_limits<T>::max() : static_cast<T>(r));
    }
  }
  std::memcpy(p, &v, sizeof(T));
}
}  // namespace

double readAsDouble(const std::uint8_t *record, const PointField &field, std::uint32_t element) {
  const std::uint8_t *p = record + field.offset + element * fieldTypeSize(field.type);
  switch (field.type) {
    case FieldType::Int8:
      return loadAs<std::int8_t>(p);
    case FieldType::UInt8:
      return loadAs<std::uint8_t>(p);
    case FieldType::Int16:
      return loadAs<std::int16_t>(p);
    case FieldType::UInt16:
      return loadAs<std::uint16_t>(p);
    case FieldType::Int32:
      return loadAs<std::int32_t>(p);
    case FieldType::UInt32:
      return loadAs<std::uint32_t>(p);
    case FieldType::Float32:
      return loadAs<float>(p);
    case FieldType::Float64:
      return loadAs<double>(p);
  }
  return std::numeric_limits<double>::quiet_NaN();
}

void writeFromDouble(std::uint8_t *record, const PointField &field, double value, std::uint32_t element) {
  std::uint8_t *p = record + field.offset + element * fieldTypeSize(field.type);
  switch (field.type) {
    case FieldType::Int8:
      return storeSaturated<std::int8_t>(p, value);
    case FieldType::UInt8:
      return storeSaturated<std::uint8_t>(p, value);
    case FieldType::Int16:
      return storeSaturated<std::int16_t>(p, value);
    case FieldType::UInt16:
      return storeSaturated<std::uint16_t>(p, value);
    case FieldType::Int32:
      return storeSaturated<std::int32_t>(p, value);
    case FieldType::UInt32:
      return storeSaturated<std::uint32_t>(p, value);
    case FieldType::Float32:
      return storeSaturated<float>(p, value);
    case FieldType::Float64:
      return storeSaturated<double>(p, value);
  }
}

PointBuffer withLayout(const PointBuffer &from, const PointLayout &to) {
  PointBuffer out(to, from.size());
  out.setOrganization(from.width(), from.height());
  for (const PointField &f : to.fields) {
    const PointField *src = from.layout().find(f.name);
    if (!src) continue;
    if (src->type != f.type || src->count != f.count)
      throw std::invalid_argument("withLayout: field '" + f.name + "' differs in type or count");
    for (std::size_t i = 0; i < from.size(); ++i) copyFieldBytes(out.record(i), f, from.record(i), *src);
  }
  return out;
}

}  // namespace hpds
