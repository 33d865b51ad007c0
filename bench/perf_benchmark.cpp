// Performance against the tools users would pick instead, measured in one process on the same data:
// hierarchy build vs PCL VoxelGrid / UniformSampling, normals vs PCL NormalEstimation(OMP), the per-frame path,
// downsampling and the frame path with valid normals vs small_gicp on 1 and 2 threads (SmallGicpRows.cpp), the
// shipped defaults against the sensor period, map mode over a long synthetic stream, and 1 vs 2 threads. Prints a
// table of medians and ratios and writes JSON. Never fails on timing: ratios are reported, not asserted (the machines
// here are shared and noisy).
#include <pcl/PCLPointCloud2.h>
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/features/normal_3d.h>
#include <pcl/features/normal_3d_omp.h>
#include <pcl/filters/uniform_sampling.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "BenchTiming.hpp"
#include "FramePath.hpp"
#include "SmallGicpRows.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/pipeline/ScanFrames.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl/PclCloud.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/util/FrameMemory.hpp"

namespace {

using namespace hpds;
using namespace bench;

struct Options {
  std::string data_dir = "../shared/data/lidar";
  std::string json = "build/bench/perf.json";
  int repeats = 5;
  int level = 5;             // output level D
  double cell_size = 4.0;    // level-0 edge, as the default config
  std::size_t stream_points = 5'000'000;
  std::string only;  // "frames" or "stream": one half of the table (e.g. the thread row on an otherwise idle machine)
  std::string peers = "both";  // "pcl", "small_gicp" or "both": whose rows to run
  std::vector<std::string> frames;  // real frames to run (file names); empty = every sensor's
  [[nodiscard]] LevelSetting setting() const { return LevelSetting{level, cell_size}; }
};

pcl::PointCloud<pcl::PointXYZ>::Ptr toPcl(const PointBuffer &b) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr c(new pcl::PointCloud<pcl::PointXYZ>);
  const PointLayout &l = b.layout();
  const PointField *fx = l.find("x"), *fy = l.find("y"), *fz = l.find("z");
  c->reserve(b.size());
  for (std::size_t i = 0; i < b.size(); ++i) {
    const float x = static_cast<float>(readAsDouble(b.record(i), *fx)), y = static_cast<float>(readAsDouble(b.record(i), *fy)),
                z = static_cast<float>(readAsDouble(b.record(i), *fz));
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z) || (x == 0 && y == 0 && z == 0)) continue;
    c->push_back(pcl::PointXYZ(x, y, z));
  }
  c->width = static_cast<std::uint32_t>(c->size());
  c->height = 1;
  return c;
}

/// Whether PCL's VoxelGrid at `leaf` would overflow its 32-bit voxel indices on this message: its own check, the
/// product of the voxel counts per axis over the bounding box its getMinMax3D finds. VoxelGrid<PointXYZ> then returns
/// the input; VoxelGrid<PCLPointCloud2> warns and carries on with wrapped indices, merging unrelated voxels.
bool voxelIndicesOverflow(const pcl::PCLPointCloud2::ConstPtr &message, double leaf) {
  Eigen::Vector4f lo, hi;
  pcl::getMinMax3D(message, pcl::getFieldIndex(*message, "x"), pcl::getFieldIndex(*message, "y"),
                   pcl::getFieldIndex(*message, "z"), lo, hi);
  const float inv = 1.0f / static_cast<float>(leaf);
  double cells = 1.0;
  for (int a = 0; a < 3; ++a) cells *= std::floor(double((hi[a] - lo[a]) * inv)) + 1.0;
  return cells > 2147483647.0;
}

HpdsConfig scanConfig(const Options &o, int threads) {
  HpdsConfig c;
  c.hierarchy.cell_size = o.cell_size;
  c.hierarchy.max_depth = o.level;  // build up to the output level only, as a live downsampler would
  c.output.level = o.level;
  c.threads = threads;
  // The plain estimator: the same radius neighbourhood PCL gets (the default refinements widen it).
  c.normals.neighborhood_level_offset = 0;
  c.normals.max_growth = 1.0;
  return c;
}

/// One frame: build, normals, threads.
void benchFrame(const Options &o, const std::string &name, const Frame &frame) {
  const double leaf = cellEdge(o.cell_size, o.level), radius = poissonRadius(o.cell_size, o.level);
  const auto cloud = toPcl(frame.points);
  const pcl::PCLPointCloud2::ConstPtr message(new pcl::PCLPointCloud2(toPclCloud2(frame.points)));
  const bool pcl_overflow = voxelIndicesOverflow(message, leaf);

  // Hierarchy build up to D vs VoxelGrid(c_D) and UniformSampling(r_D).
  // Scan mode keeps one pipeline across frames (the node, `hpds sample`): its arrays and grids are reused. A fresh
  // pipeline per frame also pays their first allocation; both are reported.
  std::size_t hpds_count = 0;
  Pipeline reused(scanConfig(o, 1));
  const auto build = [&] { hpds_count = reused.addFrame(frame).counters.accepted; };
  const double t_build_fresh = medianSeconds(o.repeats, [&] {
    Pipeline p(scanConfig(o, 1));
    hpds_count = p.addFrame(frame).counters.accepted;
  });
  char fresh_note[64];
  std::snprintf(fresh_note, sizeof fresh_note, "[fresh pipeline: %.2f ms]", t_build_fresh * 1e3);
  std::size_t vg_count = 0;
  const Paired t_vg = pairedMedians(o.repeats, build, [&] {
    pcl::VoxelGrid<pcl::PointXYZ> vg;
    vg.setInputCloud(cloud);
    vg.setLeafSize(static_cast<float>(leaf), static_cast<float>(leaf), static_cast<float>(leaf));
    pcl::PointCloud<pcl::PointXYZ> out;
    vg.filter(out);
    vg_count = out.size();
  });
  report(name, "build to level " + std::to_string(o.level) + " (" + std::to_string(hpds_count) + ")", t_vg,
         "VoxelGrid c_D (" + std::to_string(vg_count) + ")",
         std::string(fresh_note) + (pcl_overflow ? " [VoxelGrid overflowed: no-op]" : ""));
  // What the pcl_ros VoxelGrid nodelet runs: VoxelGrid<PCLPointCloud2> on the message as it arrives, every field
  // averaged per voxel. hpds keeps every field too (each sample is one real point with its record); the row above,
  // x/y/z only, is the stricter peer.
  std::size_t vg_msg_count = 0;
  const Paired t_vg_msg = pairedMedians(o.repeats, build, [&] {
    pcl::VoxelGrid<pcl::PCLPointCloud2> vg;
    vg.setInputCloud(message);
    vg.setLeafSize(static_cast<float>(leaf), static_cast<float>(leaf), static_cast<float>(leaf));
    pcl::PCLPointCloud2 out;
    vg.filter(out);
    vg_msg_count = std::size_t(out.width) * out.height;
  });
  report(name, "build to level " + std::to_string(o.level), t_vg_msg,
         "VoxelGrid msg, all fields (" + std::to_string(vg_msg_count) + ")",
         std::to_string(message->fields.size()) + " fields, as the pcl_ros nodelet" +
             (pcl_overflow ? " [VoxelGrid index overflow: voxels merged, time not comparable]" : ""));
  std::size_t us_count = 0;
  const Paired t_us = pairedMedians(o.repeats, build, [&] {
    pcl::UniformSampling<pcl::PointXYZ> us;
    us.setInputCloud(cloud);
    us.setRadiusSearch(radius);
    pcl::PointCloud<pcl::PointXYZ> out;
    us.filter(out);
    us_count = out.size();
  });
  report(name, "build to level " + std::to_string(o.level), t_us, "UniformSampling r_D (" + std::to_string(us_count) + ")");

  // Normals on the same sample set and neighbourhood (radius 2.5 r_D).
  Pipeline p(scanConfig(o, 1));
  p.addFrame(frame);
  const std::vector<SampleId> ids = p.outputSamples();
  pcl::PointCloud<pcl::PointXYZ>::Ptr samples(new pcl::PointCloud<pcl::PointXYZ>);
  for (SampleId id : ids) {
    const double *q = p.hierarchy().position(id);
    samples->push_back(pcl::PointXYZ(static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2])));
  }
  for (int threads : {1, 2}) {
    NormalParams np = normalParamsFor(scanConfig(o, threads), o.level);
    const Paired t_n = pairedMedians(o.repeats, [&] { (void)estimateNormals(p.hierarchy(), ids, np); }, [&] {
      pcl::PointCloud<pcl::Normal> normals;
      pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
      if (threads == 1) {
        pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
        ne.setInputCloud(samples);
        ne.setSearchMethod(tree);
        ne.setRadiusSearch(np.radius);
        ne.compute(normals);
      } else {
        pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne(threads);
        ne.setInputCloud(samples);
        ne.setSearchMethod(tree);
        ne.setRadiusSearch(np.radius);
        ne.compute(normals);
      }
    });
    report(name, "normals, " + std::to_string(threads) + " thread(s) (" + std::to_string(ids.size()) + ")", t_n,
           threads == 1 ? "NormalEstimation" : "NormalEstimationOMP(2)");
  }

  // Whole per-frame path of the node: message bytes in, insert, normals, message bytes out, on one pipeline kept
  // across frames as the node keeps it. PCL's: the same message through pcl_conversions' fromPCLPointCloud2,
  // VoxelGrid, NormalEstimation, the points and normals concatenated and converted back (what a pcl_ros chain
  // publishes). The no-return (0,0,0) points stay in PCL's input, as in the message: one extra voxel.
  HpdsConfig full = scanConfig(o, 1);
  full.normals.enabled = true;
  Pipeline node_pipeline(full);
  std::size_t sink = 0;
  // The frame as a driver publishes it, every field included, as pcl_conversions hands it to PCL.
  const Paired t_path = pairedMedians(o.repeats, [&] { sink += nodePath(node_pipeline, frame).points; }, [&] {
    pcl::PointCloud<pcl::PointXYZ>::Ptr in(new pcl::PointCloud<pcl::PointXYZ>);
    pcl::fromPCLPointCloud2(*message, *in);
    pcl::VoxelGrid<pcl::PointXYZ> vg;
    vg.setInputCloud(in);
    vg.setLeafSize(static_cast<float>(leaf), static_cast<float>(leaf), static_cast<float>(leaf));
    pcl::PointCloud<pcl::PointXYZ>::Ptr out(new pcl::PointCloud<pcl::PointXYZ>);
    vg.filter(*out);
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
    ne.setInputCloud(out);
    ne.setSearchMethod(tree);
    ne.setRadiusSearch(2.5 * radius);
    pcl::PointCloud<pcl::Normal> normals;
    ne.compute(normals);
    pcl::PointCloud<pcl::PointNormal> with_normals;
    pcl::concatenateFields(*out, normals, with_normals);
    pcl::PCLPointCloud2 out_msg;
    pcl::toPCLPointCloud2(with_normals, out_msg);
    sink += out_msg.data.size();
  });
  if (sink == 0) std::printf("(no output)\n");
  report(name, "frame path: msg->insert+normals->msg", t_path, "conv+VoxelGrid+NormalEst+conv",
         pcl_overflow ? "[VoxelGrid overflowed and passed the frame through: PCL's normals ran on every point]" : "");

}

/// The node's frame path with HpdsConfig's defaults (config/hpds.yaml, what a user gets out of the box), held against
/// the 100 ms period of a 10 Hz sensor on one thread.
void benchShippedDefaults(const Options &o, const std::string &name, const Frame &frame) {
  const HpdsConfig shipped;
  Pipeline pipeline(shipped);
  NodePathRun last;
  const double t = medianSeconds(o.repeats, [&] { last = nodePath(pipeline, frame); });
  last = nodePath(pipeline, frame, true);
  std::ostringstream note;
  note.precision(3);
  note << last.points << " points out (level " << pipeline.outputLevel() << ", r = " << pipeline.hierarchy().radius(pipeline.outputLevel())
       << " m, built to level " << pipeline.buildDepth() << "), normals ";
  if (shipped.normals.enabled)
    note << "on, " << 100.0 * double(last.valid_normals) / double(std::max<std::size_t>(1, last.points)) << " % valid";
  else
    note << "off";
  note << "; last run: insert " << last.insert_s * 1e3 << " ms, normals " << last.normals_s * 1e3 << " ms";
  report(name, "shipped defaults, frame path, 1 thread", Paired{t, 0.1, t / 0.1}, "sensor period (10 Hz)", note.str());
}

void benchStream(const Options &o) {
  SyntheticLidarConfig lc;
  lc.frames = static_cast<int>((o.stream_points + 57599) / 57600);
  lc.speed = 1.5;
  lc.yaw_rate = 0.01;
  const SyntheticLidar lidar(lc);
  std::vector<Frame> frames;
  std::size_t total = 0;
  for (int i = 0; i < lc.frames; ++i) {
    frames.push_back(lidar.frame(i).frame);
    total += frames.back().points.size();
  }
  const std::string name = "synthetic " + std::to_string(total / 1000) + "k pts";
  std::vector<pcl::PointCloud<pcl::PointXYZ>::Ptr> clouds;
  for (const auto &f : frames) clouds.push_back(toPcl(f.points));
  if (o.peers != "pcl" && smallGicpAvailable()) benchSmallGicp(o.setting(), o.repeats, name, frames);
  if (o.peers == "small_gicp") return;
  const double leaf = cellEdge(o.cell_size, o.level);
  const int reps = o.repeats;
  const Paired t_build = pairedMedians(reps, [&] {
    Pipeline p(scanConfig(o, 1));
    for (const auto &f : frames) p.addFrame(f);
  }, [&] {
    for (const auto &c : clouds) {
      pcl::VoxelGrid<pcl::PointXYZ> vg;
      vg.setInputCloud(c);
      vg.setLeafSize(static_cast<float>(leaf), static_cast<float>(leaf), static_cast<float>(leaf));
      pcl::PointCloud<pcl::PointXYZ> out;
      vg.filter(out);
    }
  });
  report(name, "scan mode, every frame to level " + std::to_string(o.level), t_build, "VoxelGrid c_D per frame");

  // 1 vs 2 threads on the same stream (frame-parallel scan mode), and the outputs compared byte for byte.
  auto runThreads = [&](int threads, std::vector<std::vector<std::uint8_t>> *out) {
    if (out) out->assign(frames.size(), {});
    forEachScanFrame(scanConfig(o, 1), frames.size(), threads, [&](Pipeline &p, std::size_t i) {
      p.addFrame(frames[i]);
      if (out) (*out)[i] = p.makeCloud(p.outputSamples(), true).bytes();
    });
  };
  std::vector<std::vector<std::uint8_t>> out1, out2;
  runThreads(1, &out1);
  runThreads(2, &out2);
  const Paired t_threads = pairedMedians(reps, [&] { runThreads(2, nullptr); }, [&] { runThreads(1, nullptr); });
  report(name, "scan mode, 2 threads vs 1 thread", t_threads, "hpds 1 thread",
         out1 == out2 ? "[outputs identical]" : "[OUTPUTS DIFFER]");

  // Map mode: frames per second and hierarchy bytes per stored sample.
  HpdsConfig mc = scanConfig(o, 1);
  mc.mode = Mode::Map;
  mc.map.evict_distance = 60.0;
  std::size_t samples = 0, bytes = 0, scratch = 0;
  const double t_map = medianSeconds(reps, [&] {
    Pipeline p(mc);
    for (const auto &f : frames) p.addFrame(f);
    samples = p.hierarchy().sampleCount();
    bytes = p.hierarchy().memUsage();
    scratch = p.memUsage() - bytes;
  });
  const double per_sample_point_data = static_cast<double>(frames[0].points.layout().point_step);
  std::ostringstream note;
  note.precision(3);
  // Point data = the fixed-frame position (3 doubles) and the input record; the rest is the hierarchy's own.
  const double point_data = 3 * sizeof(double) + per_sample_point_data;
  note << lc.frames / t_map << " frames/s, " << samples << " samples, " << static_cast<double>(bytes) / samples
       << " B/sample = " << point_data << " B point data (xyz + record) + "
       << static_cast<double>(bytes) / samples - point_data << " B hierarchy; per-frame scratch " << scratch / 1024
       << " KiB on top";
  report(name, "map mode (evict 60 m)", t_map, note.str());

  // The node's map-mode ~output per frame: the samples of levels 0..D within 2 r_D of the frame just inserted.
  std::size_t selected = 0;
  const double t_map_out = medianSeconds(reps, [&] {
    Pipeline p(mc);
    selected = 0;
    for (const auto &f : frames) {
      p.addFrame(f);
      selected += p.samplesHitByLastFrame(0, o.level, 2.0 * poissonRadius(o.cell_size, o.level)).size();
    }
  });
  std::ostringstream out_note;
  out_note.precision(3);
  out_note << lc.frames / t_map_out << " frames/s; selection alone " << (t_map_out - t_map) / lc.frames * 1e3
           << " ms/frame, " << selected / lc.frames << " samples/frame";
  report(name, "map mode + ~output selection", t_map_out, out_note.str());

  // Map mode at the shipped defaults (spacing 0.1 m, normals on): the node's frame path, insertion and ~output (the
  // samples the frame hit, with normals), per frame. Against map.keep_depth 7, which builds levels 6..7 and reads
  // them for the normals instead of keeping per-frame ones (map mode's only way before). The first 30 frames.
  const std::size_t n_map = std::min<std::size_t>(frames.size(), 30);
  std::size_t kept_samples = 0, deep_samples = 0;
  auto mapFramePath = [&](int keep_depth, std::size_t *held) {
    HpdsConfig dc;
    dc.mode = Mode::Map;
    dc.map.keep_depth = keep_depth;
    Pipeline p(dc);
    const int L = p.outputLevel();
    for (std::size_t i = 0; i < n_map; ++i) {
      p.addFrame(frames[i]);
      (void)p.makeCloud(p.samplesHitByLastFrame(0, L, 2.0 * p.hierarchy().radius(L)), false);
    }
    *held = p.hierarchy().sampleCount();
  };
  const Paired t_defaults = pairedMedians(std::min(reps, 3), [&] { mapFramePath(-1, &kept_samples); },
                                          [&] { mapFramePath(7, &deep_samples); });
  std::ostringstream defaults_note;
  defaults_note.precision(3);
  defaults_note << "per frame, " << n_map << " frames; samples held " << kept_samples << " against " << deep_samples;
  report(name, "map mode, shipped defaults, frame path",
         Paired{t_defaults.hpds_s / double(n_map), t_defaults.peer_s / double(n_map), t_defaults.ratio},
         "map.keep_depth 7 (levels 6..7 read)", defaults_note.str());
}

}  // namespace

int main(int argc, char **argv) {
  // NormalEstimationOMP leaves its threads spinning after each parallel region (libgomp's default wait policy),
  // which takes the second core from the 2-thread hpds run that follows it in a paired round (2-thread normals read
  // 60% slower than 1-thread ones that way). libgomp reads the policy once, when it loads, so the benchmark runs
  // itself again with the policy set; when that fails it goes on and says so.
  if (!std::getenv("OMP_WAIT_POLICY")) {
    setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
    execv("/proc/self/exe", argv);
    std::fprintf(stderr, "perf_benchmark: could not re-run with OMP_WAIT_POLICY=PASSIVE; the 2-thread rows may read slow\n");
  }
  // glibc's default malloc thresholds, unless HPDS_BENCH_KEEP_FRAME_MEMORY=1 asks for the node's and the CLI's
  // setting (hpds/util/FrameMemory.hpp). Process-wide, it speeds up the peers' large allocations too, and the heap the
  // PCL rows leave behind then slowed some later hpds rows (OT128 frame path 8.3 -> 10.2 ms in whole runs), which a
  // node, running nothing else, does not see: the default keeps the tables comparable.
  if (const char *keep = std::getenv("HPDS_BENCH_KEEP_FRAME_MEMORY"); keep && std::string(keep) == "1")
    hpds::keepFreedFrameMemory();
  Options o;
  const auto usage = [] {
    std::cerr << "usage: perf_benchmark [--data DIR] [--json FILE] [--repeats N>=1] [--level D, 0..21] "
                 "[--stream-points N>=1] [--only frames|stream] [--peers pcl|small_gicp|both] [--frame FILE]...\n";
    return 2;
  };
  try {
    for (int i = 1; i < argc; i += 2) {
      if (i + 1 >= argc) return usage();
      const std::string k = argv[i], v = argv[i + 1];
      if (k == "--data") o.data_dir = v;
      else if (k == "--json") o.json = v;
      else if (k == "--repeats") o.repeats = std::stoi(v);
      else if (k == "--level") o.level = std::stoi(v);
      else if (k == "--stream-points") o.stream_points = std::stoull(v);
      else if (k == "--only" && (v == "frames" || v == "stream")) o.only = v;
      else if (k == "--peers" && (v == "pcl" || v == "small_gicp" || v == "both")) o.peers = v;
      else if (k == "--frame") o.frames.push_back(v);
      else return usage();
    }
  } catch (const std::exception &) {  // a value that is not a number
    return usage();
  }
  if (o.repeats < 1 || o.level < 0 || o.level > 21 || o.stream_points < 1) return usage();
  std::printf("hpds performance vs PCL, level D = %d (c_D = %.4g m, r_D = %.4g m), median of %d runs after warm-up;\n"
              "each ratio is the median of per-round ratios, hpds and its peer timed in alternating rounds\n",
              o.level, cellEdge(o.cell_size, o.level), poissonRadius(o.cell_size, o.level), o.repeats);
  if (o.only != "stream") {
    if (std::filesystem::is_directory(o.data_dir)) {
      // One frame of every sensor in the data set (hdl32_b.pcd is a second frame of the same HDL-32 scene).
      for (const char *name : {"hdl32_a.pcd", "velodyne_vlp16.pcd", "velodyne_vlp32.pcd", "hesai_xt32.pcd",
                               "hesai_64.pcd", "hesai_ot128.pcd", "velodyne_vls128.pcd"}) {
        const auto path = std::filesystem::path(o.data_dir) / name;
        if (!std::filesystem::exists(path)) continue;
        if (!o.frames.empty() && std::find(o.frames.begin(), o.frames.end(), name) == o.frames.end()) continue;
        Frame f;
        f.points = readPointCloud(path.string());
        if (o.peers != "small_gicp") benchFrame(o, name, f);
        if (o.peers != "pcl" && smallGicpAvailable()) benchSmallGicp(o.setting(), o.repeats, name, {f});
        benchShippedDefaults(o, name, f);
      }
    } else {
      std::printf("(%s absent: real frames skipped)\n", o.data_dir.c_str());
    }
  }
  if (o.peers != "pcl" && !smallGicpAvailable())
    std::printf("(small_gicp rows skipped: its headers were not found at configure time; put small_gicp's include/ "
                "in ../shared/peers/small_gicp or set HPDS_SMALL_GICP_DIR, then re-run cmake)\n");
  if (o.only != "frames") benchStream(o);
  writeJson(o.json);
  std::printf("wrote %s\n", o.json.c_str());
  return 0;
}
