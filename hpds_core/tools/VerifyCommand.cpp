// `hpds verify SAMPLING.ply [--cell-size C | --spacing S] [--max-depth M] [--input INPUT...] [--poses P]
// [--frame K]`: an independent check of a written sampling (k-d trees, not the sampler's grids). Prints a per-level
// table; exit code 1 on any violation. A scan-mode output of several frames is checked frame by frame.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <map>
#include <utility>
#include <stdexcept>

#include "CliOptions.hpp"
#include "Commands.hpp"
#include "hpds/io/InputFolders.hpp"
#include "hpds/eval/SamplingVerifier.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds::cli {

namespace {
struct VerifyArgs {
  std::string sampling;
  CellSizeOptions cell;
  std::vector<std::string> inputs;
  std::string poses;
  long long frame = -1;  // -1: every frame
  int threads = 1;
};

/// The samples of a scan-mode output of several frames (field `frame`) by frame value, in increasing order; the
/// whole sampling as one entry when it has no such field.
std::map<std::uint64_t, PointBuffer> byFrame(PointBuffer sampling) {
  std::map<std::uint64_t, PointBuffer> frames;
  const PointField *f = sampling.layout().find("frame");
  if (!f) {
    frames.emplace(0, std::move(sampling));
    return frames;
  }
  for (std::size_t i = 0; i < sampling.size(); ++i) {
    const double v = readAsDouble(sampling.record(i), *f);
    if (!(v >= 0.0 && v < 18446744073709551616.0 && v == std::floor(v)))
      throw std::invalid_argument("sample " + std::to_string(i) + " has frame " + std::to_string(v) +
                                  ", expected a non-negative integer");
    auto it = frames.try_emplace(static_cast<std::uint64_t>(v), sampling.layout(), 0).first;
    it->second.pushBack(sampling.record(i));
  }
  return frames;
}
// The inputs as the sampling saw them, in one cloud of float64 x y z: each posed by its pose (none: as they are).
// NaN/Inf and exact (0,0,0) no-returns are left out before posing, as hpds sample skips them: posed, a no-return
// would land on the sensor and read as an uncovered point.
PointBuffer posedInputs(const std::vector<std::string> &paths, const std::vector<Eigen::Isometry3d> &poses) {
  PointLayout layout;
  for (const char *axis : {"x", "y", "z"}) layout.append(axis, FieldType::Float64);
  PointBuffer all(layout, 0);
  for (std::size_t k = 0; k < paths.size(); ++k) {
    const PointBuffer cloud = readPointCloud(paths[k]);
    const PointField *f[3] = {cloud.layout().find("x"), cloud.layout().find("y"), cloud.layout().find("z")};
    if (!f[0] || !f[1] || !f[2]) throw std::invalid_argument("--input '" + paths[k] + "': no x/y/z fields");
    std::uint8_t rec[24];
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      Eigen::Vector3d p;
      for (int a = 0; a < 3; ++a) p[a] = readAsDouble(cloud.record(i), *f[a]);
      if (!p.allFinite() || p.isZero(0.0)) continue;
      if (!poses.empty()) p = poses[k] * p;
      std::memcpy(rec, p.data(), sizeof rec);
      all.pushBack(rec);
    }
  }
  return all;
}
}  // namespace

void addVerifyCommand(CLI::App &app) {
  auto a = std::make_shared<VerifyArgs>();
  CLI::App *cmd = app.add_subcommand("verify", "check a sampling: one sample per cell, additive spacing, coverage");
  // Not ->required(): checked in the callback, where a SAMPLING taken by a greedy --input can be said.
  cmd->add_option("sampling", a->sampling, "required: the sampling written by hpds sample (needs x y z level)");
  addCellSizeOptions(*cmd, a->cell, true);
  cmd->add_option("--input", a->inputs,
                  "input cloud(s) or folder(s) the sampling was made from: also check coverage <= 2 r_D (a map's "
                  "frames are checked together; a scan-mode output's frame K against input K)");
  cmd->add_option("--poses", a->poses,
                  "the pose file the sampling was made with (hpds sample --poses): each --input is posed by "
                  "its line, or with --frame K by line K");
  cmd->add_option("--frame", a->frame,
                  "a scan-mode output of several frames (field 'frame'): check only this frame (-1 = each frame "
                  "on its own; --input needs one frame)")
      ->capture_default_str()
      ->check(integerIn(-1, 4294967295));
  cmd->add_option("--threads", a->threads, "worker threads, 0 = all cores")->capture_default_str()->check(integerIn(0, 1024));
  cmd->callback([a, cmd] {
    if (a->sampling.empty() && a->inputs.empty())
      throw CLI::ValidationError("SAMPLING is required: the output of hpds sample to check");
    if (a->sampling.empty())
      throw CLI::ValidationError("SAMPLING is missing: --input takes every path after it, so '" + a->inputs.back() +
                                 "' was read as an input; give SAMPLING first: hpds verify SAMPLING --input INPUT...");
    a->inputs = expandInputFolders(a->inputs, std::cerr);
    const double cell_size = resolveSamplingCell(a->cell, a->sampling, cmd->count("--max-depth") > 0);
    if (a->cell.recorded_level)
      std::cout << "as its header records: level-0 cell " << cell_size << " m, max_depth " << a->cell.max_depth
                << ", output level " << *a->cell.recorded_level << "\n";
    // A scan-mode output of several frames holds one sampling per frame (each frame sampled on its own): each is
    // checked on its own, as the sampler made it.
    PointBuffer all = readPointCloud(a->sampling);
    // Checked here, where the file can be named: a raw scan given by mistake is the usual cause.
    if (!all.layout().find("level"))
      throw std::invalid_argument(a->sampling +
                                  ": no 'level' field, so not a sampling written by hpds sample (verify checks "
                                  "hpds sample's output; give it that, and the scan as --input)");
    const PointField &lf = *all.layout().find("level");
    double max_level = -1.0;
    for (std::size_t i = 0; i < all.size(); ++i) max_level = std::max(max_level, readAsDouble(all.record(i), lf));
    // A --spacing with another --max-depth than the sampling's derives another cell, against which a sampling can
    // pass unchecked (its radii all shrunk): a level deeper than that cell's output level gives it away.
    if (const int deepest = deepestLevelFor(a->cell); deepest >= 0 && max_level > deepest) {
      if (a->cell.recorded_level)
        throw std::invalid_argument(a->sampling + ": holds level " +
                                    std::to_string(static_cast<long long>(max_level)) +
                                    ", but its header records levels 0.." + std::to_string(deepest));
      throw std::invalid_argument(
          a->sampling + ": holds level " + std::to_string(static_cast<long long>(max_level)) + ", but --spacing " +
          std::to_string(*a->cell.spacing) + " with --max-depth " + std::to_string(a->cell.max_depth) +
          " makes samplings of levels 0.." + std::to_string(deepest) +
          ": give the --spacing and --max-depth it was sampled with (or its --cell-size)");
    }
    // The depth whose cells bound the coordinates the sampler inserted: --input points beyond were never inserted,
    // and counted as uncovered they failed a sampling that did all it could. hpds sample's default depth unless
    // given; a sampling holding deeper levels was built at least that deep.
    // Levels beyond 21 are no sampler's: the verifier names the sample.
    int key_depth = a->cell.max_depth;
    if (a->cell.cell_size && max_level <= 21.0) {
      const int present = static_cast<int>(max_level);
      if (cmd->count("--max-depth") == 0) {
        key_depth = std::max(key_depth, present);
      } else if (present > key_depth) {
        throw std::invalid_argument(a->sampling + ": holds level " + std::to_string(present) +
                                    ", deeper than --max-depth " + std::to_string(key_depth) +
                                    ": give the --max-depth it was sampled with");
      }
    }
    const bool several = all.layout().find("frame") != nullptr;
    const PointLayout sampling_layout = all.layout();
    std::map<std::uint64_t, PointBuffer> frames = byFrame(std::move(all));
    if (a->frame >= 0) {
      if (!several) throw std::invalid_argument("--frame: '" + a->sampling + "' has no 'frame' field");
      const auto it = frames.find(static_cast<std::uint64_t>(a->frame));
      if (it == frames.end())
        throw std::invalid_argument("--frame: '" + a->sampling + "' holds no sample of frame " +
                                    std::to_string(a->frame));
      PointBuffer one = std::move(it->second);
      frames.clear();
      frames.emplace(static_cast<std::uint64_t>(a->frame), std::move(one));
    } else if (several && a->inputs.size() == 1 && frames.size() > 1) {
      throw std::invalid_argument("--input: '" + a->sampling + "' holds " + std::to_string(frames.size()) +
                                  " scan-mode frames (field 'frame'), each sampled from its own input: give every "
                                  "input in order (frame K is input K), or check one with --frame K");
    }
    // A scan-mode output of several frames against all its inputs: frame K was sampled from input K (posed by line K).
    const bool per_frame = several && a->frame < 0 && a->inputs.size() > 1;
    if (per_frame) {
      for (const auto &[frame, samples] : frames)
        if (frame >= a->inputs.size())
          throw std::invalid_argument("--input: '" + a->sampling + "' holds frame " + std::to_string(frame) + ", but " +
                                      std::to_string(a->inputs.size()) + " inputs were given (frame K is input K)");
      // An input whose frame left no sample must still be covered: checked against an empty sampling.
      for (std::size_t k = 0; k < a->inputs.size(); ++k)
        frames.try_emplace(k, sampling_layout, 0);
    }
    std::vector<Eigen::Isometry3d> poses;
    if (!a->poses.empty()) {
      if (a->inputs.empty()) throw std::invalid_argument("--poses: give the --input frames it poses");
      poses = readPosesOption(a->poses);
      if (a->frame >= 0) {
        // A scan-mode output: frame K was sampled from one input posed by line K.
        if (a->inputs.size() != 1)
          throw std::invalid_argument("--frame: one --input, the frame's, posed by line " + std::to_string(a->frame) +
                                      " of --poses");
        if (static_cast<std::size_t>(a->frame) >= poses.size())
          throw std::invalid_argument("--poses: '" + a->poses + "' has " + std::to_string(poses.size()) +
                                      " poses, none for frame " + std::to_string(a->frame));
        poses = {poses[static_cast<std::size_t>(a->frame)]};
      } else if (const std::string w = checkPosesMatchInputs(a->poses, poses.size(), a->inputs); !w.empty()) {
        std::cerr << "hpds: warning: " << w << "\n";
      }
    } else if (a->frame >= 0 && a->inputs.size() > 1) {
      throw std::invalid_argument("--frame: one --input, the frame's");
    }
    const bool with_input = !a->inputs.empty();
    PointBuffer input;
    if (with_input && !per_frame) input = posedInputs(a->inputs, poses);
    // The levels the sampling must reach: --spacing names its output level, and a sampling that stops short of it
    // (its finest levels missing) leaves the input uncovered at that spacing. With --cell-size only the levels
    // present are known; an input must then be covered at level 0 at least, which an empty sampling is not.
    const int implied = deepestLevelFor(a->cell);
    const int through = implied >= 0 ? implied : (with_input ? 0 : -1);
    std::size_t bad = 0, bad_frames = 0;
    for (const auto &[frame, sampling] : frames) {
      VerifyReport report;
      try {
        if (per_frame) {
          const std::size_t k = static_cast<std::size_t>(frame);
          std::vector<Eigen::Isometry3d> pose;
          if (!poses.empty()) pose.push_back(poses[k]);
          input = posedInputs({a->inputs[k]}, pose);
        }
        report = verifySampling(sampling, cell_size, with_input ? &input : nullptr, a->threads, key_depth, through);
      } catch (const std::invalid_argument &e) {
        // The verifier knows no file names; its complaints are about the sampling's content.
        std::string why = e.what();
        const std::string prefix = "verifySampling: ";
        if (why.compare(0, prefix.size(), prefix) == 0) why.erase(0, prefix.size());
        throw std::invalid_argument(a->sampling + ": " + why);
      }
      const std::size_t v = report.total_violations();
      // One frame's table, or each failing frame's when there are several.
      if (frames.size() == 1 || v > 0) {
        if (several) std::cout << "frame " << frame << ":\n";
        std::cout << formatReport(report);
      }
      bad += v;
      bad_frames += v > 0 ? 1 : 0;
      // Without an input nothing can fail there, but a sampling asked for --spacing that holds none of its finest
      // levels is not what that spacing gives.
      if (!with_input && implied >= 0 && !report.levels.empty() && report.levels.back().union_count > 0 &&
          report.levels.back().count == 0)
        std::cout << "note: level " << implied
                  << (a->cell.recorded_level ? " (the output level its header records)" : " (the level --spacing gives)")
                  << " holds no sample"
                  << (several ? " in frame " + std::to_string(frame) : std::string())
                  << ": the sampling may stop short of that spacing; give --input to check its coverage\n";
      if (report.levels.empty() || report.levels.back().union_count == 0)
        std::cout << "note: " << (several ? "frame " + std::to_string(frame) + " of " : std::string())
                  << "the sampling holds no sample"
                  << (with_input ? "" : ": give --input to check it against the input") << "\n";
    }
    if (frames.size() > 1)
      std::cout << frames.size() << " frames checked on their own, " << bad_frames << " with violations\n";
    if (bad > 0) {
      std::cout << "FAILED: " << bad << " violations\n";
      throw CLI::RuntimeError(1);
    }
    std::cout << "OK: no violations\n";
  });
}

}  // namespace hpds::cli
