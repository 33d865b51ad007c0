// Writes the seed corpora of the fuzz targets into DIR/<target>/: small valid inputs of every format variant the
// readers support, made from the project's own synthetic lidar (no external data). Usage: make_seeds DIR
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "hpds/config/ConfigYaml.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"

namespace fs = std::filesystem;
using namespace hpds;

namespace {

void writeText(const fs::path &p, const std::string &text) {
  std::ofstream f(p, std::ios::binary);
  f << text;
}

void writeBytes(const fs::path &p, const std::vector<std::uint8_t> &b) {
  std::ofstream f(p, std::ios::binary);
  f.write(reinterpret_cast<const char *>(b.data()), static_cast<std::streamsize>(b.size()));
}

SyntheticLidarConfig tinyLidar(bool organized) {
  SyntheticLidarConfig c;
  c.beams = 4;
  c.azimuth_steps = 24;
  c.frames = 5;
  c.organized = organized;
  c.emit_no_returns = organized;
  return c;
}

// x y z intensity as ascii PCD lines; every fourth point a NaN (as PCL writes invalid points).
std::string asciiPcd(const PointBuffer &cloud) {
  std::ostringstream s;
  const std::size_t n = cloud.size();
  s << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\n"
       "TYPE F F F F\nCOUNT 1 1 1 1\nWIDTH "
    << n << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << n << "\nDATA ascii\n";
  const PointLayout &l = cloud.layout();
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 4; ++k) {
      if (k) s << ' ';
      if (i % 4 == 3 && k < 3)
        s << "nan";
      else
        s << readAsDouble(cloud.record(i), l.fields[k]);
    }
    s << '\n';
  }
  return s.str();
}

// binary_compressed PCD: fields transposed (all x, then all y, ...) and LZF-encoded with literal runs only, which
// is valid LZF that PCL's decompressor reads like any other.
std::vector<std::uint8_t> compressedPcd(const PointBuffer &cloud) {
  const PointLayout &l = cloud.layout();
  std::ostringstream h;
  h << "VERSION 0.7\nFIELDS";
  for (const auto &f : l.fields) h << ' ' << f.name;
  h << "\nSIZE";
  for (const auto &f : l.fields) h << ' ' << fieldTypeSize(f.type);
  h << "\nTYPE";
  for (const auto &f : l.fields)
    h << ' ' << (f.type == FieldType::Float32 || f.type == FieldType::Float64 ? 'F'
                 : (f.type == FieldType::Int8 || f.type == FieldType::Int16 || f.type == FieldType::Int32) ? 'I'
                                                                                                             : 'U');
  h << "\nCOUNT";
  for (const auto &f : l.fields) h << ' ' << f.count;
  h << "\nWIDTH " << cloud.size() << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << cloud.size()
    << "\nDATA binary_compressed\n";
  std::vector<std::uint8_t> soa;
  for (const auto &f : l.fields)
    for (std::size_t i = 0; i < cloud.size(); ++i)
      soa.insert(soa.end(), cloud.record(i) + f.offset, cloud.record(i) + f.offset + f.byteSize());
  std::vector<std::uint8_t> lzf;
  for (std::size_t i = 0; i < soa.size(); i += 32) {
    const std::size_t run = std::min<std::size_t>(32, soa.size() - i);
    lzf.push_back(static_cast<std::uint8_t>(run - 1));
    lzf.insert(lzf.end(), soa.begin() + static_cast<std::ptrdiff_t>(i), soa.begin() + static_cast<std::ptrdiff_t>(i + run));
  }
  const std::string head = h.str();
  std::vector<std::uint8_t> out(head.begin(), head.end());
  const std::uint32_t sizes[2] = {static_cast<std::uint32_t>(lzf.size()), static_cast<std::uint32_t>(soa.size())};
  const auto *p = reinterpret_cast<const std::uint8_t *>(sizes);
  out.insert(out.end(), p, p + 8);
  out.insert(out.end(), lzf.begin(), lzf.end());
  return out;
}

std::string asciiPly(const PointBuffer &cloud) {
  std::ostringstream s;
  const std::size_t n = std::min<std::size_t>(cloud.size(), 20);
  s << "ply\nformat ascii 1.0\ncomment seed\nelement vertex " << n
    << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar intensity\n"
       "element face 2\nproperty list uchar int vertex_indices\nend_header\n";
  const PointLayout &l = cloud.layout();
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) s << readAsDouble(cloud.record(i), l.fields[k]) << ' ';
    s << (i * 13) % 256 << '\n';
  }
  s << "3 0 1 2\n4 0 1 2 3\n";
  return s.str();
}

std::vector<std::uint8_t> bigEndianPly(const PointBuffer &cloud) {
  const std::size_t n = std::min<std::size_t>(cloud.size(), 20);
  const std::string head = "ply\nformat binary_big_endian 1.0\nelement vertex " + std::to_string(n) +
                           "\nproperty float x\nproperty float y\nproperty float z\nproperty double t\nend_header\n";
  std::vector<std::uint8_t> out(head.begin(), head.end());
  const PointLayout &l = cloud.layout();
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      const float v = static_cast<float>(readAsDouble(cloud.record(i), l.fields[k]));
      std::uint8_t b[4];
      std::memcpy(b, &v, 4);
      for (int j = 3; j >= 0; --j) out.push_back(b[j]);
    }
    const double t = 0.001 * double(i);
    std::uint8_t b[8];
    std::memcpy(b, &t, 8);
    for (int j = 7; j >= 0; --j) out.push_back(b[j]);
  }
  return out;
}

PointBuffer typedCloud(FieldType xyz, std::size_t n) {
  PointLayout l;
  for (const char *a : {"x", "y", "z"}) l.append(a, xyz);
  l.append("intensity", FieldType::UInt8);
  l.append("ring", FieldType::UInt16);
  l.append("normal", FieldType::Float32, 3);
  PointBuffer b(l, n);
  for (std::size_t i = 0; i < n; ++i) {
    writeFromDouble(b.record(i), l.fields[0], double(i % 7) - 3.0);
    writeFromDouble(b.record(i), l.fields[1], double(i % 5) * 2.0);
    writeFromDouble(b.record(i), l.fields[2], double(i) * 0.5);
    writeFromDouble(b.record(i), l.fields[3], double(i % 256));
    writeFromDouble(b.record(i), l.fields[4], double(i % 16));
  }
  return b;
}

}  // namespace

int main(int argc, char **argv) {
  if (argc != 2) {
    std::cerr << "usage: make_seeds DIR\n";
    return 2;
  }
  const fs::path dir = argv[1];
  for (const char *t : {"pcd", "ply", "kitti_bin", "poses", "config_yaml", "map", "cloud_conversion"})
    fs::create_directories(dir / t);

  const SyntheticLidar organized(tinyLidar(true));
  const SyntheticLidar sparse(tinyLidar(false));
  const PointBuffer grid = organized.frame(0).frame.points;
  const PointBuffer cloud = sparse.frame(1).frame.points;

  writePcd((dir / "pcd" / "organized.pcd").string(), grid);
  writePcd((dir / "pcd" / "binary.pcd").string(), cloud);
  writePcd((dir / "pcd" / "typed_f64.pcd").string(), typedCloud(FieldType::Float64, 30));
  writePcd((dir / "pcd" / "typed_i32.pcd").string(), typedCloud(FieldType::Int32, 30));
  writePcd((dir / "pcd" / "empty.pcd").string(), PointBuffer(cloud.layout(), 0));
  writeText(dir / "pcd" / "ascii.pcd", asciiPcd(cloud));
  writeBytes(dir / "pcd" / "compressed.pcd", compressedPcd(cloud));

  writePly((dir / "ply" / "binary.ply").string(), cloud);
  writePly((dir / "ply" / "organized.ply").string(), grid);
  writePly((dir / "ply" / "typed_u8.ply").string(), typedCloud(FieldType::UInt8, 30));
  writeText(dir / "ply" / "ascii.ply", asciiPly(cloud));
  writeBytes(dir / "ply" / "big_endian.ply", bigEndianPly(cloud));

  writeKittiBin((dir / "kitti_bin" / "frame.bin").string(), cloud);
  writeKittiBin((dir / "kitti_bin" / "one.bin").string(), typedCloud(FieldType::Float32, 1));

  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < 5; ++i) poses.push_back(organized.pose(i));
  writeKittiPoses((dir / "poses" / "exact.txt").string(), poses);
  writeText(dir / "poses" / "kitti.txt",
            "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 "
            "3.330669e-16 2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16\n\n"
            "9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 -1.154865e-03 "
            "-2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01\n");
  writeText(dir / "poses" / "tum.txt",
            "# timestamp tx ty tz qx qy qz qw\n1700000000.1 12.5 -3.25 0.75 0 0 0.7071068 0.7071068\n"
            "1700000000.2 13.0 -3.2 0.76 0.0012 -0.0008 0.7082 0.7060\n");

  HpdsConfig config;
  writeText(dir / "config_yaml" / "defaults.yaml", dumpConfigYaml(config));
  config.mode = Mode::Map;
  config.hierarchy.cell_size = 2.5;
  config.hierarchy.max_depth = 12;
  config.order.type = InsertionOrder::Sphericity;
  config.order.seed = 99;
  config.output.level = -1;
  config.output.spacing = 0.2;
  config.normals.enabled = true;
  config.normals.k = 12;
  config.map.evict_distance = 60.0;
  config.map.max_samples = 100000;
  config.input.min_range = 0.5;
  config.input.max_range = 90.0;
  config.threads = 2;
  writeText(dir / "config_yaml" / "everything.yaml", dumpConfigYaml(config));
  writeText(dir / "config_yaml" / "partial.yaml", "mode: map\nhierarchy:\n  max_depth: 6  # comment\nmap: {evict_distance: 30}\n");
  writeText(dir / "config_yaml" / "empty.yaml", "");

  HpdsConfig map_config;
  map_config.mode = Mode::Map;
  map_config.hierarchy.max_depth = 4;
  Pipeline pipeline(map_config);
  for (int i = 0; i < 2; ++i) pipeline.addFrame(sparse.frame(i).frame);
  saveMap((dir / "map" / "small.hpdsmap").string(), pipeline);
  saveHierarchy((dir / "map" / "empty.hpdsmap").string(), Hierarchy(4.0, 8), 0);

  // FuzzedDataProvider input: any bytes are a message; a few varied ones start the corpus off.
  for (int s = 0; s < 4; ++s) {
    std::vector<std::uint8_t> b(64 + 32 * s);
    for (std::size_t i = 0; i < b.size(); ++i) b[i] = static_cast<std::uint8_t>((i * 37 + s * 11) ^ (i >> 2));
    writeBytes(dir / "cloud_conversion" / ("seed" + std::to_string(s)), b);
  }
  std::cout << "seeds written to " << dir.string() << "\n";
  return 0;
}
