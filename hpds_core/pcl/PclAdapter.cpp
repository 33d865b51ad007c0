// The PCL side of hpds::pcl: PCL's readers run quietly and their clouds copied into PointBuffers, and PointBuffers
// turned into PCL clouds and PCD files.
#include <pcl/console/print.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include <algorithm>
#include <filesystem>
#include <mutex>

#include "ReaderSupport.hpp"
#include "hpds/pcl/PclCloud.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds {

namespace pcl_detail {

namespace {

namespace fs = std::filesystem;

// PCL's console verbosity is process-global. Nested/concurrent readers share one "quiet" period; the level in force
// before the first one entered is restored when the last one leaves.
class QuietPcl {
 public:
  QuietPcl() {
    std::lock_guard<std::mutex> lock(mutex());
    if (depth()++ == 0) {
      saved() = pcl::console::getVerbosityLevel();
      pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
    }
  }
  ~QuietPcl() {
    std::lock_guard<std::mutex> lock(mutex());
    if (--depth() == 0) pcl::console::setVerbosityLevel(saved());
  }
  QuietPcl(const QuietPcl &) = delete;
  QuietPcl &operator=(const QuietPcl &) = delete;

 private:
  static std::mutex &mutex() {
    static std::mutex m;
    return m;
  }
  static int &depth() {
    static int d = 0;
    return d;
  }
  static pcl::console::VERBOSITY_LEVEL &saved() {
    static pcl::console::VERBOSITY_LEVEL level = pcl::console::L_INFO;
    return level;
  }
};

PointBuffer fromPcl(const std::string &path, const pcl::PCLPointCloud2 &pc) {
  if (pc.is_bigendian) fail(path, "big-endian point data is not supported");
  PointLayout layout;
  layout.point_step = pc.point_step;
  for (const auto &f : pc.fields) {
    if (f.name == "_") continue;  // PCL's padding
    if (!isValidFieldType(f.datatype))
      fail(path, "field '" + f.name + "' has datatype " + std::to_string(int(f.datatype)) +
                     " (64-bit integer or bool), which hpds cannot represent");
    if (f.count == 0) fail(path, "field '" + f.name + "' has count 0");
    PointField field;
    field.name = f.name;
    field.offset = f.offset;
    field.type = static_cast<FieldType>(f.datatype);
    field.count = f.count;
    layout.fields.push_back(std::move(field));
  }
  checkCloudLayout(path, layout);

  // Sizes are checked against the bytes PCL actually produced before anything is allocated: width/height can come
  // from file content PCL applies after sizing its buffer (a PLY "camera" element's viewport).
  const std::uint64_t n = std::uint64_t(pc.width) * pc.height;
  const std::uint64_t dense_row = std::uint64_t(pc.width) * pc.point_step;
  const bool dense = pc.data.size() == n * pc.point_step;
  const bool strided = !dense && pc.row_step > dense_row && pc.height > 0 &&
                       pc.data.size() >= std::uint64_t(pc.height - 1) * pc.row_step + dense_row;
  if (!dense && !strided)
    fail(path, "inconsistent cloud: " + std::to_string(pc.data.size()) + " bytes for " + std::to_string(pc.width) +
                   "x" + std::to_string(pc.height) + " points of " + std::to_string(pc.point_step) + " bytes");
  PointBuffer cloud(layout, static_cast<std::size_t>(n));
  if (dense) {
    if (!pc.data.empty()) std::memcpy(cloud.bytes().data(), pc.data.data(), pc.data.size());
  } else {
    for (std::uint32_t row = 0; row < pc.height; ++row)
      std::memcpy(cloud.bytes().data() + row * dense_row, pc.data.data() + std::uint64_t(row) * pc.row_step,
                  static_cast<std::size_t>(dense_row));
  }
  cloud.setOrganization(pc.width, pc.height);
  return cloud;
}

bool isValidPcdFieldName(const std::string &name) {
  if (name.empty()) return false;
  for (unsigned char c : name)
    if (c <= ' ' || c == 0x7f) return false;
  return true;
}

}  // namespace

void checkCloudLayout(const std::string &path, const PointLayout &layout) {
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(path, std::string("invalid point layout: ") + e.what());
  }
  if (!layout.find("x") || !layout.find("y") || !layout.find("z")) {
    std::string names;
    // Quoted: a name with a NUL or other control byte in it ("z\0w") cut the message short, as if z were there.
    for (const auto &f : layout.fields) names += (names.empty() ? "" : " ") + quote(f.name);
    fail(path, "no x/y/z fields (fields: " + (names.empty() ? std::string("none") : names) + ")");
  }
  // The pipeline reads one coordinate per axis; a vector-valued x would be sampled by its first element and lost on
  // writing (fuzz_pcd found it), so it is refused here, where the file can still be named.
  for (const char *axis : {"x", "y", "z"}) {
    const PointField &f = *layout.find(axis);
    if (f.count != 1)
      fail(path, "field '" + f.name + "' has count " + std::to_string(f.count) + ": x, y and z must be single values");
  }
}

PointBuffer readWithPcl(const std::string &path, PclFormat which) {
  const char *format = which == PclFormat::Pcd ? "PCD" : "PLY";
  pcl::PCLPointCloud2 pc;
  int result = -1;
  {
    QuietPcl quiet;
    try {
      Eigen::Vector4f origin;
      Eigen::Quaternionf orientation;
      int version = 0;
      if (which == PclFormat::Pcd)
        result = pcl::PCDReader().read(path, pc, origin, orientation, version);
      else
        result = pcl::PLYReader().read(path, pc, origin, orientation, version);
    } catch (const std::exception &e) {
      fail(path, std::string("PCL's ") + format + " reader failed: " + e.what());
    } catch (...) {
      fail(path, std::string("PCL's ") + format + " reader failed with an unknown exception");
    }
  }
  if (result < 0)
    fail(path, std::string("PCL's ") + format + " reader rejected the file (error " + std::to_string(result) + ")");
  return fromPcl(path, pc);
}

}  // namespace pcl_detail

using pcl_detail::fail;
using pcl_detail::kMaxFieldCount;
using pcl_detail::QuietPcl;
using pcl_detail::isValidPcdFieldName;
using pcl_detail::quote;
namespace fs = std::filesystem;

pcl::PCLPointCloud2 toPclCloud2(const PointBuffer &cloud) {
  const PointLayout &layout = cloud.layout();
  // PCL's header writer assumes fields in offset order and derives "_" padding from the gaps between them.
  std::vector<PointField> fields = layout.fields;
  std::stable_sort(fields.begin(), fields.end(),
                   [](const PointField &a, const PointField &b) { return a.offset < b.offset; });
  bool overlapping = false;
  for (std::size_t i = 1; i < fields.size(); ++i)
    overlapping = overlapping || fields[i].offset < fields[i - 1].offset + fields[i - 1].byteSize();

  pcl::PCLPointCloud2 pc;
  pc.is_bigendian = false;
  pc.is_dense = false;
  const std::size_t n = cloud.size();
  const bool organised = std::uint64_t(cloud.width()) * cloud.height() == n;
  pc.width = organised ? cloud.width() : static_cast<std::uint32_t>(n);
  pc.height = organised ? cloud.height() : 1;
  if (!overlapping) {
    for (const auto &f : fields) {
      pcl::PCLPointField pf;
      pf.name = f.name;
      pf.offset = f.offset;
      pf.datatype = static_cast<std::uint8_t>(f.type);
      pf.count = f.count;
      pc.fields.push_back(pf);
    }
    pc.point_step = layout.point_step;
    pc.data = cloud.bytes();
  } else {
    // PCL fields cannot alias each other: repack each into its own bytes.
    std::uint32_t offset = 0;
    for (const auto &f : layout.fields) {
      pcl::PCLPointField pf;
      pf.name = f.name;
      pf.offset = offset;
      pf.datatype = static_cast<std::uint8_t>(f.type);
      pf.count = f.count;
      pc.fields.push_back(pf);
      offset += static_cast<std::uint32_t>(f.byteSize());
    }
    pc.point_step = offset;
    pc.data.resize(n * offset);
    for (std::size_t i = 0; i < n; ++i) {
      std::uint8_t *dst = pc.data.data() + i * offset;
      for (std::size_t k = 0; k < layout.fields.size(); ++k)
        std::memcpy(dst + pc.fields[k].offset, cloud.record(i) + layout.fields[k].offset, layout.fields[k].byteSize());
    }
  }
  pc.row_step = pc.width * pc.point_step;
  return pc;
}

void writePcd(const std::string &path, const PointBuffer &cloud) {
  const PointLayout &layout = cloud.layout();
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(path, std::string("cannot write PCD: invalid layout: ") + e.what());
  }
  if (layout.fields.empty()) fail(path, "cannot write PCD: the cloud has no fields");
  for (const auto &f : layout.fields) {
    if (!isValidPcdFieldName(f.name)) fail(path, "cannot write PCD: field name " + quote(f.name) + " is invalid");
    if (f.count > kMaxFieldCount)
      fail(path, "cannot write PCD: field '" + f.name + "' has count " + std::to_string(f.count) +
                     ", more than the " + std::to_string(kMaxFieldCount) + " elements a field may have");
  }

  const pcl::PCLPointCloud2 pc = toPclCloud2(cloud);

  const fs::path parent = fs::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty() && !fs::is_directory(parent, ec)) fail(path, "cannot write PCD: directory does not exist");

  // PCL formats the header (field list, "_" padding fields, organisation). The file itself is written here:
  // PCDWriter::writeBinary stretches the file to one memory page plus the data, which leaves up to 4 KiB of zeros
  // after the points and, once the header outgrows a page (many fields), writes past the end of its mapping (SIGBUS).
  std::string header;
  {
    QuietPcl quiet;
    try {
      pcl::PCDWriter writer;
      header = writer.generateHeaderBinary(pc, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity());
    } catch (const std::exception &e) {
      fail(path, std::string("cannot write PCD: ") + e.what());
    }
  }
  if (header.empty()) fail(path, "cannot write PCD: PCL could not describe the point layout");
  header += "DATA binary\n";

  io_detail::OutputFile file(path);
  file.write(header.data(), header.size());
  file.write(pc.data.data(), pc.data.size());
  file.close();
}

}  // namespace hpds
