// `hpds sample INPUT... -o OUT.ply`: files in, hierarchy, PLY out.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "CliOptions.hpp"
#include "hpds/io/InputFolders.hpp"
#include "Commands.hpp"
#include "OutputPaths.hpp"
#include "RunReport.hpp"
#include "hpds/config/NodeConfig.hpp"
#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/util/ParallelFor.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/pipeline/ScanFrames.hpp"
#include "hpds/points/FarViewpoint.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"

namespace hpds::cli {

namespace {

struct SampleArgs {
  std::vector<std::string> inputs;
  std::string output;
  std::string poses;
  std::string stats;
  std::string load_map;
  std::string save_map;
  std::vector<double> viewpoint;  // empty: each input's own (a PCD's VIEWPOINT), else the origin
  SamplingOptions sampling;
};

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The file takes the fields of the first frame with samples, as map mode's layout rule does: a recorded drive often
// holds an empty frame (a driver's first message, a blocked sensor) with fewer fields, which has nothing to write.
void appendCloud(PointBuffer &all, const PointBuffer &part, const std::string &input) {
  if (all.layout().point_step == 0 || (all.size() == 0 && part.size() > 0)) {
    all = PointBuffer(part.layout());
  } else if (part.size() == 0) {
    return;
  } else if (all.layout() != part.layout()) {
    throw std::invalid_argument("scan mode writes all frames into one file, but '" + input + "' has other point " +
                                "fields (" + describeFields(part.layout()) + ") than the frames with samples before "
                                "it (" + describeFields(all.layout()) + "): sample such inputs in separate runs");
  }
  all.bytes().insert(all.bytes().end(), part.bytes().begin(), part.bytes().end());
  all.setOrganization(static_cast<std::uint32_t>(all.size()), 1);
}

// Every path this run reads or writes, checked before any work (OutputPaths.hpp).
void checkSamplePaths(const SampleArgs &a) {
  std::vector<InputPath> inputs;
  for (const std::string &in : a.inputs) inputs.push_back({"input", in});
  inputs.push_back({"--poses", a.poses});
  inputs.push_back({"--config", a.sampling.config_file});
  inputs.push_back({"--load-map", a.load_map});
  checkPaths(inputs, {{"-o", a.output, {".ply"}, "PLY"},
                      {"--stats", a.stats, {".json"}, "JSON"},
                      {"--save-map", a.save_map, {}, "an hpds map"}});
}

int runSample(const SampleArgs &a) {
  checkSamplePaths(a);
  HpdsConfig config = resolveConfig(a.sampling);
  // The node's keys this command does not use: checked all the same, as config/hpds.yaml promises.
  if (!a.sampling.config_file.empty()) validateRosSectionOfFile(a.sampling.config_file);
  std::vector<Eigen::Isometry3d> poses;
  if (!a.poses.empty()) {
    poses = readPosesOption(a.poses);
    if (const std::string w = checkPosesMatchInputs(a.poses, poses.size(), a.inputs); !w.empty())
      std::cerr << "hpds: warning: " << w << "\n";
    double largest_translation = 0.0;
    for (const Eigen::Isometry3d &pose : poses)
      largest_translation = std::max(largest_translation, pose.translation().cwiseAbs().maxCoeff());
    if (const std::string note = widenXyzForPoses(config, largest_translation, "--float32-xyz"); !note.empty())
      std::cerr << "hpds: note: " << note << "\n";
  }

  if ((!a.load_map.empty() || !a.save_map.empty()) && config.mode != Mode::Map)
    throw std::invalid_argument("--load-map/--save-map need --mode map (scan mode keeps no map)");
  Pipeline pipeline(config);
  int loaded_deepest = -1;
  std::uint32_t loaded_frames = 0;
  if (!a.load_map.empty()) {
    const std::string normals_warning = loadMap(a.load_map, pipeline);
    loaded_deepest = deepestPopulatedLevel(pipeline.hierarchy());
    loaded_frames = pipeline.framesProcessed();
    for (const std::string &w : {shallowMapWarning(pipeline), normals_warning})
      if (!w.empty()) std::cerr << "hpds: warning: " << w << "\n";
  }
  RunReport report = reportFor("sample", pipeline);

  const bool scan = config.mode == Mode::Scan;
  const bool frame_field = scan && a.inputs.size() > 1;
  // One frame through a pipeline: read, insert, and in scan mode its output cloud.
  // Input fields the output cannot carry (it writes fields of those names), with the first input that had each.
  std::map<std::string, std::string> not_carried;
  std::mutex not_carried_mutex;
  std::atomic<bool> any_viewpoint{false};  // a PCD's VIEWPOINT placed a sensor where no pose did
  // The inputs' own float32 rounding: when it is what rounds the output, float64 output would not help.
  double input_rounding = 0.0;
  std::mutex input_rounding_mutex;
  std::string far_viewpoint;  // the first input whose viewpoint lies far from all its points, said once
  std::mutex far_viewpoint_mutex;
  auto runFrame = [&](Pipeline &p, std::size_t i, StageSeconds &seconds, PointBuffer *cloud) {
    auto t0 = std::chrono::steady_clock::now();
    Frame frame;
    frame.points = readPointCloud(a.inputs[i], &frame.viewpoint);
    if (!a.viewpoint.empty()) frame.viewpoint = Eigen::Vector3d(a.viewpoint[0], a.viewpoint[1], a.viewpoint[2]);
    if (!frame.viewpoint.isZero(0.0)) any_viewpoint = true;
    if (const double d = nearestPointDistance(frame.points, frame.viewpoint); isFarViewpoint(d)) {
      const std::lock_guard<std::mutex> lock(far_viewpoint_mutex);
      if (far_viewpoint.empty()) {
        std::ostringstream w;
        w << farViewpointWarning(a.inputs[i], d, frame.viewpoint);
        if (a.viewpoint.empty())
          w << "the input seems not to be in its sensor's frame; give the sensor's position with --viewpoint X Y Z"
            << (poses.empty() ? " (or the frames' sensor poses with --poses)" : "");
        else
          w << "check --viewpoint: it is the sensor's position in the inputs' own coordinates";
        far_viewpoint = w.str();
      }
    }
    if (const double rounding = positionRounding(frame.points); rounding > 0.0) {
      const std::lock_guard<std::mutex> lock(input_rounding_mutex);
      input_rounding = std::max(input_rounding, rounding);
    }
    for (const std::string &name : fieldsNotCarried(frame.points.layout(), config.normals.enabled,
                                                    config.normals.enabled && config.normals.covariances)) {
      const std::lock_guard<std::mutex> lock(not_carried_mutex);
      not_carried.try_emplace(name, a.inputs[i]);
    }
    frame.stamp = static_cast<double>(i);
    if (!poses.empty()) frame.sensor_to_fixed = poses[i];
    seconds.read += since(t0);
    t0 = std::chrono::steady_clock::now();
    FrameResult r;
    try {
      r = p.addFrame(frame);
    } catch (const std::invalid_argument &e) {
      throw std::invalid_argument("'" + a.inputs[i] + "': " + e.what());
    }
    // Map mode estimates the normals the map keeps inside addFrame: counted as normals, not insertion.
    seconds.insert += since(t0) - r.seconds_normals;
    seconds.normals += r.seconds_normals;
    if (cloud) {
      double normals_s = 0.0;
      *cloud = p.makeCloud(p.outputSamples(), frame_field, &normals_s);
      seconds.normals += normals_s;
    }
    return r.counters;
  };

  PointBuffer output;
  Progress progress(a.inputs.size());
  FrameCounters totals;
  const int threads = resolveThreads(config.threads);
  if (scan && threads > 1 && a.inputs.size() > 1) {
    // Scan-mode frames are independent: each worker runs its own pipeline, numbering frames by input index, so
    // the bytes written are those of a single-threaded run. Stage seconds are summed over workers.
    std::vector<PointBuffer> clouds(a.inputs.size());
    std::vector<FrameCounters> counters(a.inputs.size());
    std::vector<StageSeconds> seconds(a.inputs.size());
    std::mutex progress_mutex;
    std::size_t done = 0;
    forEachScanFrame(config, a.inputs.size(), threads, [&](Pipeline &p, std::size_t i) {
      counters[i] = runFrame(p, i, seconds[i], &clouds[i]);
      const std::lock_guard<std::mutex> lock(progress_mutex);
      progress.step(++done, a.inputs[i]);
    });
    for (std::size_t i = 0; i < a.inputs.size(); ++i) {
      appendCloud(output, clouds[i], a.inputs[i]);
      totals += counters[i];
      report.seconds.read += seconds[i].read;
      report.seconds.insert += seconds[i].insert;
      report.seconds.normals += seconds[i].normals;
    }
  } else {
    for (std::size_t i = 0; i < a.inputs.size(); ++i) {
      progress.step(i + 1, a.inputs[i]);
      PointBuffer cloud;
      runFrame(pipeline, i, report.seconds, scan ? &cloud : nullptr);
      if (scan) appendCloud(output, cloud, a.inputs[i]);
    }
    totals = pipeline.totals();
  }
  progress.finish();
  if (!far_viewpoint.empty()) std::cerr << "hpds: warning: " << far_viewpoint << "\n";
  for (const auto &[name, input] : not_carried)
    std::cerr << "hpds: warning: input field '" << name << "' (of '" << input
              << "' and maybe others) is not in the output: " << fieldNotCarriedReason(name)
              << "; rename the field to keep it\n";
  if (scan) {
    for (std::size_t d = 0; d < report.samples_per_level.size(); ++d) report.samples_per_level[d] = totals.accepted_per_level[d];
  } else {
    for (std::size_t d = 0; d < report.samples_per_level.size(); ++d)
      report.samples_per_level[d] = pipeline.hierarchy().countAtLevel(static_cast<int>(d));
    // makeCloud sets its argument: add to the per-frame normals map mode counted above, not overwrite them.
    double final_normals = 0.0;
    output = pipeline.makeCloud(pipeline.outputSamples(), false, &final_normals);
    report.seconds.normals += final_normals;
  }
  report.frames = a.inputs.size();
  report.totals = totals;
  report.output_points = output.size();
  report.invalid_normals = countInvalidNormals(output);
  report.hierarchy_bytes = pipeline.hierarchy().memUsage();

  // Every output is written and synced under a temporary name first, then all are put in place together: a
  // failure on the way (a full disk) leaves every previous output as it was, never a new cloud beside an old map.
  auto t0 = std::chrono::steady_clock::now();
  AtomicFile ply_file(a.output);
  writePly(ply_file, output, samplingRecordOf(pipeline));
  ply_file.finish();
  std::optional<AtomicFile> map_file;
  if (!a.save_map.empty()) {
    map_file.emplace(a.save_map);
    saveMap(*map_file, pipeline);
    map_file->finish();
  }
  report.seconds.write = since(t0);
  std::optional<AtomicFile> stats_file;
  stageJsonFile(stats_file, a.stats, report);
  ply_file.commit();
  if (map_file) map_file->commit();
  if (stats_file) stats_file->commit();

  std::cout << levelSummary(report);
  std::cout << "wrote " << output.size() << " samples (levels 0.." << report.output_level << ") to " << a.output;
  if (config.normals.enabled) std::cout << ", " << report.invalid_normals << " without a valid normal";
  std::cout << "\n";
  // The input's own rounding counts only as far as the samples reach: points dropped as out of range (a 3e38
  // outlier) made it huge once, and the warning blamed the input for an output that was fine.
  input_rounding = std::min(input_rounding, std::ldexp(largestCoordinate(output), -24));
  if (const std::string w = roundingWarning(output, report.output_radius, config.output, input_rounding); !w.empty())
    std::cerr << w << "\n";
  if (!a.save_map.empty())
    if (const std::string w = shallowSaveWarning(pipeline, loaded_deepest, loaded_frames); !w.empty())
      std::cerr << "hpds: warning: " << w << "\n";
  if (const std::string w = evictionWarning(config, report.totals.evicted, pipeline.hierarchy().sampleCount(),
                                            poses.empty() && !any_viewpoint);
      !w.empty())
    std::cerr << w << "\n";
  if (const std::string w = emptyOutputWarning(output.size(), report.totals); !w.empty()) std::cerr << w << "\n";
  if (report.totals.out_of_range > 0)
    std::cerr << "hpds: warning: " << report.totals.out_of_range
              << " points lie beyond the exact key range and were not inserted: " << keyRangeAdvice(config) << "\n";
  return 0;
}

}  // namespace

void addSampleCommand(CLI::App &app) {
  auto args = std::make_shared<SampleArgs>();
  CLI::App *cmd = app.add_subcommand("sample", "sample point clouds into an additive Poisson-disk hierarchy");
  cmd->add_option("inputs", args->inputs,
                  "input clouds: .pcd, .ply, KITTI .bin (several = a stream of frames); a folder stands for its "
                  ".pcd/.ply/.bin files in natural name order (frame_2 before frame_10), hidden files and hpds's "
                  "own outputs left out")
      ->required();
  cmd->add_option("-o,--output", args->output, "output PLY (binary little-endian)")
      ->required()
      ->check(nonEmptyPath());
  cmd->add_option("--poses", args->poses, "pose file, one sensor-to-world pose per input in order: KITTI (a 3x4 "
                  "matrix per line) or TUM (time x y z qx qy qz qw)");
  cmd->add_option("--viewpoint", args->viewpoint,
                  "[m] X Y Z: the sensor's position in the inputs' own coordinates, for every input (normals face it, "
                  "input.min_range/max_range measure from it); default: a PCD's VIEWPOINT, else the origin")
      ->expected(3)
      ->check(finiteIn(-1e9, 1e9));
  cmd->add_option("--stats", args->stats, "write run statistics as JSON");
  cmd->add_option("--load-map", args->load_map, "map mode: start from a map saved by --save-map (same cell size and depth)");
  cmd->add_option("--save-map", args->save_map, "map mode: save the final map (written atomically) for a later --load-map");
  addSamplingOptions(*cmd, args->sampling);
  cmd->callback([args] {
    args->inputs = expandInputFolders(args->inputs, std::cerr);
    const int rc = runSample(*args);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace hpds::cli
