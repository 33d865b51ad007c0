// plane_sampling: the paper's figure-5 setting, a dense uniformly random point set on a plane, sampled by the hierarchy.
// Writes OUT/plane_input.ply (x y z) and OUT/plane_sampling.ply (x y z level, all levels up to --level), which
// `hpds analyze OUT/plane_sampling.ply --cell-size 4 --input OUT/plane_input.ply --patch 0,0,12` compares with the
// grid baselines at equal count, free of any lidar scan pattern.
// Usage: plane_sampling [--out DIR] [--points N] [--level L]
#include <filesystem>
#include <iostream>
#include <string>

#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/util/SplitMix64.hpp"
#include "hpds/io/PlyWriter.hpp"

int main(int argc, char **argv) {
  using namespace hpds;
  std::string out = "build/quality";
  std::size_t points = 1'500'000;
  int level = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) out = argv[++i];
    else if (a == "--points" && i + 1 < argc) points = std::stoul(argv[++i]);
    else if (a == "--level" && i + 1 < argc) level = std::stoi(argv[++i]);
    else {
      std::cerr << "usage: plane_sampling [--out DIR] [--points N] [--level L]\n";
      return 2;
    }
  }
  std::filesystem::create_directories(out);
  // 16 m x 16 m centred on the origin, z = 0.3 (inside a cell layer, so the grid baselines are not split in z).
  // splitmix64 keeps the set identical on every platform.
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  Frame frame;
  frame.points = PointBuffer(layout, points);
  std::uint64_t state = 12345;
  auto uniform = [&state] { return unitInterval(splitMix64(state)); };
  for (std::size_t i = 0; i < points; ++i) {
    writeFromDouble(frame.points.record(i), layout.fields[0], 16.0 * uniform() - 8.0);
    writeFromDouble(frame.points.record(i), layout.fields[1], 16.0 * uniform() - 8.0);
    writeFromDouble(frame.points.record(i), layout.fields[2], 0.3);
  }
  HpdsConfig cfg;
  cfg.hierarchy.cell_size = 4.0;
  cfg.hierarchy.max_depth = level;
  cfg.output.level = level;
  Pipeline pipeline(cfg);
  pipeline.addFrame(frame);
  writePly(out + "/plane_input.ply", frame.points);
  const PointBuffer sampling = pipeline.makeCloud(pipeline.outputSamples(), false);
  writePly(out + "/plane_sampling.ply", sampling);
  std::cout << "plane: " << points << " uniform points on 16 m x 16 m, " << sampling.size() << " samples in levels 0.."
            << level << " -> " << out << "/plane_{input,sampling}.ply\n";
  return 0;
}
