#include "SmallGicpRows.hpp"

#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

#include "BenchTiming.hpp"

#ifdef HPDS_HAVE_SMALL_GICP
#include <small_gicp/ann/kdtree.hpp>
#include <small_gicp/ann/kdtree_omp.hpp>
#include <small_gicp/points/point_cloud.hpp>
#include <small_gicp/util/downsampling.hpp>
#include <small_gicp/util/downsampling_omp.hpp>
#include <small_gicp/util/normal_estimation.hpp>
#include <small_gicp/util/normal_estimation_omp.hpp>
#endif

namespace bench {

#ifndef HPDS_HAVE_SMALL_GICP

bool smallGicpAvailable() { return false; }
void benchSmallGicp(const LevelSetting &, int, const std::string &, const std::vector<hpds::Frame> &) {}

#else

bool smallGicpAvailable() { return true; }

namespace {

/// small_gicp's usual neighbourhood for normals and covariances (its registration helpers' default is 10 too).
constexpr int kNeighbors = 10;

/// The frame's x/y/z in small_gicp's cloud, read from the same bytes hpds reads and put into the same frame (the
/// frame's pose), without the points hpds skips (non-finite, exact (0,0,0) no-returns): what a user's converter
/// does before small_gicp can run.
small_gicp::PointCloud::Ptr toPeerCloud(const hpds::Frame &frame) {
  const hpds::PointBuffer &b = frame.points;
  const hpds::PointLayout &l = b.layout();
  const hpds::PointField *fx = l.find("x"), *fy = l.find("y"), *fz = l.find("z");
  auto cloud = std::make_shared<small_gicp::PointCloud>();
  cloud->points.reserve(b.size());
  const Eigen::Isometry3d &pose = frame.sensor_to_fixed;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const std::uint8_t *rec = b.record(i);
    const Eigen::Vector3d p(hpds::readAsDouble(rec, *fx), hpds::readAsDouble(rec, *fy), hpds::readAsDouble(rec, *fz));
    if (!p.allFinite() || (p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0)) continue;
    cloud->points.emplace_back((Eigen::Vector4d() << pose * p, 1.0).finished());
  }
  cloud->normals.resize(cloud->points.size());
  cloud->covs.resize(cloud->points.size());
  return cloud;
}

small_gicp::PointCloud::Ptr downsample(const small_gicp::PointCloud &cloud, double leaf, int threads) {
  return threads == 1 ? small_gicp::voxelgrid_sampling(cloud, leaf)
                      : small_gicp::voxelgrid_sampling_omp(cloud, leaf, threads);
}

struct PeerRun {
  std::size_t points = 0, valid_normals = 0;
};

/// small_gicp's whole frame path: message to cloud, voxel grid, k-d tree, k-NN normals, and the points with their
/// normals written out as float x y z nx ny nz (the message a node would publish).
PeerRun peerFramePath(const hpds::Frame &frame, double leaf, int threads, std::vector<float> &msg) {
  const auto cloud = toPeerCloud(frame);
  const auto ds = downsample(*cloud, leaf, threads);
  if (threads == 1) {
    const small_gicp::KdTree<small_gicp::PointCloud> tree(ds, small_gicp::KdTreeBuilder());
    small_gicp::estimate_normals(*ds, tree, kNeighbors);
  } else {
    const small_gicp::KdTree<small_gicp::PointCloud> tree(ds, small_gicp::KdTreeBuilderOMP(threads));
    small_gicp::estimate_normals_omp(*ds, tree, kNeighbors, threads);
  }
  PeerRun run;
  run.points = ds->size();
  msg.resize(6 * ds->size());
  for (std::size_t i = 0; i < ds->size(); ++i) {
    const Eigen::Vector4d &p = ds->points[i], &n = ds->normals[i];
    float *o = &msg[6 * i];
    for (int a = 0; a < 3; ++a) o[a] = static_cast<float>(p[a]), o[3 + a] = static_cast<float>(n[a]);
    run.valid_normals += n.head<3>().squaredNorm() > 0.0 ? 1 : 0;  // too few neighbours: a zero normal
  }
  return run;
}

std::string percent(std::size_t part, std::size_t whole) {
  char s[32];
  std::snprintf(s, sizeof s, "%.1f %%", whole ? 100.0 * double(part) / double(whole) : 0.0);
  return s;
}

}  // namespace

void benchSmallGicp(const LevelSetting &setting, int repeats, const std::string &name,
                    const std::vector<hpds::Frame> &frames) {
  const double leaf = hpds::cellEdge(setting.cell_size, setting.level);
  const std::string lv = "level " + std::to_string(setting.level);
  for (int threads : {1, 2}) {
    const std::string th = threads == 1 ? "1 thread" : std::to_string(threads) + " threads";
    // Downsampling alone: levels 0..D from the frame's bytes against the voxel grid from the same bytes.
    std::size_t hpds_count = 0, peer_count = 0;
    hpds::Pipeline down(downsampleConfig(setting, threads));
    const Paired t_down = pairedMedians(
        repeats,
        [&] {
          hpds_count = 0;
          for (const hpds::Frame &f : frames) hpds_count += down.addFrame(f).counters.accepted;
        },
        [&] {
          peer_count = 0;
          for (const hpds::Frame &f : frames) peer_count += downsample(*toPeerCloud(f), leaf, threads)->size();
        });
    report(name, "downsampling to " + lv + ", " + th + " (" + std::to_string(hpds_count) + ")", t_down,
           (threads == 1 ? "small_gicp voxelgrid (" : "small_gicp voxelgrid_omp (") + std::to_string(peer_count) + ")");

    // The frame path with valid normals: hpds with the shipped normal settings, small_gicp with k = 10.
    hpds::Pipeline path(framePathConfig(setting, threads));
    std::vector<float> msg;
    NodePathRun last;
    PeerRun peer_last;
    const Paired t_path = pairedMedians(
        repeats,
        [&] {
          for (const hpds::Frame &f : frames) last = nodePath(path, f);
        },
        [&] {
          for (const hpds::Frame &f : frames) peer_last = peerFramePath(f, leaf, threads, msg);
        });
    // Valid shares over every frame, outside the timed rounds.
    std::size_t h_points = 0, h_valid = 0, p_points = 0, p_valid = 0;
    for (const hpds::Frame &f : frames) {
      const NodePathRun r = nodePath(path, f, true);
      h_points += r.points, h_valid += r.valid_normals;
      const PeerRun pr = peerFramePath(f, leaf, threads, msg);
      p_points += pr.points, p_valid += pr.valid_normals;
    }
    std::ostringstream note;
    note << "valid normals: hpds " << percent(h_valid, h_points) << " of " << h_points << ", small_gicp "
         << percent(p_valid, p_points) << " of " << p_points;
    report(name, "frame path, valid normals, " + lv + ", " + th, t_path,
           threads == 1 ? "small_gicp vg+KdTree+normals k10" : "small_gicp OMP vg+KdTree+normals k10", note.str());
  }
}

#endif

}  // namespace bench
