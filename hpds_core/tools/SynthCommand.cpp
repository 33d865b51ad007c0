// `hpds synth -o DIR [--bag OUT.bag]`: writes a synthetic lidar stream (frames + KITTI poses) that `hpds sample` can
// read back, and with --bag the same frames as a bag for `roslaunch hpds replay.launch` (SynthBag.hpp).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "CliOptions.hpp"
#include "Commands.hpp"
#include "OutputPaths.hpp"
#include "SynthBag.hpp"
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
  SynthBagOptions bag;  ///< bag.path empty: no bag
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

// Found: a second run with fewer frames (or another --format) into the same folder left the first run's extra
// frames beside the new poses.txt, which a later `hpds sample DIR --poses` took as one drive. Those files are not
// this run's to delete, so the run is refused before any work.
void refuseStaleFrames(const std::string &dir, const std::vector<std::string> &files) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return;
  const std::set<std::string> written(files.begin(), files.end());
  std::vector<std::string> stale;
  for (const auto &entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("frame_", 0) == 0 && !written.count(name)) stale.push_back(name);
  }
  if (ec || stale.empty()) return;
  std::sort(stale.begin(), stale.end());
  throw std::invalid_argument("-o: '" + dir + "' holds " + std::to_string(stale.size()) + " frame file(s) this run " +
                              "would not replace (" + stale.front() + (stale.size() > 1 ? ", ..." : "") +
                              "), which would then lie beside a poses.txt that is not theirs: write into an empty "
                              "or new folder (or remove them)");
}

void runSynth(SynthArgs a, SynthBagOpener open_bag) {
  if (!a.bag.path.empty()) {
    // Before any work, as every usage error: a build without ROS has no bag writer.
    if (!open_bag)
      throw std::invalid_argument("--bag: this hpds was built without ROS (rosbag); build it with the ROS node "
                                  "(-DHPDS_BUILD_NODE=ON) to write bags");
    if (a.bag.topic.empty()) throw std::invalid_argument("--topic: empty topic name");
    // tf2 refuses frame ids with ROS 1's leading slash, so the transforms would never match the clouds.
    if (a.bag.frame_id.empty() || a.bag.frame_id.front() == '/')
      throw std::invalid_argument("--frame-id: '" + a.bag.frame_id + "' is not a tf frame id (non-empty, no leading "
                                  "'/')");
  }
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
  // The bag is one more output: never one of the folder's files, whatever links lead there.
  checkPaths({}, {{"--bag", a.bag.path, {".bag"}, "a bag"}}, {{"-o", a.out_dir, files}});
  refuseStaleFrames(a.out_dir, files);
  const SyntheticLidar lidar(a.lidar);
  RunFolder folder(a.out_dir);
  // Under a temporary name until the folder is complete: a failed run leaves an existing bag as it was.
  std::unique_ptr<SynthBagWriter> bag = a.bag.path.empty() ? nullptr : open_bag(a.bag);
  std::vector<Eigen::Isometry3d> poses;
  std::size_t points = 0;
  for (int i = 0; i < a.lidar.frames; ++i) {
    const SyntheticFrame f = lidar.frame(i);
    writePointCloud(folder.file(frameName(i, a.format)), f.frame.points);
    poses.push_back(f.frame.sensor_to_fixed);
    if (bag) bag->write(f.frame);
    points += f.frame.points.size();
  }
  writeKittiPoses(folder.file("poses.txt"), poses);
  // The folder's files and the bag go in place together, after everything is written.
  if (bag) bag->finish();
  folder.keep();
  if (bag) bag->commit();
  const std::string pose_path = (std::filesystem::path(a.out_dir) / "poses.txt").string();
  std::cout << "wrote " << a.lidar.frames << " frames (" << points << " points, scene " << toString(a.lidar.scene)
            << ") and " << pose_path << "\n";
  if (bag)
    std::cout << "wrote " << a.bag.path << " (" << a.bag.topic << " in frame " << a.bag.frame_id << ", /tf "
              << kSynthBagFixedFrame << " -> " << a.bag.frame_id << ")\n";
}

}  // namespace

void addSynthCommand(CLI::App &app, SynthBagOpener open_bag) {
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
  // Offered in every build, so that a build without ROS says why it cannot rather than not knowing the flag.
  const char *bag_help = open_bag ? "also write the frames as a ROS bag (PointCloud2 + /tf odom -> frame) for "
                                    "replay.launch"
                                  : "ROS bag output: not in this build (built without ROS)";
  CLI::Option *bag = cmd->add_option("--bag", a->bag.path, bag_help)->check(nonEmptyPath());
  cmd->add_option("--topic", a->bag.topic, "--bag: PointCloud2 topic")->capture_default_str()->needs(bag);
  cmd->add_option("--frame-id", a->bag.frame_id, "--bag: the clouds' frame (tf child of odom)")
      ->capture_default_str()
      ->needs(bag);
  cmd->callback([a, open_bag] { runSynth(*a, open_bag); });
}

}  // namespace hpds::cli
