// registration_benchmark: does hpds make scan matching better? Frame pairs with known relative poses are downsampled
// to the same point count N by hpds (levels 0..d of one hierarchy), voxel centroids and one random point per voxel,
// then registered by PCL's point-to-plane ICP and GeneralizedIterativeClosestPoint (GICP) from perturbed starts and
// from the identity; and coarse to fine over the hpds levels against a voxel pyramid at matching counts.
//
// Data sets: a synthetic drive (SyntheticLidar, exact poses) and the shared HDL-32 pair (hdl32_relative.txt as the
// reference; skipped with a message when ../shared/data is absent). One set of settings for every data set.
// Method, settings and the reading of the tables: docs/quality.md, "Registration".
//
// Usage: registration_benchmark [--data DIR] [--out DIR] [--quick] [--perturbed K] [--samplings K] [--only TEXT]
//                               [--dataset TEXT]
//   --quick: 3 synthetic pairs and 1 perturbed start each (a smoke run); --samplings: every frame sampled K ways
//   (hpds seeds, grid origins drawn inside the cell; the first as shipped), trials pooled; --only: just the rows
//   whose "algorithm method" contains TEXT (e.g. "GICP hpds"); --dataset: just the data sets whose name contains
//   TEXT ("synthetic", "HDL-32").
// Writes OUT/registration.md and OUT/registration.csv (one row per registration, with the residual translation).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "QualityBenchSupport.hpp"
#include "RegistrationRunners.hpp"
#include "RegistrationSamplers.hpp"
#include "hpds/eval/PoseError.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/util/SplitMix64.hpp"

namespace {

using namespace hpds;
using namespace hpds::bench;
namespace fs = std::filesystem;

// ------------------------------------------------------------------------------------------------ settings
// The same for every data set.
constexpr double kCountTolerance = 0.03;         // grid baselines within 3 % of hpds's count
constexpr int kLevels[] = {3, 4, 5};             // single-level tables: r_D = 0.43, 0.22, 0.11 m at cell 4 m
constexpr int kCoarsest = 2, kFinest = 5;        // coarse to fine: levels 0..2, 0..3, 0..4, 0..5
constexpr double kPerturbTranslation = 0.5;      // [m] perturbed starts
constexpr double kPerturbRotationDeg = 2.0;      // [deg]
constexpr double kStageDistancePerRadius = 4.0;  // coarse to fine: correspondence distance 4 r_d at stage d
const double kEpsilon = HpdsConfig{}.normals.covariance_epsilon;  // GICP's plane regularisation, as PCL's

struct Options {
  std::string data_dir = "../shared/data/lidar";
  std::string out = "build/quality/registration";
  bool quick = false;
  int perturbed = 3;  // perturbed starts per pair (1 with --quick)
  int samplings = 1;  // samplings of every frame per method: hpds seeds, grid origins
  std::string only;   // run only the rows whose "algorithm method" contains this
  std::string dataset;  // run only the data sets whose name contains this
};

struct Pair {
  std::string dataset;
  std::string name;
  PointBuffer target, source;
  Eigen::Isometry3d truth;  // source -> target
};

// ------------------------------------------------------------------------------------------------ data sets

std::vector<Pair> syntheticPairs(bool quick) {
  SyntheticLidarConfig c;  // 32 beams, 1800 columns, 1 m and 0.02 rad per frame, urban street
  c.frames = quick ? 4 : 8;
  c.seed = 1;
  const SyntheticLidar lidar(c);
  std::vector<Pair> pairs;
  // Consecutive (1 m apart) and three apart (3 m), the later frame registered into the earlier one.
  std::vector<std::pair<int, int>> ij;
  for (int i = 0; i + 1 < c.frames; i += 2) ij.emplace_back(i, i + 1);
  for (int i = 0; i + 3 < c.frames; i += 4) ij.emplace_back(i, i + 3);
  for (const auto &[i, j] : ij) {
    Pair p;
    p.dataset = "synthetic";
    p.name = "frames " + std::to_string(i) + "-" + std::to_string(j);
    p.target = lidar.frame(i).frame.points;
    p.source = lidar.frame(j).frame.points;
    p.truth = lidar.pose(i).inverse() * lidar.pose(j);
    pairs.push_back(std::move(p));
  }
  return pairs;
}

std::vector<Pair> hdl32Pair(const std::string &dir) {
  const fs::path a = fs::path(dir) / "hdl32_a.pcd", b = fs::path(dir) / "hdl32_b.pcd",
                 rel = fs::path(dir) / "hdl32_relative.txt";
  if (!fs::exists(a) || !fs::exists(b) || !fs::exists(rel)) {
    std::cout << "HDL-32 pair not found under " << dir << ": that data set is skipped\n";
    return {};
  }
  Pair p;
  p.dataset = "HDL-32";
  p.name = "a-b";
  p.target = readPointCloud(a.string());
  p.source = readPointCloud(b.string());
  std::ifstream in(rel);
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) in >> m(r, c);
  if (!in) throw std::runtime_error("cannot read " + rel.string());
  p.truth.matrix() = m;
  return {p};
}

// ------------------------------------------------------------------------------------------------ results

struct Record {
  std::string dataset, pair, algorithm, method, start;
  int level = 0;  // single level: d; coarse to fine: the finest stage
  std::size_t n_source = 0, n_target = 0;
  PoseError error;
  double seconds = 0.0;
  std::size_t fallback = 0;
  int sampling = 0;  // which sampling of the frames (--samplings)
  Eigen::Vector3d residual = Eigen::Vector3d::Zero();  // [m] translation of truth^-1 * estimate, in the target frame
};

struct GroupKey {
  std::string dataset, algorithm, start, method;
  int level;
  bool operator<(const GroupKey &o) const {
    return std::tie(dataset, algorithm, start, level, method) < std::tie(o.dataset, o.algorithm, o.start, o.level,
                                                                         o.method);
  }
};

/// One markdown table per (data set, algorithm, start kind): a row per level and method.
std::string summaryTables(const std::vector<Record> &records) {
  std::map<GroupKey, std::vector<const Record *>> groups;
  for (const Record &r : records) groups[{r.dataset, r.algorithm, r.start, r.method, r.level}].push_back(&r);
  std::ostringstream out;
  std::string current;
  for (const auto &[key, rs] : groups) {
    const std::string title = key.dataset + ", " + key.algorithm + ", " + key.start;
    if (title != current) {
      current = title;
      out << "\n#### " << title << "\n\n"
          << "| level | method | N (mean) | trials | median t [cm] | mean t [cm] | median r [deg] | mean r [deg] | "
             "failures | ms |\n|---|---|---|---|---|---|---|---|---|---|\n";
    }
    std::vector<PoseError> errors;
    double n = 0.0, seconds = 0.0;
    for (const Record *r : rs) {
      errors.push_back(r->error);
      n += 0.5 * double(r->n_source + r->n_target);
      seconds += r->seconds;
    }
    const ErrorSummary s = summarizeErrors(errors);
    out << "| " << key.level << " | " << key.method << " | " << static_cast<long>(n / rs.size()) << " | "
        << rs.size() << " | " << fmt(100.0 * s.median_translation, 1) << " | " << fmt(100.0 * s.mean_translation, 1)
        << " | " << fmt(s.median_rotation_deg, 3) << " | " << fmt(s.mean_rotation_deg, 3) << " | "
        << fmt(100.0 * s.failure_rate, 0) << " % | " << fmt(1000.0 * seconds / rs.size(), 0) << " |\n";
  }
  return out.str();
}

/// Where the translation errors point on the real pair (no exact pose there): per level and method the median of
/// each component of the residual translation of GICP from the perturbed starts.
std::string residualTable(const std::vector<Record> &records, const std::string &dataset) {
  std::map<std::pair<int, std::string>, std::vector<Eigen::Vector3d>> groups;
  for (const Record &r : records)
    if (r.dataset == dataset && r.algorithm == "GICP" && r.start == "perturbed")
      groups[{r.level, r.method}].push_back(r.residual);
  if (groups.empty()) return {};
  std::ostringstream out;
  out << "\n#### " << dataset << ", GICP, perturbed: median residual translation per axis [cm]\n\n"
      << "| level | method | x | y | z |\n|---|---|---|---|---|\n";
  for (const auto &[key, rs] : groups) {
    out << "| " << key.first << " | " << key.second;
    for (int a = 0; a < 3; ++a) {
      std::vector<double> v;
      for (const Eigen::Vector3d &t : rs) v.push_back(t[a]);
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      out << " | " << fmt(100.0 * v[v.size() / 2], 1);
    }
    out << " |\n";
  }
  return out.str();
}

void writeCsv(const fs::path &path, const std::vector<Record> &records) {
  std::ofstream out(path);
  out << "dataset,pair,algorithm,method,start,level,n_source,n_target,translation_m,rotation_deg,seconds,fallback,"
         "sampling,residual_x,residual_y,residual_z\n";
  for (const Record &r : records)
    out << r.dataset << "," << r.pair << "," << r.algorithm << "," << r.method << "," << r.start << "," << r.level
        << "," << r.n_source << "," << r.n_target << "," << r.error.translation << "," << r.error.rotation_deg << ","
        << r.seconds << "," << r.fallback << "," << r.sampling << "," << r.residual.x() << "," << r.residual.y()
        << "," << r.residual.z() << "\n";
}

// ------------------------------------------------------------------------------------------------ the runs

/// A frame downsampled every way the benchmark compares, at every level it uses.
struct Prepared {
  std::map<int, SampledCloud> hpds, voxel, random;
  std::map<int, SampledCloud> hpds_planes;  // ablation: a plane covariance for every sample with a normal
  std::map<int, SampledCloud> hpds_own_planes;  // ablation: normals.covariance_k 0, planes from the output normals
  std::map<int, double> hpds_seconds;  // normals + covariances per level
  double cell_size = 0.0;              // [m] the level-0 cell hpds sampled with (the stages' radii follow it)
};

/// Sampling `sampling` of a frame: hpds with that seed of the random order, the grids anchored at an origin drawn
/// inside the cell (sampling 0: the shipped seed and the grids at the origin, as PCL's VoxelGrid), so that a
/// median over samplings is not one draw of where the samples happened to fall.
Prepared prepare(const PointBuffer &frame, std::uint64_t seed, int sampling) {
  Prepared p;
  const std::vector<Eigen::Vector3d> points = framePoints(frame);
  HpdsConfig config;
  config.order.seed += static_cast<std::uint64_t>(sampling);
  const HpdsFrame h(frame, config, kCoarsest, kFinest);
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();  // origin / cell
  if (sampling > 0) {
    std::uint64_t state = seed * 7919 + static_cast<std::uint64_t>(sampling);
    for (int a = 0; a < 3; ++a) shift[a] = unitInterval(splitMix64(state));
  }
  p.cell_size = h.cellSize();
  for (int d = kCoarsest; d <= kFinest; ++d) {
    p.hpds[d] = h.levels(d, &p.hpds_seconds[d]);
    // The samples' covariances with the output normal's plane: for every sample with a normal, or only where the
    // covariance is a plane (the others keep the identity).
    auto withOwnPlanes = [&](bool only_plane_like) {
      SampledCloud c = p.hpds[d];
      for (std::size_t i = 0; i < c.xyz.size(); ++i) {
        const Eigen::Vector3d &n = c.normal[i];
        if (n.allFinite() && (!only_plane_like || c.plane_like[i]))
          c.covariance[i] = Eigen::Matrix3d::Identity() - (1.0 - kEpsilon) * n * n.transpose();
      }
      return c;
    };
    p.hpds_planes[d] = withOwnPlanes(false);
    p.hpds_own_planes[d] = withOwnPlanes(true);
    const std::size_t n = p.hpds[d].xyz.size();
    p.voxel[d] = voxelCentroidsAtCount(points, n, kCountTolerance, shift);
    p.random[d] = randomPerVoxelAtCount(points, n, kCountTolerance, seed + static_cast<std::uint64_t>(d), shift);
    if (!p.voxel[d].count_matched || !p.random[d].count_matched)
      std::cout << "  note: level " << d << " grid count not within 3 % of " << n << " (voxel "
                << p.voxel[d].xyz.size() << ", random " << p.random[d].xyz.size() << ")\n";
  }
  return p;
}

struct Start {
  std::string kind;  // "perturbed" | "identity"
  Eigen::Isometry3d pose;
};

std::vector<Start> startsFor(const Pair &pair, int perturbed, std::uint64_t seed) {
  std::vector<Start> starts;
  for (int k = 0; k < perturbed; ++k)
    starts.push_back({"perturbed", perturbedPose(pair.truth, kPerturbTranslation, kPerturbRotationDeg,
                                                 seed * 1000 + static_cast<std::uint64_t>(k))});
  starts.push_back({"identity", Eigen::Isometry3d::Identity()});
  return starts;
}

/// GICP over the stages' clouds, each warm-started from the last, correspondence distance 4 r_d at stage d.
RegistrationResult coarseToFine(const std::map<int, SampledCloud> &source, const std::map<int, SampledCloud> &target,
                                double cell_size, CovarianceSource cov, const RegistrationSettings &base) {
  RegistrationResult total;
  Eigen::Isometry3d at = Eigen::Isometry3d::Identity();
  for (int d = kCoarsest; d <= kFinest; ++d) {
    RegistrationSettings s = base;
    s.max_correspondence = kStageDistancePerRadius * poissonRadius(cell_size, d);
    const RegistrationResult r = registerGicp(source.at(d), target.at(d), at, cov, s);
    at = r.transform;
    total.seconds += r.seconds;
    total.fallback += r.fallback;
  }
  total.transform = at;
  return total;
}

}  // namespace

int main(int argc, char **argv) {
  Options opt;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--data") {
      opt.data_dir = value();
    } else if (a == "--out") {
      opt.out = value();
    } else if (a == "--quick") {
      opt.quick = true;
    } else if (a == "--perturbed") {
      opt.perturbed = std::stoi(value());
    } else if (a == "--only") {
      opt.only = value();
    } else if (a == "--samplings") {
      opt.samplings = std::stoi(value());
      if (opt.samplings < 1) throw std::invalid_argument("--samplings needs a count >= 1");
    } else if (a == "--dataset") {
      opt.dataset = value();
    } else {
      std::cerr << "usage: registration_benchmark [--data DIR] [--out DIR] [--quick] [--perturbed K] [--samplings K] "
                   "[--only TEXT] [--dataset TEXT]\n";
      return 2;
    }
  }
  fs::create_directories(opt.out);
  const RegistrationSettings settings;  // 1 m correspondences, 50 iterations, k = 20
  const int perturbed = opt.quick ? 1 : opt.perturbed;

  std::vector<Pair> pairs = syntheticPairs(opt.quick);
  for (Pair &p : hdl32Pair(opt.data_dir)) pairs.push_back(std::move(p));

  std::vector<Record> single, staged;
  std::map<int, std::vector<double>> hpds_prep;  // normals + covariances per frame, by level
  std::ostringstream notes;
  std::uint64_t seed = 1;
  for (const Pair &pair : pairs) {
    const std::uint64_t pair_seed = seed++;
    if (pair.dataset.find(opt.dataset) == std::string::npos) continue;
    const std::vector<Start> starts = startsFor(pair, perturbed, pair_seed);
    for (int sampling = 0; sampling < opt.samplings; ++sampling) {
      std::cout << pair.dataset << " " << pair.name << ": motion " << fmt(pair.truth.translation().norm(), 2)
                << " m, sampling " << sampling << "\n" << std::flush;
      const Prepared tgt = prepare(pair.target, 2 * pair_seed, sampling),
                     src = prepare(pair.source, 2 * pair_seed + 1, sampling);
      for (const Prepared *p : {&tgt, &src})
        for (const auto &[d, seconds] : p->hpds_seconds) hpds_prep[d].push_back(seconds);
      // Runs `registration` unless --only excludes the row, and records its error.
      auto record = [&](std::vector<Record> &into, const std::string &algorithm, const std::string &method,
                        const std::string &start, int level, const SampledCloud &s, const SampledCloud &t,
                        const std::function<RegistrationResult()> &registration) {
        if ((algorithm + " " + method).find(opt.only) == std::string::npos) return;
        const RegistrationResult r = registration();
        into.push_back(Record{pair.dataset, pair.name, algorithm, method, start, level, s.xyz.size(), t.xyz.size(),
                              poseError(r.transform, pair.truth), r.seconds, r.fallback, sampling,
                            (pair.truth.inverse() * r.transform).translation()});
      };
      for (int d : kLevels) {
        for (const Start &st : starts) {
          const Eigen::Isometry3d &g = st.pose;
          record(single, "GICP", "hpds + hierarchy cov", st.kind, d, src.hpds.at(d), tgt.hpds.at(d),
                 [&] { return registerGicp(src.hpds.at(d), tgt.hpds.at(d), g, CovarianceSource::Given, settings); });
          record(single, "GICP", "hpds + plane cov everywhere", st.kind, d, src.hpds_planes.at(d),
                 tgt.hpds_planes.at(d), [&] {
                   return registerGicp(src.hpds_planes.at(d), tgt.hpds_planes.at(d), g, CovarianceSource::Given,
                                       settings);
                 });
          record(single, "GICP", "hpds + output-normal planes", st.kind, d, src.hpds_own_planes.at(d),
                 tgt.hpds_own_planes.at(d), [&] {
                   return registerGicp(src.hpds_own_planes.at(d), tgt.hpds_own_planes.at(d), g,
                                       CovarianceSource::Given, settings);
                 });
          record(single, "GICP", "hpds + k-NN cov", st.kind, d, src.hpds.at(d), tgt.hpds.at(d),
                 [&] { return registerGicp(src.hpds.at(d), tgt.hpds.at(d), g, CovarianceSource::Knn, settings); });
          record(single, "GICP", "voxel centroids + k-NN cov", st.kind, d, src.voxel.at(d), tgt.voxel.at(d),
                 [&] { return registerGicp(src.voxel.at(d), tgt.voxel.at(d), g, CovarianceSource::Knn, settings); });
          record(single, "GICP", "random per voxel + k-NN cov", st.kind, d, src.random.at(d), tgt.random.at(d),
                 [&] { return registerGicp(src.random.at(d), tgt.random.at(d), g, CovarianceSource::Knn, settings); });
          record(single, "point-to-plane ICP", "hpds + hierarchy normals", st.kind, d, src.hpds.at(d), tgt.hpds.at(d),
                 [&] { return registerPointToPlane(src.hpds.at(d), tgt.hpds.at(d), g, settings); });
          record(single, "point-to-plane ICP", "voxel centroids + k-NN normals", st.kind, d, src.voxel.at(d),
                 tgt.voxel.at(d), [&] { return registerPointToPlane(src.voxel.at(d), tgt.voxel.at(d), g, settings); });
          record(single, "point-to-plane ICP", "random per voxel + k-NN normals", st.kind, d, src.random.at(d),
                 tgt.random.at(d),
                 [&] { return registerPointToPlane(src.random.at(d), tgt.random.at(d), g, settings); });
        }
      }
      // Coarse to fine from the identity, against single-level runs at the finest level with the first stage's
      // correspondence distance (the same capture range) and with the common 1 m.
      const Eigen::Isometry3d id = Eigen::Isometry3d::Identity();
      RegistrationSettings wide = settings;
      wide.max_correspondence = kStageDistancePerRadius * poissonRadius(src.cell_size, kCoarsest);
      const SampledCloud &hs = src.hpds.at(kFinest), &ht = tgt.hpds.at(kFinest);
      const SampledCloud &vs = src.voxel.at(kFinest), &vt = tgt.voxel.at(kFinest);
      record(staged, "GICP", "hpds coarse to fine + hierarchy cov", "identity", kFinest, hs, ht,
             [&] { return coarseToFine(src.hpds, tgt.hpds, src.cell_size, CovarianceSource::Given, settings); });
      record(staged, "GICP", "hpds single level + hierarchy cov (wide)", "identity", kFinest, hs, ht,
             [&] { return registerGicp(hs, ht, id, CovarianceSource::Given, wide); });
      record(staged, "GICP", "hpds single level + hierarchy cov (1 m)", "identity", kFinest, hs, ht,
             [&] { return registerGicp(hs, ht, id, CovarianceSource::Given, settings); });
      record(staged, "GICP", "voxel pyramid + k-NN cov", "identity", kFinest, vs, vt,
             [&] { return coarseToFine(src.voxel, tgt.voxel, src.cell_size, CovarianceSource::Knn, settings); });
      record(staged, "GICP", "voxel single level + k-NN cov (wide)", "identity", kFinest, vs, vt,
             [&] { return registerGicp(vs, vt, id, CovarianceSource::Knn, wide); });
      record(staged, "GICP", "voxel single level + k-NN cov (1 m)", "identity", kFinest, vs, vt,
             [&] { return registerGicp(vs, vt, id, CovarianceSource::Knn, settings); });
      // How far the reference itself is from GICP on the full clouds (real data has no exact pose).
      if (pair.dataset == "HDL-32" && !opt.quick && opt.only.empty() && sampling == 0) {
        SampledCloud fs_, ft_;
        fs_.xyz = framePoints(pair.source);
        ft_.xyz = framePoints(pair.target);
        const RegistrationResult r = registerGicp(fs_, ft_, id, CovarianceSource::Knn, settings);
        const PoseError e = poseError(r.transform, pair.truth);
        const Eigen::Vector3d t = (pair.truth.inverse() * r.transform).translation();
        notes << "- HDL-32, GICP with k-NN covariances on the full clouds (" << fs_.xyz.size() << " and "
              << ft_.xyz.size() << " points) from the identity: " << fmt(100.0 * e.translation, 1) << " cm ("
              << fmt(100.0 * t.x(), 1) << ", " << fmt(100.0 * t.y(), 1) << ", " << fmt(100.0 * t.z(), 1)
              << "), " << fmt(e.rotation_deg, 3) << " deg from the reference, " << fmt(r.seconds, 1) << " s.\n";
      }
    }
  }
  for (const auto &[d, seconds] : hpds_prep) {
    double mean = 0.0;
    for (double x : seconds) mean += x / static_cast<double>(seconds.size());
    notes << "- hpds normals + covariances for levels 0.." << d << ": " << fmt(1000.0 * mean, 0)
          << " ms per frame (mean of " << seconds.size() << "; not in the ms column, where GICP with k-NN "
          << "covariances computes its own).\n";
  }

  std::ostringstream md;
  md << "### Single level, equal N\n" << summaryTables(single) << residualTable(single, "HDL-32")
     << "\n### Coarse to fine from the identity\n"
     << summaryTables(staged) << "\n### Notes\n\n" << notes.str();
  std::cout << md.str();
  std::ofstream(fs::path(opt.out) / "registration.md") << md.str();
  std::vector<Record> all = single;
  all.insert(all.end(), staged.begin(), staged.end());
  writeCsv(fs::path(opt.out) / "registration.csv", all);
  std::cout << "\nwritten: " << (fs::path(opt.out) / "registration.md").string() << ", registration.csv\n";
  return 0;
}
