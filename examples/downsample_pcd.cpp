// Downsamples a PCD file with hpds's two one-call APIs and writes the samples, with normals, to a new PCD.
//   downsample_pcd IN.pcd OUT.pcd [CONFIG.yaml]
// The PCL call keeps every field of the input points; the plain call gives indices into the input. Both must agree.
#include <pcl/PCLPointCloud2.h>
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <iostream>

#include <hpds/hpds.hpp>
#include <hpds/pcl.hpp>

// One value of a PCL field of any numeric type, as float.
float fieldAsFloat(const std::uint8_t *p, std::uint8_t datatype) {
  auto as = [p](auto v) {
    std::memcpy(&v, p, sizeof v);
    return static_cast<float>(v);
  };
  switch (datatype) {
    case pcl::PCLPointField::INT8: return as(std::int8_t{});
    case pcl::PCLPointField::UINT8: return as(std::uint8_t{});
    case pcl::PCLPointField::INT16: return as(std::int16_t{});
    case pcl::PCLPointField::UINT16: return as(std::uint16_t{});
    case pcl::PCLPointField::INT32: return as(std::int32_t{});
    case pcl::PCLPointField::UINT32: return as(std::uint32_t{});
    case pcl::PCLPointField::FLOAT64: return as(double{});
    default: return as(float{});
  }
}

int main(int argc, char **argv) {
  if (argc < 3 || argc > 4) {
    std::cerr << "usage: downsample_pcd IN.pcd OUT.pcd [CONFIG.yaml]\n";
    return 2;
  }
  namespace fs = std::filesystem;
  const fs::path in = argv[1], out = argv[2];
  std::error_code ec;
  if (fs::equivalent(in, out, ec)) {
    std::cerr << "downsample_pcd: " << out << " is the input\n";
    return 2;
  }
  try {
    const hpds::HpdsConfig config = argc == 4 ? hpds::loadConfig(argv[3]) : hpds::HpdsConfig{};

    // x y z through PCL's conversion; intensity by hand, whatever its type: drivers write uint8 (Velodyne's VLP-16),
    // uint16 or float, and PCL converts a field into PointXYZI only from float32 (otherwise it leaves 0 and warns).
    pcl::PCLPointCloud2 blob;
    if (pcl::io::loadPCDFile(in.string(), blob) != 0) {
      std::cerr << "downsample_pcd: cannot read " << in << "\n";
      return 1;
    }
    pcl::PointCloud<pcl::PointXYZ> xyz_cloud;
    pcl::fromPCLPointCloud2(blob, xyz_cloud);
    pcl::PointCloud<pcl::PointXYZI> cloud;
    pcl::copyPointCloud(xyz_cloud, cloud);
    if (const int index = pcl::getFieldIndex(blob, "intensity"); index >= 0) {
      const pcl::PCLPointField &field = blob.fields[static_cast<std::size_t>(index)];
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        const std::size_t at = (i / blob.width) * blob.row_step + (i % blob.width) * blob.point_step;
        cloud[i].intensity = fieldAsFloat(&blob.data[at + field.offset], field.datatype);
      }
    }

    // 1. The PCL call: real input points with every field, and their normals in the same order.
    pcl::PointCloud<pcl::Normal> normals;
    const pcl::PointCloud<pcl::PointXYZI>::Ptr samples = hpds::downsample(cloud, config, &normals);

    // 2. The plain call on the same coordinates: indices into the input and levels.
    std::vector<Eigen::Vector3f> xyz;
    xyz.reserve(cloud.size());
    for (const auto &p : cloud.points) xyz.emplace_back(p.x, p.y, p.z);
    hpds::HpdsConfig with_normals = config;
    with_normals.normals.enabled = true;
    const hpds::Samples plain = hpds::downsample(xyz, with_normals);

    if (plain.size() != samples->size()) {
      std::cerr << "downsample_pcd: the two calls disagree: " << plain.size() << " vs " << samples->size() << "\n";
      return 1;
    }
    std::size_t valid = 0;
    for (std::size_t i = 0; i < plain.size(); ++i) {
      if (cloud[plain.index[i]].intensity != (*samples)[i].intensity) {
        std::cerr << "downsample_pcd: sample " << i << " differs between the two calls\n";
        return 1;
      }
      valid += std::isfinite(normals[i].normal_x) ? 1u : 0u;
    }

    pcl::PointCloud<pcl::PointXYZINormal> result;
    pcl::concatenateFields(*samples, normals, result);
    // Written beside the target and renamed into place: an interrupted run never leaves a half-written OUT.
    const fs::path tmp = out.string() + ".tmp";
    if (pcl::io::savePCDFileBinary(tmp.string(), result) != 0) {
      std::cerr << "downsample_pcd: cannot write " << tmp << "\n";
      return 1;
    }
    fs::rename(tmp, out);
    const int deepest = plain.level.empty() ? 0 : *std::max_element(plain.level.begin(), plain.level.end());
    std::cout << cloud.size() << " points -> " << samples->size() << " samples (levels 0.." << deepest << "), "
              << valid << " with a normal, written to " << out.string() << "\n";
    return 0;
  } catch (const std::exception &e) {
    std::cerr << "downsample_pcd: " << e.what() << "\n";
    return 1;
  }
}
