// readPointCloud / writePointCloud: one entry point per direction, dispatching on the file extension.
#include "hpds/pcl/PointCloudFile.hpp"

#include "ReaderSupport.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "io/FileAccess.hpp"

namespace hpds {

using pcl_detail::fail;
using pcl_detail::lowerExtension;
using pcl_detail::quote;
using pcl_detail::readPcd;
using pcl_detail::readPly;

PointBuffer readPointCloud(const std::string &path) { return readPointCloud(path, nullptr); }

PointBuffer readPointCloud(const std::string &path, Eigen::Vector3d *viewpoint) {
  if (viewpoint) viewpoint->setZero();
  const std::string ext = lowerExtension(path);
  if (ext == ".pcd") return readPcd(path, viewpoint);
  if (ext == ".ply") return readPly(path);
  if (ext == ".bin") return readKittiBin(path);
  // A folder of frames or a mistyped path: "file not found" / "not a regular file" says more than its extension.
  io_detail::requireRegularFile(path);
  fail(path, "unsupported extension " + quote(ext.empty() ? "(none)" : ext) + " (expected .pcd, .ply or .bin)");
}

void writePointCloud(const std::string &path, const PointBuffer &cloud) {
  const std::string ext = lowerExtension(path);
  if (ext == ".pcd") return writePcd(path, cloud);
  if (ext == ".ply") return writePly(path, cloud);
  if (ext == ".bin") return writeKittiBin(path, cloud);
  fail(path, "unsupported extension " + quote(ext.empty() ? "(none)" : ext) + " (expected .pcd, .ply or .bin)");
}

}  // namespace hpds
