// feature_sensitivity: do the feature-sensitive insertion orders (paper, section 6.2) put feature points into the
// coarse levels? One synthetic sweep of the CurvedObjects scene (spheres, cylinders and the rippled sculpture) is
// sampled three times (random, sphericity and surface-variation order); for every union of levels 0..D we report the
// mean feature value of its samples and the share of "high-feature" samples (the input's top 10 % by that feature),
// and the share of samples on the sculpture. Features are computed on the input exactly as the orders compute them
// (same radius, same neighbourhoods), so a sample's value is the one its order saw.
//
// Writes OUT/feature_levels.{csv,md} and close-up pictures of a sculpture under OUT/pictures/.
// Usage: feature_sensitivity [--out DIR] [--threads N]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "hpds/sampling/InsertionOrderer.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/eval/PointRender.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/eval/PngWriter.hpp"
#include "QualityBenchSupport.hpp"

namespace {

using namespace hpds;
using bench::fmt;
namespace fs = std::filesystem;

struct Options {
  std::string out_dir = "build/quality";
  int threads = 2;
  double cell_size = 4.0;
  int level = 5;                // output level; the feature radius is 2 r_level, the pipeline's default
  double high_quantile = 0.9;  // "high-feature" = at or above this quantile of the input's values
};

}  // namespace

int main(int argc, char **argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) o.out_dir = argv[++i];
    else if (a == "--threads" && i + 1 < argc) o.threads = std::stoi(argv[++i]);
    else {
      std::cerr << "usage: feature_sensitivity [--out DIR] [--threads N]\n";
      return 2;
    }
  }
  fs::create_directories(fs::path(o.out_dir) / "pictures");

  // 1. One sweep taken beside a sculpture (so the detailed object is densely scanned), with its truth; a `gt` field
  //    carries each point's index through the sampler.
  SyntheticLidarConfig lc;
  lc.scene = SceneKind::CurvedObjects;
  lc.frames = 40;
  lc.yaw_rate = 0.0;  // a straight street: pose i is at x = i metres
  lc.azimuth_steps = 3600;
  lc.beams = 64;
  const SyntheticLidar lidar(lc);
  int pick = 0;
  {
    // The sculpture nearest the path ahead: its points in the first sweep give its x.
    const SyntheticFrame f0 = lidar.frame(0);
    const PointField *fx = f0.frame.points.layout().find("x");
    double best = INFINITY;
    for (std::size_t i = 0; i < f0.kinds.size(); ++i)
      if (f0.kinds[i] == ObjectKind::Sculpture) {
        const double x = readAsDouble(f0.frame.points.record(i), *fx);
        if (x > 0.0 && x < best) best = x;
      }
    if (std::isfinite(best)) pick = std::clamp(static_cast<int>(std::lround(best + 1.0)), 0, lc.frames - 1);
  }
  const SyntheticFrame sf = lidar.frame(pick);
  std::vector<double> xyz;
  std::vector<ObjectKind> kinds;
  // The pipeline reads the float32 coordinates: the features here must see the same numbers.
  Frame frame = bench::objectReturnsFrame(sf, 0, [&](std::size_t i, const Eigen::Vector3d &p) {
    xyz.insert(xyz.end(), {p.x(), p.y(), p.z()});
    kinds.push_back(sf.kinds[i]);
  });
  const std::size_t n = kinds.size();
  const double radius = 2.0 * poissonRadius(o.cell_size, o.level);
  std::vector<std::uint32_t> all(n);
  for (std::uint32_t i = 0; i < n; ++i) all[i] = i;

  struct Feature {
    const char *name;
    InsertionOrder kind;
    std::vector<float> value;
    double threshold = 0.0;
    double input_mean = 0.0;
  };
  std::vector<Feature> features = {{"sphericity", InsertionOrder::Sphericity, {}, 0, 0},
                                   {"surface_variation", InsertionOrder::SurfaceVariation, {}, 0, 0}};
  for (Feature &f : features) {
    f.value = localFeature(xyz.data(), all, f.kind, radius, o.threads);
    std::vector<float> sorted = f.value;
    std::sort(sorted.begin(), sorted.end());
    f.threshold = sorted[static_cast<std::size_t>(o.high_quantile * static_cast<double>(n - 1))];
    for (float v : f.value) f.input_mean += v / static_cast<double>(n);
  }
  std::size_t sculpture_in = 0;
  for (ObjectKind k : kinds) sculpture_in += k == ObjectKind::Sculpture ? 1 : 0;

  // 2. The three orders, each sampled into a fresh hierarchy (scan mode, one frame).
  struct Run {
    const char *order;
    InsertionOrder kind;
    std::vector<std::uint32_t> truth;  // input index per output sample
    std::vector<int> level;
    std::vector<Eigen::Vector3d> pos;
  };
  std::vector<Run> runs = {{"random", InsertionOrder::Random, {}, {}, {}},
                           {"sphericity", InsertionOrder::Sphericity, {}, {}, {}},
                           {"surface_variation", InsertionOrder::SurfaceVariation, {}, {}, {}}};
  for (Run &r : runs) {
    HpdsConfig cfg;
    cfg.hierarchy.cell_size = o.cell_size;
    cfg.hierarchy.max_depth = o.level + 2;
    cfg.output.level = o.level;
    cfg.order.type = r.kind;
    cfg.order.feature_radius = radius;
    cfg.threads = o.threads;
    Pipeline p(cfg);
    p.addFrame(frame);
    const Hierarchy &h = p.hierarchy();
    const PointField *gtf = h.recordLayout().find("gt");
    for (SampleId id : p.outputSamples()) {
      r.truth.push_back(static_cast<std::uint32_t>(readAsDouble(h.record(id), *gtf)));
      r.level.push_back(h.level(id));
      const double *q = h.position(id);
      r.pos.emplace_back(q[0], q[1], q[2]);
    }
  }

  // 3. Per union of levels 0..D: mean feature, share of high-feature samples, share on the sculpture.
  std::ofstream csv(fs::path(o.out_dir) / "feature_levels.csv");
  csv << "feature,order,level,count,mean_feature,high_share,input_mean,input_high_share,sculpture_share,"
         "input_sculpture_share\n";
  std::ostringstream md;
  md << "Feature-sensitive orders on one CurvedObjects sweep (" << n << " points, feature radius " << fmt(radius, 3)
     << " m). high = the input's top " << fmt(100.0 * (1.0 - o.high_quantile), 0)
     << " % by that feature; the input itself has " << fmt(100.0 * (1.0 - o.high_quantile), 0)
     << " % high points and " << fmt(100.0 * static_cast<double>(sculpture_in) / static_cast<double>(n), 1)
     << " % sculpture points.\n\n";
  for (const Feature &f : features) {
    md << "| levels 0..D | samples | mean " << f.name << " (random / " << f.name << " order) | high-" << f.name
       << " share (random / " << f.name << " order) | sculpture share (random / " << f.name << " order) |\n"
       << "|---:|---:|---:|---:|---:|\n";
    for (int d = 0; d <= o.level; ++d) {
      double stats[3][4] = {};  // per run: count, mean, high share, sculpture share
      for (std::size_t ri = 0; ri < runs.size(); ++ri) {
        const Run &r = runs[ri];
        double cnt = 0, sum = 0, high = 0, sculpt = 0;
        for (std::size_t s = 0; s < r.truth.size(); ++s) {
          if (r.level[s] > d) continue;
          const double v = f.value[r.truth[s]];
          cnt += 1, sum += v, high += v >= f.threshold ? 1 : 0;
          sculpt += kinds[r.truth[s]] == ObjectKind::Sculpture ? 1 : 0;
        }
        stats[ri][0] = cnt;
        stats[ri][1] = cnt > 0 ? sum / cnt : NAN;
        stats[ri][2] = cnt > 0 ? high / cnt : NAN;
        stats[ri][3] = cnt > 0 ? sculpt / cnt : NAN;
        csv << f.name << "," << r.order << "," << d << "," << cnt << "," << stats[ri][1] << "," << stats[ri][2] << ","
            << f.input_mean << "," << 1.0 - o.high_quantile << "," << stats[ri][3] << ","
            << static_cast<double>(sculpture_in) / static_cast<double>(n) << "\n";
      }
      const std::size_t own = f.kind == InsertionOrder::Sphericity ? 1 : 2;
      md << "| " << d << " | " << fmt(stats[0][0], 0) << " / " << fmt(stats[own][0], 0) << " | "
         << fmt(stats[0][1], 4) << " / " << fmt(stats[own][1], 4) << " | " << fmt(100 * stats[0][2], 1) << " % / "
         << fmt(100 * stats[own][2], 1) << " % | " << fmt(100 * stats[0][3], 1) << " % / " << fmt(100 * stats[own][3], 1)
         << " % |\n";
    }
    md << "\n";
  }
  // On the detailed object alone: does the order pick its most curved parts first? Threshold: the sculpture's own
  // top 10 %, so the question is which of the object's points, not whether the object, gets sampled.
  for (const Feature &f : features) {
    std::vector<float> on;
    for (std::size_t i = 0; i < n; ++i)
      if (kinds[i] == ObjectKind::Sculpture) on.push_back(f.value[i]);
    if (on.empty()) continue;
    std::sort(on.begin(), on.end());
    const double thr = on[static_cast<std::size_t>(o.high_quantile * static_cast<double>(on.size() - 1))];
    double mean_on = 0.0;
    for (float v : on) mean_on += v / static_cast<double>(on.size());
    md << "Sculpture samples only (" << on.size() << " input points, mean " << f.name << " " << fmt(mean_on, 4)
       << "):\n\n| levels 0..D | sculpture samples (random / " << f.name << " order) | mean " << f.name
       << " | share in the sculpture's top 10 % |\n|---:|---:|---:|---:|\n";
    const std::size_t own = f.kind == InsertionOrder::Sphericity ? 1 : 2;
    for (int d = 0; d <= o.level; ++d) {
      double st[2][3] = {};
      for (int w = 0; w < 2; ++w) {
        const Run &r = runs[w == 0 ? 0 : own];
        double cnt = 0, sum = 0, high = 0;
        for (std::size_t k = 0; k < r.truth.size(); ++k) {
          if (r.level[k] > d || kinds[r.truth[k]] != ObjectKind::Sculpture) continue;
          const double v = f.value[r.truth[k]];
          cnt += 1, sum += v, high += v >= thr ? 1 : 0;
        }
        st[w][0] = cnt, st[w][1] = cnt > 0 ? sum / cnt : NAN, st[w][2] = cnt > 0 ? high / cnt : NAN;
        csv << f.name << "_sculpture," << r.order << "," << d << "," << cnt << "," << st[w][1] << "," << st[w][2] << ","
            << mean_on << "," << 1.0 - o.high_quantile << ",1,1\n";
      }
      md << "| " << d << " | " << fmt(st[0][0], 0) << " / " << fmt(st[1][0], 0) << " | " << fmt(st[0][1], 4) << " / "
         << fmt(st[1][1], 4) << " | " << fmt(100 * st[0][2], 1) << " % / " << fmt(100 * st[1][2], 1) << " % |\n";
    }
    md << "\n";
  }
  std::ofstream(fs::path(o.out_dir) / "feature_levels.md") << md.str();
  std::cout << md.str();

  // 4. Pictures: the sculpture nearest the sensor, levels 0..3 of random vs sphericity order, coloured by sphericity.
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  double best_d = INFINITY;
  for (std::size_t i = 0; i < n; ++i) {
    if (kinds[i] != ObjectKind::Sculpture) continue;
    const Eigen::Vector3d p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (p.head<2>().norm() < best_d) best_d = p.head<2>().norm(), best = p;  // sensor frame: the nearest one
  }
  if (std::isfinite(best_d)) {
    Eigen::AlignedBox3d box;
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
      if (kinds[i] == ObjectKind::Sculpture && (p - best).norm() < 3.0) box.extend(p);
    }
    box.min() -= Eigen::Vector3d(0.6, 0.6, 0.3);
    box.max() += Eigen::Vector3d(0.6, 0.6, 0.3);
    const Feature &sph = features[0];
    std::vector<float> on;
    for (std::size_t i = 0; i < n; ++i)
      if (kinds[i] == ObjectKind::Sculpture) on.push_back(sph.value[i]);
    std::sort(on.begin(), on.end());
    const double top = std::max(1e-6, static_cast<double>(on[static_cast<std::size_t>(0.95 * (on.size() - 1))]));
    for (const Run &r : runs) {
      for (int d : {3, 4, o.level}) {
        // The input as small grey dots behind the samples, so the object's shape reads at coarse levels too.
        std::vector<Eigen::Vector3d> p;
        std::vector<Rgb> c;
        std::vector<double> prio;
        for (std::size_t i = 0; i < n; ++i) {
          p.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
          c.push_back({200, 200, 200});
          prio.push_back(-1.0);
        }
        for (std::size_t k = 0; k < r.truth.size(); ++k) {
          if (r.level[k] > d) continue;
          p.push_back(r.pos[k]);
          c.push_back(scalarColor(sph.value[r.truth[k]] / top));
          prio.push_back(0.0);
        }
        RenderOptions ro;
        ro.crop = box;
        ro.max_width = 600;
        ro.max_height = 600;
        ro.splat_radius = 0.03;
        ro.view = ViewDirection::Front;  // along +y, the street's lateral axis: the scanned face of the sculpture
        writePng((fs::path(o.out_dir) / "pictures" /
                  ("sculpture_" + std::string(r.order) + "_L" + std::to_string(d) + ".png"))
                     .string(),
                 renderPoints(p, c, ro, &prio));
      }
    }
  }
  return 0;
}
