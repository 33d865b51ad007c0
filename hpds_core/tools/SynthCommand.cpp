// `hpds synth -o DIR`: writes a synthetic lidar stream (frames + KITTI poses) that `hpds sample` can read back.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include "CliOptions.hpp"
#include "Commands.hpp"
#include "OutputPaths.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"

namespace hpds::cli {

namespace {

// 4 M rays: twice a 128-beam sensor at 0.1 degree, about 100 MB per frame.
constexpr long long kMaxPointsPerFrame = 1 << 22;

struct SynthArgs {
  std::string out_dir;
  std::string format = "pcd";
  std::string scene = "urban";
  SyntheticLidarConfig lidar;
};

SceneKind parseScene(const std::string &s) {
  if (s == "urban") return SceneKind::Urban;
  if (s == "planar_urban") return SceneKind::PlanarUrban;
  if (s == "curved_objects") return SceneKind::CurvedObjects;
  throw std::invalid_argument("--scene: unknown scene '" + s + "' (expected urban, planar_urban or curved_objects)");
}

std::string frameName(int index, const std::string &format) {
  char name[64];
  std::snprintf(name, sizeof name, "frame_%06d.%s", index, format.c_str());
  return name;
}

void runSynth(SynthArgs a) {
  if (a.format != "pcd" && a.format != "bin" && a.format != "ply")
    throw std::invalid_argument("--format: expected pcd, ply or bin, got '" + a.format + "'");
  a.lidar.scene = parseScene(a.scene);
  if (static_cast<long long>(a.lidar.beams) * a.lidar.azimuth_steps > kMaxPointsPerFrame)
    throw std::invalid_argument("--beams x --azimuth-steps: " + std::to_string(a.lidar.beams) + " x " +
                                std::to_string(a.lidar.azimuth_steps) + " rays per frame, more than the " +
                                std::to_string(kMaxPointsPerFrame) + " a synthetic frame may have");
  // Every file the run writes is named to checkPaths: a pipe already in the folder under one of those names would
  // otherwise hold the run (writing a frame or poses.txt blocks until something reads it).
  std::vector<std::string> files;
  for (int i = 0; i < a.lidar.frames; ++i) files.push_back(frameName(i, a.format));
  files.push_back("poses.txt");
  checkPaths({}, {}, {{"-o", a.out_dir, files}});
  const SyntheticLidar lidar(a.lidar);
  RunFolder folder(a.out_dir);
  std::vector<Eigen::Isometry3d> poses;
  std::size_t points = 0;
  for (int i = 0; i < a.lidar.frames; ++i) {
    const SyntheticFrame f = lidar.frame(i);
    writePointCloud((std::filesystem::path(a.out_dir) / frameName(i, a.format)).string(), f.frame.points);
    poses.push_back(f.frame.sensor_to_fixed);
    points += f.frame.points.size();
  }
  const std::string pose_path = (std::filesystem::path(a.out_dir) / "poses.txt").string();
  writeKittiPoses(pose_path, poses);
  folder.keep();
  std::cout << "wrote " << a.lidar.frames << " frames (" << points << " points, scene " << toString(a.lidar.scene)
            << ") and " << pose_path << "\n";
}

}  // namespace

void addSynthCommand(CLI::App &app) {
  auto a = std::make_shared<SynthArgs>();
  CLI::App *cmd = app.add_subcommand("synth", "write a synthetic spinning-lidar stream (frames + KITTI poses)");
  cmd->add_option("-o,--output", a->out_dir, "output directory (frame_NNNNNN.<format> and poses.txt)")->required()
      ->check(nonEmptyPath());
  cmd->add_option("--frames", a->lidar.frames, "number of frames")->capture_default_str()->check(integerIn(1, 100000));
  cmd->add_option("--seed", a->lidar.seed, "scene and noise seed")->capture_default_str()->check(unsigned64());
  cmd->add_option("--scene", a->scene, "urban | planar_urban | curved_objects")->capture_default_str();
  cmd->add_option("--beams", a->lidar.beams, "beams (rings)")->capture_default_str()->check(integerIn(1, 1024));
  cmd->add_option("--azimuth-steps", a->lidar.azimuth_steps, "columns per revolution")
      ->capture_default_str()
      ->check(integerIn(1, 100000));
  cmd->add_option("--speed", a->lidar.speed, "[m per frame] sensor speed")->capture_default_str()->check(finiteIn(-100.0, 100.0));
  cmd->add_option("--noise", a->lidar.range_noise, "[m] range noise sigma")->capture_default_str()->check(finiteIn(0.0, 10.0));
  cmd->add_option("--format", a->format, "pcd | ply | bin (KITTI: x y z intensity only)")->capture_default_str();
  cmd->callback([a] { runSynth(*a); });
}

}  // namespace hpds::cli
