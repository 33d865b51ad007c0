// normal_accuracy: how close hpds normals come to the exact surface normals, against the subsample-then-PCA pipelines
// people use instead, at equal sample count.
//
// For each synthetic scene (SyntheticLidar knows the true normal of every return) the frames are merged in the world
// frame and
//   hpds            map-mode hierarchy, output levels 0..L, normals from the hierarchy (NormalEstimator)
//   hpds_refined    the same with NormalParams::neighborhood_level_offset and max_growth (--level-offset,
//                   --max-growth); ablation rows give each refinement alone, and the growth rule to the voxel grid
//   voxel_grid      PCL VoxelGrid (centroids), leaf chosen by bisection so the count equals hpds's
//   uniform         PCL UniformSampling (point nearest each voxel centre), radius by bisection likewise
//   random          PCL RandomSample of exactly hpds's count
//   full_res        PCA at hpds's sample positions with neighbours from the full-resolution input
//   hpds_scan       the node's scan mode: every frame sampled on its own, normals with hpds_refined's settings
//                   (its count is the sum over the frames, not the merged count)
//   hpds_map        the node's map mode with hpds_refined's settings: the normals the map keeps, each estimated from
//                   the frame that saw its sample from closest (the hierarchy rows above keep the finer levels that
//                   map mode no longer builds, map.keep_depth)
// each get PCA normals with two neighbourhoods: the k nearest (k = 10) and a fixed radius (2.5 r_L), neighbours taken
// from the method's own point set. The error of a normal is the unoriented angle to the true normal of the sample's
// input point (for a voxel centroid, of the input point nearest to it). A normal that could not be estimated counts
// as 90 degrees (it is reported separately too), so giving up is never rewarded.
// Grids are offset by half a cell: the synthetic ground is exactly z = 0, which on a cell boundary would split every
// ground column into two cells a noise width apart (real data has no such coincidence).
//
// Writes OUT/normal_accuracy.{md,csv,json}, OUT/normal_errors.csv (error quantiles, for the CDF plot) and pictures
// under OUT/pictures/. Usage: normal_accuracy [--out DIR] [--level L] [--threads N] [--quick] [--scan-only]
// [--level-offset O] [--max-growth G] [--line-ratio R] [--plane-rms P]
#include <pcl/features/normal_3d_omp.h>
#include <pcl/filters/random_sample.h>
#include <pcl/filters/uniform_sampling.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "hpds/eval/GridSubsampling.hpp"
#include "hpds/normals/LocalPca.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/eval/PointRender.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/eval/PngWriter.hpp"
#include "GrowthAblation.hpp"
#include "QualityBenchSupport.hpp"
#include "ScanModeNormals.hpp"

namespace {

using namespace hpds;
using bench::fmt;
using bench::Growth;
using bench::adaptiveNormals;
namespace fs = std::filesystem;
using Cloud = pcl::PointCloud<pcl::PointXYZ>;

constexpr double kRadToDeg = 57.29577951308232;

struct Options {
  std::string out_dir = "build/quality";
  int level = 5;
  double cell_size = 4.0;
  int k = 10;
  double radius_factor = 2.5;  // radius neighbourhood = factor * r_L, hpds's default
  int threads = 2;
  bool quick = false;
  bool scan_only = false;  // only the hpds_scan rows: a quick check of the scan-mode estimator
  int level_offset = 2;     // hpds_refined: NormalParams::neighborhood_level_offset
  double max_growth = 8.0;  // hpds_refined: NormalParams::max_growth
  double line_ratio = 0.05;
  double plane_rms = 0.02;
};

struct Scene {
  std::string name;
  std::string description;
  SyntheticLidarConfig lidar;
};

/// The merged frames in the world frame with their exact normals; frames carry a `gt` field indexing these arrays.
struct GroundTruth {
  std::vector<Frame> frames;
  std::vector<Eigen::Vector3d> xyz;
  std::vector<Eigen::Vector3d> normal;
  std::vector<ObjectKind> kind;
  Cloud::Ptr cloud{new Cloud};
};

std::vector<Scene> scenes(bool quick) {
  std::vector<Scene> s;
  SyntheticLidarConfig base;
  base.emit_no_returns = false;
  base.organized = false;
  base.frames = quick ? 2 : 5;
  {
    Scene sc{"planar_urban", "PlanarUrban, 32 beams, 5 frames 1 m apart", base};
    sc.lidar.scene = SceneKind::PlanarUrban;
    s.push_back(sc);
  }
  {
    Scene sc{"curved_objects", "CurvedObjects (spheres, cylinders, sculptures), 32 beams, 5 frames 1 m apart", base};
    sc.lidar.scene = SceneKind::CurvedObjects;
    s.push_back(sc);
  }
  {
    // Few beams, fine azimuth and poses far apart: dense scan lines with wide gaps, crossing at scan edges.
    Scene sc{"crossing_scans", "Urban, 16 beams x 3600 azimuths, 4 scans 6 m apart turning 3.4 deg each", base};
    sc.lidar.scene = SceneKind::Urban;
    sc.lidar.beams = 16;
    sc.lidar.min_elevation_deg = -15.0;
    sc.lidar.azimuth_steps = 3600;
    sc.lidar.speed = 6.0;
    sc.lidar.yaw_rate = 0.06;
    sc.lidar.frames = quick ? 2 : 4;
    s.push_back(sc);
  }
  {
    Scene sc{"single_scan", "Urban, one scan of 16 beams x 3600 azimuths: scan lines only", base};
    sc.lidar.scene = SceneKind::Urban;
    sc.lidar.beams = 16;
    sc.lidar.min_elevation_deg = -15.0;
    sc.lidar.azimuth_steps = 3600;
    sc.lidar.frames = 1;
    s.push_back(sc);
  }
  return s;
}

GroundTruth generate(const Scene &scene) {
  const SyntheticLidar lidar(scene.lidar);
  GroundTruth gt;
  for (int f = 0; f < scene.lidar.frames; ++f) {
    const SyntheticFrame sf = lidar.frame(f);
    const Eigen::Isometry3d T = sf.frame.sensor_to_fixed;
    Frame out = bench::objectReturnsFrame(sf, static_cast<std::uint32_t>(gt.xyz.size()),
                                          [&](std::size_t i, const Eigen::Vector3d &p) {
                                            gt.xyz.push_back(T * p);
                                            gt.normal.push_back((T.linear() * sf.normals[i].cast<double>()).normalized());
                                            gt.kind.push_back(sf.kinds[i]);
                                          });
    out.sensor_to_fixed = T;
    out.stamp = sf.frame.stamp;
    gt.frames.push_back(std::move(out));
  }
  gt.cloud->reserve(gt.xyz.size());
  for (const auto &p : gt.xyz) gt.cloud->push_back(pcl::PointXYZ(float(p.x()), float(p.y()), float(p.z())));
  return gt;
}

/// One method's sample set: positions and, per sample, the index of its ground-truth input point.
struct SampleSet {
  std::string method;
  Cloud::Ptr points{new Cloud};
  std::vector<std::uint32_t> truth;
  double cell = 0.0;  // leaf / radius found by bisection (0 when not applicable)
};

struct ErrorSet {
  std::string scene, method, neighborhood;
  std::size_t count = 0;
  double cell = 0.0;
  std::vector<double> errors;  // degrees, 90 for invalid
  std::vector<ObjectKind> kinds;  // of each sample's true surface
  std::size_t invalid = 0;
  // Oriented methods (hpds's: toward the sensor) only; PCL's normals here are unoriented (NaN).
  // Of the normals within kAxisDeg of the true axis (a sign is only worth judging on a right axis; worse ones are in
  // the error columns already), those facing away from the true, sensor-facing normal.
  static constexpr double kAxisDeg = 45.0;
  std::size_t near_axis = 0, wrong_side = 0;
  std::vector<std::uint8_t> away;  // per sample: 1 where it does
  bool oriented = false;
  double wrongSidePct() const {
    return oriented ? 100.0 * static_cast<double>(wrong_side) / static_cast<double>(std::max<std::size_t>(1, near_axis))
                    : NAN;
  }
  double quantile(double q) const {
    if (errors.empty()) return NAN;
    std::vector<double> e = errors;
    const std::size_t k = std::min(e.size() - 1, static_cast<std::size_t>(q * static_cast<double>(e.size())));
    std::nth_element(e.begin(), e.begin() + static_cast<long>(k), e.end());
    return e[k];
  }
  double fractionOver(double deg) const {
    std::size_t n = 0;
    for (double e : errors) n += e > deg ? 1 : 0;
    return errors.empty() ? NAN : static_cast<double>(n) / static_cast<double>(errors.size());
  }
};

std::vector<std::uint32_t> nearestTruth(const GroundTruth &gt, const pcl::search::KdTree<pcl::PointXYZ> &tree,
                                        const Cloud &pts) {
  std::vector<std::uint32_t> out(pts.size());
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    tree.nearestKSearch(pts[i], 1, idx, d2);
    out[i] = static_cast<std::uint32_t>(idx[0]);
  }
  return out;
}

Cloud::Ptr shifted(const Cloud &c, float s) {
  Cloud::Ptr out(new Cloud(c));
  for (auto &p : *out) p.x += s, p.y += s, p.z += s;
  return out;
}

void unshift(Cloud &c, float s) {
  for (auto &p : c) p.x -= s, p.y -= s, p.z -= s;
}

Cloud::Ptr voxelGrid(const Cloud::Ptr &in, double leaf) {
  // Shifting the cloud by half a leaf is the same as offsetting PCL's origin-anchored grid (see header).
  const float s = static_cast<float>(0.5 * leaf);
  Cloud::Ptr moved = shifted(*in, s);
  pcl::VoxelGrid<pcl::PointXYZ> vg;
  vg.setInputCloud(moved);
  vg.setLeafSize(float(leaf), float(leaf), float(leaf));
  Cloud::Ptr out(new Cloud);
  vg.filter(*out);
  unshift(*out, s);
  return out;
}

Cloud::Ptr uniformSampling(const Cloud::Ptr &in, double radius) {
  const float s = static_cast<float>(0.5 * radius);
  Cloud::Ptr moved = shifted(*in, s);
  pcl::UniformSampling<pcl::PointXYZ> us;
  us.setInputCloud(moved);
  us.setRadiusSearch(radius);
  Cloud::Ptr out(new Cloud);
  us.filter(*out);
  unshift(*out, s);
  return out;
}

/// PCL normals of `query` with neighbours from `surface`; NaN where PCL could not estimate one.
std::vector<Eigen::Vector3d> pclNormals(const Cloud::Ptr &query, const Cloud::Ptr &surface, bool knn, int k,
                                        double radius, int threads) {
  pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne(static_cast<unsigned>(threads));
  pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
  ne.setInputCloud(query);
  ne.setSearchSurface(surface);
  ne.setSearchMethod(tree);
  if (knn)
    ne.setKSearch(k);
  else
    ne.setRadiusSearch(radius);
  pcl::PointCloud<pcl::Normal> n;
  ne.compute(n);
  std::vector<Eigen::Vector3d> out(n.size());
  for (std::size_t i = 0; i < n.size(); ++i) out[i] = {n[i].normal_x, n[i].normal_y, n[i].normal_z};
  return out;
}

ErrorSet score(const GroundTruth &gt, const SampleSet &s, const std::vector<Eigen::Vector3d> &normals) {
  ErrorSet e;
  e.method = s.method;
  e.count = s.points->size();
  e.cell = s.cell;
  e.oriented = s.method.rfind("hpds", 0) == 0 || s.method.rfind("ablation_hpds", 0) == 0;
  e.errors.resize(normals.size());
  e.away.assign(normals.size(), 0);
  for (std::uint32_t t : s.truth) e.kinds.push_back(gt.kind[t]);
  for (std::size_t i = 0; i < normals.size(); ++i) {
    const Eigen::Vector3d &n = normals[i];
    if (!n.allFinite() || n.norm() < 0.5) {
      e.errors[i] = 90.0;
      ++e.invalid;
      continue;
    }
    const double dot = n.normalized().dot(gt.normal[s.truth[i]]);
    e.errors[i] = std::acos(std::min(1.0, std::abs(dot))) * kRadToDeg;
    if (e.errors[i] >= ErrorSet::kAxisDeg) continue;
    ++e.near_axis;
    e.away[i] = dot < 0.0 ? 1 : 0;
    e.wrong_side += e.away[i];
  }
  return e;
}

void writePictures(const Options &o, const Scene &scene, const GroundTruth &gt, const SampleSet &s,
                   const std::vector<Eigen::Vector3d> &normals, const std::string &tag) {
  const fs::path dir = fs::path(o.out_dir) / "pictures";
  fs::create_directories(dir);
  std::vector<Eigen::Vector3d> p(s.points->size());
  std::vector<Rgb> err(p.size()), nrm(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    p[i] = {(*s.points)[i].x, (*s.points)[i].y, (*s.points)[i].z};
    const Eigen::Vector3d &n = normals[i];
    const bool ok = n.allFinite() && n.norm() > 0.5;
    const double deg = ok ? std::acos(std::min(1.0, std::abs(n.normalized().dot(gt.normal[s.truth[i]])))) * kRadToDeg
                          : 90.0;
    // 0..30 degrees over the whole ramp: the interesting range; invalid normals show as grey.
    err[i] = ok ? scalarColor(deg / 30.0) : Rgb{160, 160, 160};
    // Unoriented: flip to the upper hemisphere so a plane reads as one colour whatever PCA's sign.
    Eigen::Vector3d u = ok ? n.normalized() : n;
    if (ok && u.z() < 0.0) u = -u;
    nrm[i] = normalColor(u);
  }
  // The neighbourhood of the first sensor pose, where scan lines are dense and their gaps visible.
  RenderOptions ro;
  ro.max_width = 1000;
  ro.max_height = 1000;
  ro.splat_radius = 0.04;
  const Eigen::Vector3d c = gt.frames.front().sensor_to_fixed.translation();
  ro.crop = Eigen::AlignedBox3d(c + Eigen::Vector3d(-14, -14, -3), c + Eigen::Vector3d(14, 14, 6));
  writePng((dir / (scene.name + "_" + tag + "_error_top.png")).string(), renderPoints(p, err, ro));
  writePng((dir / (scene.name + "_" + tag + "_normal_top.png")).string(), renderPoints(p, nrm, ro));
}

/// The grid baselines at hpds's sample count `target`: VoxelGrid centroids and UniformSampling (cell by bisection),
/// and a random subset of exactly that count.
std::vector<SampleSet> gridBaselines(const GroundTruth &gt, const pcl::search::KdTree<pcl::PointXYZ> &input_tree,
                                     std::size_t target, double r_level) {
  std::vector<SampleSet> sets;
  {
    SampleSet v;
    v.method = "voxel_grid";
    v.cell = cellForCount([&](double l) { return voxelGrid(gt.cloud, l)->size(); }, target, 0.2 * r_level,
                          20.0 * r_level, 40);
    v.points = voxelGrid(gt.cloud, v.cell);
    v.truth = nearestTruth(gt, input_tree, *v.points);
    sets.push_back(std::move(v));
  }
  {
    SampleSet u;
    u.method = "uniform";
    u.cell = cellForCount([&](double r) { return uniformSampling(gt.cloud, r)->size(); }, target, 0.2 * r_level,
                          20.0 * r_level, 40);
    u.points = uniformSampling(gt.cloud, u.cell);
    u.truth = nearestTruth(gt, input_tree, *u.points);
    sets.push_back(std::move(u));
  }
  {
    SampleSet r;
    r.method = "random";
    pcl::RandomSample<pcl::PointXYZ> rs;
    rs.setInputCloud(gt.cloud);
    rs.setSample(static_cast<unsigned>(target));
    rs.setSeed(1);
    pcl::Indices kept;
    rs.filter(kept);
    for (int i : kept) {
      r.points->push_back((*gt.cloud)[static_cast<std::size_t>(i)]);
      r.truth.push_back(static_cast<std::uint32_t>(i));
    }
    sets.push_back(std::move(r));
  }
  return sets;
}

/// Samples `ids` of `h` as a SampleSet, each with the ground-truth index its record carries ("gt").
SampleSet hierarchySamples(const Hierarchy &h, const std::vector<SampleId> &ids, const std::string &method) {
  const PointField *gtf = h.recordLayout().find("gt");
  SampleSet set;
  set.method = method;
  for (SampleId id : ids) {
    const double *q = h.position(id);
    set.points->push_back(pcl::PointXYZ(float(q[0]), float(q[1]), float(q[2])));
    set.truth.push_back(static_cast<std::uint32_t>(readAsDouble(h.record(id), *gtf)));
  }
  return set;
}

/// hpds normals as score() takes them: NaN where a normal could not be estimated.
std::vector<Eigen::Vector3d> scoredNormals(const std::vector<SampleNormal> &normals) {
  std::vector<Eigen::Vector3d> out(normals.size());
  for (std::size_t i = 0; i < normals.size(); ++i)
    out[i] = normals[i].valid ? Eigen::Vector3d(normals[i].normal[0], normals[i].normal[1], normals[i].normal[2])
                              : Eigen::Vector3d::Constant(NAN);
  return out;
}

}  // namespace

int main(int argc, char **argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--out") o.out_dir = next();
    else if (a == "--level") o.level = std::stoi(next());
    else if (a == "--threads") o.threads = std::stoi(next());
    else if (a == "--quick") o.quick = true;
    else if (a == "--scan-only") o.scan_only = true;
    else if (a == "--level-offset") o.level_offset = std::stoi(next());
    else if (a == "--max-growth") o.max_growth = std::stod(next());
    else if (a == "--line-ratio") o.line_ratio = std::stod(next());
    else if (a == "--plane-rms") o.plane_rms = std::stod(next());
    else {
      std::cerr << "usage: normal_accuracy [--out DIR] [--level L] [--threads N] [--quick] [--scan-only] "
                   "[--level-offset O] [--max-growth G]\n";
      return 2;
    }
  }
  fs::create_directories(o.out_dir);
  const double r_level = poissonRadius(o.cell_size, o.level);
  const double radius = o.radius_factor * r_level;
  std::vector<ErrorSet> results;
  std::map<std::string, double> seconds;  // hpds normal estimation time per variant and neighbourhood, all scenes

  for (const Scene &scene : scenes(o.quick)) {
    const auto t0 = std::chrono::steady_clock::now();
    const GroundTruth gt = generate(scene);

    // hpds: the pipeline as the node runs it (map mode, random order), then its own normal estimator.
    HpdsConfig cfg;
    cfg.mode = Mode::Map;
    cfg.hierarchy.cell_size = o.cell_size;
    cfg.hierarchy.max_depth = o.level + 3;
    cfg.output.level = o.level;
    cfg.threads = o.threads;
    // The estimators below read the hierarchy's finer levels, which map mode only builds when asked to keep them.
    cfg.map.keep_depth = std::min(cfg.hierarchy.max_depth, o.level + std::max(0, o.level_offset));
    Pipeline pipeline(cfg);
    for (const Frame &f : gt.frames) pipeline.addFrame(f);
    const Hierarchy &h = pipeline.hierarchy();
    const std::vector<SampleId> ids = pipeline.outputSamples();
    const SampleSet hp = hierarchySamples(h, ids, "hpds");
    const std::size_t target = ids.size();

    pcl::search::KdTree<pcl::PointXYZ> input_tree;
    input_tree.setInputCloud(gt.cloud);
    std::vector<SampleSet> sets;
    if (!o.scan_only) sets = gridBaselines(gt, input_tree, target, r_level);

    for (const bool knn : {true, false}) {
      const std::string nb = knn ? "knn" : "radius";
      // hpds, from the hierarchy's own levels: the estimator as the pipeline runs it, the refined one, and each
      // refinement alone (ablation).
      struct HpdsVariant {
        const char *name;
        int offset;
        double growth;
      };
      const HpdsVariant variants[] = {{"hpds", 0, 1.0},
                                      {"hpds_refined", o.level_offset, o.max_growth},
                                      {"ablation_hpds_finer_only", o.level_offset, 1.0},
                                      {"ablation_hpds_growth_only", 0, o.max_growth}};
      for (const HpdsVariant &v : variants) {
        if (o.scan_only) break;
        NormalParams np = normalParamsFor(cfg, o.level);
        np.k = knn ? o.k : 0;
        np.radius = knn ? 0.0 : radius;
        np.min_neighbors = 3;  // PCL's minimum, so neither side gives up earlier than the other
        np.threads = o.threads;
        np.neighborhood_level_offset = v.offset;
        np.max_growth = v.growth;
        np.line_ratio = o.line_ratio;
        np.max_plane_rms = o.plane_rms;
        const auto tn = std::chrono::steady_clock::now();
        const std::vector<SampleNormal> hn = estimateNormals(h, ids, np);
        seconds[std::string(v.name) + "_" + nb] += std::chrono::duration<double>(std::chrono::steady_clock::now() - tn).count();
        const std::vector<Eigen::Vector3d> hpds_normals = scoredNormals(hn);
        SampleSet hv = hp;
        hv.method = v.name;
        ErrorSet e = score(gt, hv, hpds_normals);
        e.scene = scene.name, e.neighborhood = nb;
        results.push_back(e);
        if (knn && (v.offset == 0 && v.growth == 1.0)) writePictures(o, scene, gt, hp, hpds_normals, "hpds_knn");
        if (knn && v.name == std::string("hpds_refined")) writePictures(o, scene, gt, hp, hpds_normals, "hpds_refined_knn");
      }

      // The node's pipelines with the refined estimator's settings above.
      HpdsConfig refined = cfg;
      refined.normals.k = knn ? o.k : 0;
      refined.normals.radius = knn ? 0.0 : radius;
      refined.normals.min_neighbors = 3;
      refined.normals.neighborhood_level_offset = o.level_offset;
      refined.normals.max_growth = o.max_growth;
      {
        // Scan mode: each frame on its own.
        const HpdsConfig &sc = refined;
        const auto tn = std::chrono::steady_clock::now();
        const bench::ScanModeNormals r = bench::scanModeNormals(gt.frames, sc);
        seconds["hpds_scan_" + nb] += std::chrono::duration<double>(std::chrono::steady_clock::now() - tn).count();
        SampleSet ss;
        ss.method = "hpds_scan";
        for (const Eigen::Vector3d &p : r.positions) ss.points->push_back(pcl::PointXYZ(float(p.x()), float(p.y()), float(p.z())));
        ss.truth = r.truth;
        ErrorSet e = score(gt, ss, r.normals);
        e.scene = scene.name, e.neighborhood = nb;
        results.push_back(e);
      }

      if (!o.scan_only) {
        // Map mode at its defaults: the normals the map keeps, each from the frame that saw its sample from closest.
        HpdsConfig mc = refined;
        mc.map.keep_depth = -1;
        Pipeline mp(mc);
        double frames_normals = 0.0;
        for (const Frame &f : gt.frames) frames_normals += mp.addFrame(f).seconds_normals;
        const std::vector<SampleId> mids = mp.outputSamples();
        const std::vector<SampleNormal> mn = mp.normals(mids);
        seconds["hpds_map_" + nb] += frames_normals;
        ErrorSet e = score(gt, hierarchySamples(mp.hierarchy(), mids, "hpds_map"), scoredNormals(mn));
        e.scene = scene.name, e.neighborhood = nb;
        results.push_back(e);
      }

      for (const SampleSet &s : sets) {
        if (o.scan_only) break;
        const auto n = pclNormals(s.points, s.points, knn, o.k, radius, o.threads);
        ErrorSet es = score(gt, s, n);
        es.scene = scene.name, es.neighborhood = nb;
        results.push_back(es);
        if (knn && s.method == "voxel_grid") writePictures(o, scene, gt, s, n, "voxel_grid_knn");
        if (s.method == "voxel_grid") {
          SampleSet va = s;
          va.method = "ablation_voxel_grid_growth";
          Growth g;
          g.max_growth = o.max_growth;
          g.line_ratio = o.line_ratio;
          g.max_plane_rms = o.plane_rms;
          ErrorSet ea = score(gt, va, adaptiveNormals(s.points, s.points, s.points, knn, o.k, radius, g));
          ea.scene = scene.name, ea.neighborhood = nb;
          results.push_back(ea);
        }
      }
      // Full resolution: PCA at hpds's sample positions, neighbours from every input point.
      if (o.scan_only) continue;
      SampleSet full = hp;
      full.method = "full_res";
      const auto fn = pclNormals(hp.points, gt.cloud, knn, o.k, radius, o.threads);
      ErrorSet ef = score(gt, full, fn);
      ef.scene = scene.name, ef.neighborhood = nb;
      results.push_back(ef);
      if (knn) writePictures(o, scene, gt, full, fn, "full_res_knn");
    }
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cerr << scene.name << ": " << gt.xyz.size() << " input points, " << target << " samples at level " << o.level
              << " (r_L " << r_level << " m), " << fmt(secs, 1) << " s\n";
  }

  // Tables.
  const fs::path out(o.out_dir);
  {
    std::ofstream csv(out / "normal_accuracy.csv");
    csv << "scene,method,neighborhood,count,cell,invalid_pct,median_deg,p90_deg,over10_pct,mean_deg,wrong_side_pct\n";
    std::ofstream q(out / "normal_errors.csv");
    q << "scene,method,neighborhood,quantile,error_deg\n";
    std::ofstream json(out / "normal_accuracy.json");
    json << "{\n  \"level\": " << o.level << ", \"cell_size\": " << o.cell_size << ", \"k\": " << o.k
         << ", \"radius\": " << radius << ",\n  \"results\": [\n";
    for (std::size_t i = 0; i < results.size(); ++i) {
      const ErrorSet &e = results[i];
      double mean = 0.0;
      for (double v : e.errors) mean += v / static_cast<double>(e.errors.size());
      const double inv = 100.0 * static_cast<double>(e.invalid) / static_cast<double>(std::max<std::size_t>(1, e.count));
      csv << e.scene << "," << e.method << "," << e.neighborhood << "," << e.count << "," << e.cell << "," << inv << ","
          << e.quantile(0.5) << "," << e.quantile(0.9) << "," << 100.0 * e.fractionOver(10.0) << "," << mean << ","
          << (e.oriented ? std::to_string(e.wrongSidePct()) : std::string()) << "\n";
      json << "    {\"scene\": \"" << e.scene << "\", \"method\": \"" << e.method << "\", \"neighborhood\": \""
           << e.neighborhood << "\", \"count\": " << e.count << ", \"cell\": " << e.cell << ", \"invalid_pct\": " << inv
           << ", \"median_deg\": " << e.quantile(0.5) << ", \"p90_deg\": " << e.quantile(0.9)
           << ", \"over10_pct\": " << 100.0 * e.fractionOver(10.0) << ", \"mean_deg\": " << mean
           << ", \"wrong_side_pct\": " << (e.oriented ? std::to_string(e.wrongSidePct()) : std::string("null")) << "}"
           << (i + 1 < results.size() ? ",\n" : "\n");
      std::vector<double> sorted = e.errors;
      std::sort(sorted.begin(), sorted.end());
      for (int k = 0; k < 200 && !sorted.empty(); ++k) {
        const double qq = (k + 0.5) / 200.0;
        q << e.scene << "," << e.method << "," << e.neighborhood << "," << qq << ","
          << sorted[std::min(sorted.size() - 1, static_cast<std::size_t>(qq * static_cast<double>(sorted.size())))]
          << "\n";
      }
    }
    json << "  ]\n}\n";
  }
  std::ostringstream md;
  md << "Angular error of unoriented normals against the exact surface normal, in degrees, at equal sample count "
        "(hpds levels 0.." << o.level << ", r_L = " << fmt(r_level, 3) << " m). k-NN: k = " << o.k
     << "; radius: " << fmt(radius, 3) << " m. Failed estimates count as 90 degrees. Facing away: of the normals "
        "within 45 degrees of the true axis, the share on the other side of the true, sensor-facing normal (hpds "
        "orients toward the sensor; the PCL rows are unoriented). hpds_refined: "
     << "neighborhood_level_offset = " << o.level_offset << ", max_growth = " << fmt(o.max_growth, 0) << ".\n\nScenes:";
  for (const Scene &sc : scenes(o.quick)) md << " " << sc.name << " (" << sc.description << ");";
  md << "\n\n";
  auto table = [&](bool ablation) {
    for (const std::string nb : {"knn", "radius"}) {
      md << "| scene (" << nb << ") | method | samples | leaf/radius [m] | median | p90 | > 10 deg | failed "
         << "| facing away |\n"
         << "|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
      for (const ErrorSet &e : results) {
        const bool is_ablation = e.method.rfind("ablation_", 0) == 0;
        if (e.neighborhood != nb || is_ablation != ablation) continue;
        md << "| " << e.scene << " | " << e.method << " | " << e.count << " | " << (e.cell > 0 ? fmt(e.cell, 3) : "-")
           << " | " << fmt(e.quantile(0.5)) << " | " << fmt(e.quantile(0.9)) << " | "
           << fmt(100.0 * e.fractionOver(10.0), 1) << " % | "
           << fmt(100.0 * static_cast<double>(e.invalid) / static_cast<double>(std::max<std::size_t>(1, e.count)), 1)
           << " % | " << (e.oriented ? fmt(e.wrongSidePct(), 1) + " %" : std::string("-")) << " |\n";
      }
      md << "\n";
    }
  };
  table(false);
  // The target: hpds (median, p90) no worse than the best voxel baseline (VoxelGrid or UniformSampling) per scene.
  md << "Target check, hpds_refined against the better of voxel_grid / uniform per metric (lower is better):\n\n"
     << "| scene | neighbourhood | median hpds_refined / best grid | p90 hpds_refined / best grid | met |\n"
     << "|---|---|---:|---:|---|\n";
  auto find = [&](const std::string &sc, const std::string &m, const std::string &nb) -> const ErrorSet * {
    for (const ErrorSet &e : results)
      if (e.scene == sc && e.method == m && e.neighborhood == nb) return &e;
    return nullptr;
  };
  for (const ErrorSet &e : results) {
    if (e.method != "hpds_refined") continue;
    const ErrorSet *v = find(e.scene, "voxel_grid", e.neighborhood), *u = find(e.scene, "uniform", e.neighborhood);
    if (!v || !u) continue;
    const double bm = std::min(v->quantile(0.5), u->quantile(0.5)), bp = std::min(v->quantile(0.9), u->quantile(0.9));
    const bool met = e.quantile(0.5) <= bm && e.quantile(0.9) <= bp;
    md << "| " << e.scene << " | " << e.neighborhood << " | " << fmt(e.quantile(0.5)) << " / " << fmt(bm) << " | "
       << fmt(e.quantile(0.9)) << " / " << fmt(bp) << " | " << (met ? "yes" : "**no**") << " |\n";
  }
  md << "\nAblation: each refinement alone, and the growth rule given to the voxel grid too:\n\n";
  table(true);
  // Where the errors are: p90 per surface kind (k-NN), for the main methods.
  md << "p90 error [deg] by surface kind (k-NN; share of samples in brackets, and facing away):\n\n";
  for (const ErrorSet &e : results) {
    if (e.neighborhood != "knn" || (e.method.rfind("hpds", 0) != 0 && e.method.rfind("ablation", 0) != 0 && e.method != "voxel_grid")) continue;
    md << "- " << e.scene << " / " << e.method << ":";
    for (int k = 1; k < kObjectKindCount; ++k) {
      std::vector<double> sub;
      std::size_t away = 0, valid = 0;  // valid: within ErrorSet::kAxisDeg
      for (std::size_t i = 0; i < e.errors.size(); ++i)
        if (static_cast<int>(e.kinds[i]) == k) {
          sub.push_back(e.errors[i]);
          away += e.away[i];
          valid += e.errors[i] < ErrorSet::kAxisDeg ? 1 : 0;
        }
      if (sub.empty()) continue;
      std::sort(sub.begin(), sub.end());
      md << " " << toString(static_cast<ObjectKind>(k)) << " " << fmt(sub[std::min(sub.size() - 1, sub.size() * 9 / 10)], 1)
         << " (" << fmt(100.0 * static_cast<double>(sub.size()) / static_cast<double>(e.errors.size()), 0) << " %"
         << (e.oriented ? ", " + fmt(100.0 * static_cast<double>(away) /
                                             static_cast<double>(std::max<std::size_t>(1, valid)), 1) + " % away"
                        : std::string())
         << ")";
    }
    md << "\n";
  }
  md << "\n";
  md << "hpds normal estimation time over all scenes (" << o.threads << " threads):";
  for (const auto &kv : seconds) md << " " << kv.first << " " << fmt(kv.second, 2) << " s;";
  md << "\n";
  std::ofstream(out / "normal_accuracy.md") << md.str();
  std::cout << md.str();
  return 0;
}
