#include "FuzzSupport.hpp"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds::fuzz {
namespace {

namespace fs = std::filesystem;

struct TempDir {
  TempDir() {
    const fs::path base = fs::is_directory("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    std::string pattern = (base / "hpds_fuzz_XXXXXX").string();
    if (!::mkdtemp(pattern.data())) {
      std::perror("mkdtemp");
      std::abort();
    }
    path = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  fs::path path;
};

const fs::path &tempDir() {
  static TempDir dir;
  return dir.path;
}

}  // namespace

std::string writeTemp(const std::string &name, const std::uint8_t *data, std::size_t size) {
  const fs::path p = tempDir() / name;
  std::FILE *f = std::fopen(p.c_str(), "wb");
  if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
    std::perror("writeTemp");
    std::abort();
  }
  return p.string();
}

void violated(const std::string &what) {
  std::fprintf(stderr, "invariant violated: %s\n", what.c_str());
  std::abort();
}

void exercise(const PointBuffer &cloud) {
  if (cloud.size() != std::size_t(cloud.width()) * cloud.height()) violated("size != width * height");
  // Readers promise single-valued x/y/z (fuzz_pcd once found a COUNT 2 x accepted and then lost by the PLY writer).
  for (const char *axis : {"x", "y", "z"}) {
    const PointField *f = cloud.layout().find(axis);
    if (!f || f->count != 1) violated(std::string("accepted cloud without a single-valued ") + axis);
  }
  HpdsConfig config;
  config.mode = Mode::Map;
  config.hierarchy.max_depth = 5;
  config.normals.enabled = true;
  config.map.max_samples = 2000;
  Pipeline pipeline(config);
  Frame frame;
  frame.points = cloud;
  // Twice: the second pass meets the first one's samples (map-mode conflict checks against finer levels).
  const FrameResult r = pipeline.addFrame(frame);
  pipeline.addFrame(frame);
  if (r.counters.accepted + r.counters.skipped_invalid + r.counters.skipped_zero + r.counters.skipped_range +
          r.counters.out_of_range + r.counters.dropped_depth !=
      cloud.size())
    violated("frame counters do not add up to the input size");
  const PointBuffer out = pipeline.makeCloud(pipeline.outputSamples(), false);
  if (out.size() > 2 * cloud.size()) violated("more samples than offered points");

  // What a reader returned must survive the writer and come back with the same point count. writePly refuses, at
  // once, field names PLY cannot express and counts or headers beyond what the readers accept (documented refusals).
  const std::string ply = (tempDir() / "roundtrip.ply").string();
  try {
    writePly(ply, cloud);
  } catch (const std::runtime_error &) {
    return;
  }
  PointBuffer back;
  try {
    back = readPointCloud(ply);
  } catch (const std::runtime_error &e) {
    violated(std::string("writePly wrote a file readPointCloud refuses: ") + e.what());
  }
  if (back.size() != cloud.size()) violated("PLY round trip changed the point count");
}

int fuzzPointFile(const std::uint8_t *data, std::size_t size, const char *extension) {
  const std::string path = writeTemp(std::string("input") + extension, data, size);
  PointBuffer cloud;
  try {
    cloud = readPointCloud(path);
  } catch (const std::runtime_error &) {
    return 0;
  }
  exercise(cloud);
  return 0;
}

}  // namespace hpds::fuzz
