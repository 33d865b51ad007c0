// The C++ side of the binding tests: hpds::downsample on a point-cloud file, written raw so that the Python test
// can compare the binding's arrays with the C++ API's bit for bit.
//   downsample_dump INPUT CONFIG.yaml|- OUT
// OUT: u64 n, u8 has_normals, u32 index[n], u8 level[n], then with normals f32 normal[3n], f32 curvature[n].
#include <cstdio>
#include <cstdint>
#include <exception>
#include <vector>

#include "hpds/hpds.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

int main(int argc, char **argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: downsample_dump INPUT CONFIG.yaml|- OUT\n");
    return 2;
  }
  try {
    const hpds::PointBuffer cloud = hpds::readPointCloud(argv[1]);
    const hpds::PointLayout &l = cloud.layout();
    const hpds::PointField *f[3] = {l.find("x"), l.find("y"), l.find("z")};
    std::vector<Eigen::Vector3f> points(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i)
      for (int a = 0; a < 3; ++a) points[i][a] = static_cast<float>(hpds::readAsDouble(cloud.record(i), *f[a]));
    const hpds::HpdsConfig config = std::string(argv[2]) == "-" ? hpds::HpdsConfig{} : hpds::loadConfig(argv[2]);
    const hpds::Samples s = hpds::downsample(points, config);

    std::FILE *out = std::fopen(argv[3], "wb");
    if (!out) throw std::runtime_error(std::string(argv[3]) + ": cannot open");
    const std::uint64_t n = s.size();
    const std::uint8_t has_normals = config.normals.enabled ? 1 : 0;
    bool ok = std::fwrite(&n, sizeof n, 1, out) == 1 && std::fwrite(&has_normals, 1, 1, out) == 1;
    ok = ok && std::fwrite(s.index.data(), sizeof(std::uint32_t), n, out) == n;
    ok = ok && std::fwrite(s.level.data(), 1, n, out) == n;
    if (has_normals) {
      for (const Eigen::Vector3f &v : s.normal) ok = ok && std::fwrite(v.data(), sizeof(float), 3, out) == 3;
      ok = ok && std::fwrite(s.curvature.data(), sizeof(float), n, out) == n;
    }
    ok = std::fclose(out) == 0 && ok;
    if (!ok) throw std::runtime_error(std::string(argv[3]) + ": write failed");
  } catch (const std::exception &e) {
    std::fprintf(stderr, "downsample_dump: %s\n", e.what());
    return 1;
  }
  return 0;
}
