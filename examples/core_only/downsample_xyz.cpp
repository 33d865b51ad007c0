// Downsamples a text file of points ("x y z" per line, metres, sensor frame; `#` starts a comment) with hpds's
// plain one-call API and writes one line per sample: "x y z nx ny nz level" (the normal is "nan nan nan" where
// it could not be estimated).
//   downsample_xyz IN.xyz OUT.xyz [CONFIG.yaml]
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>

#include <hpds/hpds.hpp>

namespace {
// One point per non-blank line; anything else on a line is an error naming the line, not a silently skipped point.
std::vector<Eigen::Vector3f> readXyz(const std::string &path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::vector<Eigen::Vector3f> points;
  std::string line;
  for (std::size_t number = 1; std::getline(in, line); ++number) {
    const std::string data = line.substr(0, line.find('#'));
    std::istringstream fields(data);
    float x, y, z;
    std::string extra;
    if (!(fields >> x)) {
      if (data.find_first_not_of(" \t\r") == std::string::npos) continue;  // blank or comment-only
      throw std::runtime_error(path + ":" + std::to_string(number) + ": expected \"x y z\"");
    }
    if (!(fields >> y >> z) || (fields >> extra))
      throw std::runtime_error(path + ":" + std::to_string(number) + ": expected \"x y z\"");
    points.emplace_back(x, y, z);
  }
  return points;
}
}  // namespace

int main(int argc, char **argv) {
  if (argc < 3 || argc > 4) {
    std::cerr << "usage: downsample_xyz IN.xyz OUT.xyz [CONFIG.yaml]\n";
    return 2;
  }
  namespace fs = std::filesystem;
  const fs::path in = argv[1], out = argv[2];
  std::error_code ec;
  if (fs::equivalent(in, out, ec)) {
    std::cerr << "downsample_xyz: " << out << " is the input\n";
    return 2;
  }
  try {
    const hpds::HpdsConfig config = argc == 4 ? hpds::loadConfig(argv[3]) : hpds::HpdsConfig{};
    const std::vector<Eigen::Vector3f> points = readXyz(in.string());
    const hpds::Samples s = hpds::downsample(points, config);

    // Written beside the target and renamed into place: an interrupted run never leaves a half-written OUT.
    const fs::path tmp = out.string() + ".tmp";
    {
      std::ofstream o(tmp);
      char buf[160];
      for (std::size_t i = 0; i < s.size(); ++i) {
        const Eigen::Vector3f &p = points[s.index[i]];
        const Eigen::Vector3f n = s.normal.empty() ? Eigen::Vector3f::Constant(NAN) : s.normal[i];
        std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g %.6g %.6g %.6g %d\n", p.x(), p.y(), p.z(), n.x(), n.y(), n.z(),
                      int(s.level[i]));
        o << buf;
      }
      o.flush();
      if (!o) throw std::runtime_error("cannot write " + tmp.string());
    }
    fs::rename(tmp, out);
    std::cout << points.size() << " points -> " << s.size() << " samples, written to " << out.string() << "\n";
    return 0;
  } catch (const std::exception &e) {
    std::cerr << "downsample_xyz: " << e.what() << "\n";
    return 1;
  }
}
