// `hpds analyze SAMPLING.ply [--cell-size C] -o DIR [--input FRAMES... [--poses P]]`: blue-noise statistics of a
// sampling, per level, on a planar patch (the PSA tool's RDF and radially averaged power spectrum), and with --input
// the paper's figure-5 comparison against single-grid subsamplings of the same input at equal count.
//
// Writes DIR/analysis.json, levels.csv, rdf.csv, spectrum.csv, per-set point and periodogram PNGs, and (unless
// --no-plots) the curve plots drawn by scripts/plot_quality.py.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <numeric>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "CliOptions.hpp"
#include "Commands.hpp"
#include "OutputPaths.hpp"
#include "QualityIo.hpp"
#include "hpds/eval/BlueNoiseAnalysis.hpp"
#include "hpds/config/Config.hpp"
#include "hpds/eval/GridSubsampling.hpp"
#include "hpds/sampling/InsertionOrderer.hpp"
#include "hpds/eval/PointRender.hpp"

namespace hpds::cli {

namespace {

namespace fs = std::filesystem;

struct AnalyzeArgs {
  std::string sampling;
  std::string out_dir;
  CellSizeOptions cell;
  std::vector<std::string> inputs;
  std::string poses;
  std::vector<double> patch;  // cx, cy, size
  double patch_size = 8.0;
  double plane_band = 0.1;
  double grid_offset = 0.5;
  int compare_level = -1;
  long frame = -1;
  std::uint64_t seed = 1;
  int rdf_bins = 60;
  double rdf_max = 4.0;
  double freq_max = 2.0;
  int threads = 1;
  bool no_plots = false;
  std::string plot_script;
};

/// One 2D point set analysed on the patch window.
struct SetResult {
  std::string method;
  int level = 0;
  double r = 0.0;     // r_D of the level the set is compared at
  double cell = 0.0;  // baseline grid edge (0 for hpds / random)
  std::size_t count = 0;
  double min_nn_over_r = NAN, mean_nn_over_r = NAN;
  double power_low = NAN;   // mean radial power for f * r_D <= 0.35
  double power_max = NAN;   // largest periodogram value off DC: spikes = structural aliasing
  RadialDistribution rdf;
  PowerSpectrum spectrum;
  bool analysed = false;
};

struct Patch {
  PlaneFit plane;
  SquareWindow window;  // in plane coordinates (u, v) about plane.centroid
  Eigen::Vector2d center_xy;
  double size = 0.0;
  bool automatic = true;
};

std::string defaultPlotScript() {
  // An installed hpds (bin/hpds, or lib/hpds/hpds of a ROS package) uses the script installed beside it in
  // share/hpds/scripts: the source tree it was built from may be gone, or another version. A build tree's uses the
  // source tree's (this file lives in hpds_core/tools/, the script in scripts/).
  std::error_code ec;
  const fs::path exe_dir = fs::read_symlink("/proc/self/exe", ec).parent_path();
  if (!ec)
    for (const char *up : {"..", "../.."}) {
      const fs::path installed = exe_dir / up / "share" / "hpds" / "scripts" / "plot_quality.py";
      if (fs::is_regular_file(installed, ec)) return installed.lexically_normal().string();
    }
  return (fs::path(__FILE__).parent_path().parent_path().parent_path() / "scripts" / "plot_quality.py").string();
}

std::vector<Eigen::Vector2d> inWindow(const std::vector<Eigen::Vector3d> &pts, const Patch &patch, double band) {
  std::vector<Eigen::Vector2d> uv = projectToPlane(pts, patch.plane, band);
  std::vector<Eigen::Vector2d> out;
  const SquareWindow &w = patch.window;
  for (const auto &p : uv)
    if (p.x() >= w.x0 && p.x() < w.x0 + w.size && p.y() >= w.y0 && p.y() < w.y0 + w.size) out.push_back(p);
  return out;
}

void analyseSet(SetResult &s, const std::vector<Eigen::Vector2d> &pts, const Patch &patch, const AnalyzeArgs &a) {
  s.count = pts.size();
  if (pts.size() < 2) return;
  std::vector<Eigen::Vector3d> p3;
  p3.reserve(pts.size());
  for (const auto &p : pts) p3.emplace_back(p.x(), p.y(), 0.0);
  const std::vector<double> nn = nearestNeighborDistances(p3);
  s.min_nn_over_r = *std::min_element(nn.begin(), nn.end()) / s.r;
  s.mean_nn_over_r = std::accumulate(nn.begin(), nn.end(), 0.0) / static_cast<double>(nn.size()) / s.r;
  const double r_max = std::min(a.rdf_max * s.r, 0.45 * patch.window.size);
  s.rdf = radialDistribution(pts, patch.window, r_max, a.rdf_bins, false);
  const int K = std::clamp(static_cast<int>(std::ceil(a.freq_max * patch.window.size / s.r)), 8, 256);
  s.spectrum = powerSpectrum(pts, patch.window, K, a.threads);
  double low = 0.0, nlow = 0.0;
  for (std::size_t b = 0; b < s.spectrum.radial_power.size(); ++b)
    if (s.spectrum.radial_frequency[b] * s.r <= 0.35) low += s.spectrum.radial_power[b], nlow += 1.0;
  s.power_low = nlow > 0.0 ? low / nlow : NAN;
  double mx = 0.0;
  for (int ky = -K; ky <= K; ++ky)
    for (int kx = -K; kx <= K; ++kx)
      if (kx != 0 || ky != 0) mx = std::max(mx, s.spectrum.at(kx, ky));
  s.power_max = mx;
  s.analysed = true;
}

/// The periodogram as PSA shows it: frequency 0 in the centre, brightness sqrt(P / 4) so that white noise (P ~ 1)
/// reads as mid-grey and spikes saturate.
void writePeriodogramPng(const std::string &path, const PowerSpectrum &s) {
  const int W = 2 * s.half_extent + 1;
  const int zoom = std::max(1, (400 + W - 1) / W);
  RgbImage img(W * zoom, W * zoom, 0, 0, 0);
  for (int ky = -s.half_extent; ky <= s.half_extent; ++ky)
    for (int kx = -s.half_extent; kx <= s.half_extent; ++kx) {
      const double v = std::clamp(std::sqrt(s.at(kx, ky) / 4.0), 0.0, 1.0);
      const auto g = static_cast<std::uint8_t>(std::lround(v * 255.0));
      const int x0 = (kx + s.half_extent) * zoom, y0 = (s.half_extent - ky) * zoom;
      for (int dy = 0; dy < zoom; ++dy)
        for (int dx = 0; dx < zoom; ++dx) img.set(x0 + dx, y0 + dy, g, g, g);
    }
  writePng(path, img);
}

void writePointsPng(const std::string &path, const std::vector<Eigen::Vector2d> &pts, const SquareWindow &w,
                    double r) {
  std::vector<Eigen::Vector3d> p3;
  for (const auto &p : pts) p3.emplace_back(p.x(), p.y(), 0.0);
  RenderOptions o;
  o.max_width = o.max_height = 520;
  o.margin_px = 4;
  o.splat_radius = 0.22 * r;
  o.crop = Eigen::AlignedBox3d(Eigen::Vector3d(w.x0, w.y0, -1.0), Eigen::Vector3d(w.x0 + w.size, w.y0 + w.size, 1.0));
  writePng(path, renderPoints(p3, std::vector<Rgb>(p3.size(), Rgb{0, 0, 0}), o));
}

Patch choosePatch(const AnalyzeArgs &a, const std::vector<Eigen::Vector3d> &finest) {
  Patch patch;
  if (a.patch.size() == 3) {
    patch.automatic = false;
    patch.center_xy = {a.patch[0], a.patch[1]};
    patch.size = a.patch[2];
    if (!(patch.size > 0.0)) throw std::invalid_argument("--patch: the size must be > 0");
    std::vector<Eigen::Vector3d> in;
    const double h = 0.5 * patch.size;
    for (const auto &p : finest)
      if (std::abs(p.x() - a.patch[0]) < h && std::abs(p.y() - a.patch[1]) < h) in.push_back(p);
    // A single fit is enough when the user picked the place; the band still excludes what stands on it.
    patch.plane = fitPlane(in);
    if (!patch.plane.valid)
      throw std::invalid_argument("--patch: fewer than 3 non-collinear samples inside the patch");
  } else {
    const PlanarPatch found = findPlanarPatch(finest, a.patch_size, a.plane_band);
    if (!found.found)
      throw std::invalid_argument("no planar near-horizontal patch of " + std::to_string(a.patch_size) +
                                  " m found; give one with --patch cx,cy,size");
    patch.center_xy = found.center;
    patch.size = found.size;
    patch.plane = found.plane;
  }
  // The window is a square in the plane about the patch centre; 0.95 keeps its corners inside the xy square for
  // tilts up to ~15 degrees.
  const Eigen::Vector3d c3(patch.center_xy.x(), patch.center_xy.y(),
                           patch.plane.centroid.z() - ((patch.center_xy.x() - patch.plane.centroid.x()) * patch.plane.normal.x() +
                                                       (patch.center_xy.y() - patch.plane.centroid.y()) * patch.plane.normal.y()) /
                                                          patch.plane.normal.z());
  const Eigen::Vector3d d = c3 - patch.plane.centroid;
  const double s = 0.95 * patch.size;
  patch.window = SquareWindow{d.dot(patch.plane.u) - 0.5 * s, d.dot(patch.plane.v) - 0.5 * s, s};
  return patch;
}

std::string setName(const SetResult &s) { return s.method + "_L" + std::to_string(s.level); }

void writeSetCsvRows(TextFile &rdf, TextFile &spec, const SetResult &s) {
  if (!s.analysed) return;
  for (std::size_t b = 0; b < s.rdf.r.size(); ++b)
    rdf << s.method << "," << s.level << "," << num(s.rdf.r[b] / s.r) << "," << num(s.rdf.r[b]) << "," << num(s.rdf.g[b])
        << "\n";
  for (std::size_t b = 0; b < s.spectrum.radial_power.size(); ++b)
    spec << s.method << "," << s.level << "," << num(s.spectrum.radial_frequency[b] * s.r) << ","
         << num(s.spectrum.radial_frequency[b]) << "," << num(s.spectrum.radial_power[b]) << "\n";
}

std::string setJson(const SetResult &s) {
  std::ostringstream j;
  j << "{\"method\": \"" << s.method << "\", \"level\": " << s.level << ", \"r\": " << num(s.r)
    << ", \"cell\": " << (s.cell > 0.0 ? num(s.cell) : "null") << ", \"count\": " << s.count
    << ", \"min_nn_over_r\": " << num(s.min_nn_over_r) << ", \"mean_nn_over_r\": " << num(s.mean_nn_over_r)
    << ", \"power_low\": " << num(s.power_low) << ", \"power_max\": " << num(s.power_max) << "}";
  return j.str();
}

std::string shellQuote(const std::string &s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

void runAnalyze(const AnalyzeArgs &a) {
  std::vector<InputPath> inputs = {{"input", a.sampling}, {"--poses", a.poses}};
  for (const std::string &in : a.inputs) inputs.push_back({"--input", in});
  checkPaths(inputs, {}, {{"-o", a.out_dir, {"analysis.json", "levels.csv", "rdf.csv", "spectrum.csv"}}});
  CellSizeOptions cell = a.cell;
  const double cell_size = resolveSamplingCell(cell, a.sampling, cell.spacing.has_value());
  if (!a.patch.empty() && a.patch.size() != 3) throw std::invalid_argument("--patch: expected cx,cy,size");
  SamplingCloud cloud = loadSampling(a.sampling);
  if (!cloud.has_level) throw std::invalid_argument(a.sampling + ": no `level` field (not an hpds sampling?)");
  if (a.frame >= 0 && !cloud.has_frame)
    throw std::invalid_argument("--frame: '" + a.sampling + "' has no 'frame' field (only a scan-mode output of several "
                                "frames has one)");
  std::optional<std::uint32_t> frame;
  if (!cloud.frame.empty()) {
    // Scan-mode files of several inputs stack one sampling per frame; mixing them would break the spacing.
    frame = a.frame >= 0 ? static_cast<std::uint32_t>(a.frame) : *std::min_element(cloud.frame.begin(), cloud.frame.end());
    cloud = keepFrame(cloud, *frame);
    std::cout << "analysing frame " << *frame << " of the scan-mode file (--frame to choose another)\n";
  }
  if (cloud.xyz.empty()) throw std::invalid_argument(a.sampling + ": no samples to analyse");
  const int max_level = cloud.maxLevel();
  if (!a.inputs.empty() && a.compare_level > max_level)
    throw std::invalid_argument("--compare-level " + std::to_string(a.compare_level) +
                                ": the sampling's deepest level is " + std::to_string(max_level));
  // 1. Per level: counts and 3D nearest-neighbour spacing of the union U_D.
  std::vector<std::vector<Eigen::Vector3d>> unions(static_cast<std::size_t>(max_level) + 1);
  std::vector<std::size_t> counts(static_cast<std::size_t>(max_level) + 1, 0);
  for (std::size_t i = 0; i < cloud.xyz.size(); ++i) {
    ++counts[static_cast<std::size_t>(cloud.level[i])];
    for (int d = cloud.level[i]; d <= max_level; ++d) unions[static_cast<std::size_t>(d)].push_back(cloud.xyz[i]);
  }
  // Chosen before the folder is made: a sampling without a planar patch is the common failure.
  const Patch patch = choosePatch(a, unions.back());
  RunFolder folder(a.out_dir);
  const fs::path out(a.out_dir);
  std::cout << "patch: centre (" << patch.center_xy.x() << ", " << patch.center_xy.y() << "), " << patch.size
            << " m, plane normal (" << patch.plane.normal.transpose() << "), rms " << patch.plane.rms << " m"
            << (patch.automatic ? " (found automatically)" : "") << "\n";

  TextFile levels_csv(folder.file("levels.csv"));
  TextFile rdf_csv(folder.file("rdf.csv"));
  TextFile spec_csv(folder.file("spectrum.csv"));
  levels_csv << "level,r,count,union_count,min_nn_over_r,mean_nn_over_r,patch_points\n";
  rdf_csv << "method,level,r_over_rD,r,g\n";
  spec_csv << "method,level,f_times_rD,f,power\n";
  std::ostringstream levels_json;
  std::vector<SetResult> level_sets;
  // Each analysed level's patch points: their pictures are written once the comparison cannot fail any more.
  std::vector<std::pair<std::size_t, std::vector<Eigen::Vector2d>>> level_pictures;
  std::cout << "level        r_D    count    union  min_nn/r  mean_nn/r  patch\n";
  for (int d = 0; d <= max_level; ++d) {
    const auto &u = unions[static_cast<std::size_t>(d)];
    const double r = poissonRadius(cell_size, d);
    double mn = NAN, mean = NAN;
    if (u.size() >= 2) {
      const std::vector<double> nn = nearestNeighborDistances(u);
      mn = *std::min_element(nn.begin(), nn.end()) / r;
      mean = std::accumulate(nn.begin(), nn.end(), 0.0) / static_cast<double>(nn.size()) / r;
    }
    SetResult s;
    s.method = "hpds";
    s.level = d;
    s.r = r;
    const std::vector<Eigen::Vector2d> pts = inWindow(u, patch, a.plane_band);
    // Fewer points than this give spectra of pure noise; the RDF also needs a window of a few radii.
    if (pts.size() >= 30 && a.rdf_max * r < 0.45 * patch.window.size) analyseSet(s, pts, patch, a);
    s.count = pts.size();
    if (s.analysed) level_pictures.emplace_back(level_sets.size(), pts);
    writeSetCsvRows(rdf_csv, spec_csv, s);
    levels_csv << d << "," << num(r) << "," << counts[static_cast<std::size_t>(d)] << "," << u.size() << "," << num(mn)
               << "," << num(mean) << "," << pts.size() << "\n";
    levels_json << (d ? ",\n    " : "") << "{\"level\": " << d << ", \"r\": " << num(r)
                << ", \"count\": " << counts[static_cast<std::size_t>(d)] << ", \"union_count\": " << u.size()
                << ", \"min_nn_over_r\": " << num(mn) << ", \"mean_nn_over_r\": " << num(mean)
                << ", \"patch\": " << setJson(s) << "}";
    std::printf("%5d %10.4f %8zu %8zu %9.3f %10.3f %6zu%s\n", d, r, counts[static_cast<std::size_t>(d)], u.size(), mn,
                mean, pts.size(), s.analysed ? "" : "  (too few patch points for spectra)");
    level_sets.push_back(std::move(s));
  }

  // 2. Figure 5: the baselines on the same input, each at hpds's patch count of the compared level.
  std::vector<SetResult> compare;
  const int cmp_level = a.compare_level >= 0 ? a.compare_level : max_level;
  if (!a.inputs.empty()) {
    const std::vector<Eigen::Vector3d> input = loadInputs(a.inputs, a.poses);
    // Only the patch's slab (plus a margin, so cells crossing the window edge see all their points) matters.
    std::vector<Eigen::Vector3d> local;
    const double margin = 1.0;
    for (const auto &p : input) {
      const Eigen::Vector3d d = p - patch.plane.centroid;
      const double pu = d.dot(patch.plane.u), pv = d.dot(patch.plane.v);
      if (std::abs(d.dot(patch.plane.normal)) <= a.plane_band && pu >= patch.window.x0 - margin &&
          pv >= patch.window.y0 - margin && pu < patch.window.x0 + patch.window.size + margin &&
          pv < patch.window.y0 + patch.window.size + margin)
        local.push_back(p);
    }
    const SetResult &h = level_sets[static_cast<std::size_t>(cmp_level)];
    const std::size_t target = h.count;
    const double r = h.r;
    std::cout << "comparison at level " << cmp_level << " (r_D " << r << " m): " << target << " hpds samples in the patch, "
              << local.size() << " input points near it\n";
    if (!h.analysed || target < 30) throw std::invalid_argument("--compare-level " + std::to_string(cmp_level) +
                                                 ": too few hpds samples in the patch to compare");
    compare.push_back(h);
    std::vector<Eigen::Vector2d> random_pick;
    auto gather = [&](const std::vector<std::uint32_t> &idx) {
      std::vector<Eigen::Vector3d> p;
      p.reserve(idx.size());
      for (std::uint32_t i : idx) p.push_back(local[i]);
      return p;
    };
    auto origin = [&](double c) { return Eigen::Vector3d::Constant(a.grid_offset * c); };
    using Maker = std::function<std::vector<Eigen::Vector3d>(double)>;
    const std::vector<std::pair<std::string, Maker>> grids = {
        {"grid_random", [&](double c) { return gather(gridRandom(local, c, a.seed, origin(c))); }},
        {"grid_closest", [&](double c) { return gather(gridClosestToCenter(local, c, origin(c))); }},
        {"voxel_centroid", [&](double c) { return voxelCentroids(local, c, origin(c)); }},
    };
    for (const auto &g : grids) {
      SetResult s;
      s.method = g.first;
      s.level = cmp_level;
      s.r = r;
      s.cell = cellForCount([&](double c) { return inWindow(g.second(c), patch, a.plane_band).size(); }, target,
                            0.05 * r, 20.0 * r);
      analyseSet(s, inWindow(g.second(s.cell), patch, a.plane_band), patch, a);
      compare.push_back(std::move(s));
    }
    {
      SetResult s;
      s.method = "random";
      s.level = cmp_level;
      s.r = r;
      std::vector<Eigen::Vector2d> all = inWindow(local, patch, a.plane_band);
      std::vector<std::uint32_t> idx(all.size());
      std::iota(idx.begin(), idx.end(), 0u);
      seededShuffle(idx, a.seed);
      idx.resize(std::min(idx.size(), target));
      for (std::uint32_t i : idx) random_pick.push_back(all[i]);
      analyseSet(s, random_pick, patch, a);
      compare.push_back(std::move(s));
    }
    std::cout << "method           count      cell  min_nn/r  mean_nn/r  P(low f)  P max\n";
    for (SetResult &s : compare) {
      // A baseline with fewer than two points in the patch has no statistics (its inputs are not where the sampling
      // is: a map analysed without --poses); the hpds set's own count was checked above.
      if (s.method != "hpds" && !s.analysed)
        std::cerr << "hpds: warning: only " << s.count << " point(s) of the " << s.method
                  << " baseline fall in the patch: are the --input clouds in the sampling's frame (map mode needs "
                     "--poses)?\n";
      if (s.method != "hpds" && s.analysed) {
        writeSetCsvRows(rdf_csv, spec_csv, s);
        writePeriodogramPng(folder.file("periodogram_" + setName(s) + ".png"), s.spectrum);
      }
      std::printf("%-15s %6zu %9.4f %9.3f %10.3f %9.3f %6.1f\n", s.method.c_str(), s.count, s.cell, s.min_nn_over_r,
                  s.mean_nn_over_r, s.power_low, s.power_max);
    }
    // Point pictures of the baselines (hpds's was written with its level).
    for (const auto &g : grids) {
      const auto it = std::find_if(compare.begin(), compare.end(), [&](const SetResult &s) { return s.method == g.first; });
      writePointsPng(folder.file("points_" + setName(*it) + ".png"), inWindow(g.second(it->cell), patch, a.plane_band),
                     patch.window, r);
    }
    writePointsPng(folder.file("points_random_L" + std::to_string(cmp_level) + ".png"), random_pick, patch.window, r);
  }

  for (const auto &[index, pts] : level_pictures) {
    const SetResult &s = level_sets[index];
    writePeriodogramPng(folder.file("periodogram_" + setName(s) + ".png"), s.spectrum);
    writePointsPng(folder.file("points_" + setName(s) + ".png"), pts, patch.window, s.r);
  }

  {
    TextFile json(folder.file("analysis.json"));
    json << "{\n  \"sampling\": " << jsonQuoted(a.sampling) << ",\n  \"cell_size\": " << num(cell_size)
         << ",\n  \"frame\": " << (frame ? std::to_string(*frame) : "null") << ",\n  \"patch\": {\"center\": ["
         << num(patch.center_xy.x()) << ", " << num(patch.center_xy.y()) << "], \"size\": " << num(patch.size)
         << ", \"window\": " << num(patch.window.size) << ", \"normal\": [" << num(patch.plane.normal.x()) << ", "
         << num(patch.plane.normal.y()) << ", " << num(patch.plane.normal.z()) << "], \"rms\": " << num(patch.plane.rms)
         << ", \"band\": " << num(a.plane_band) << ", \"grid_offset\": " << num(a.grid_offset) << ", \"automatic\": " << (patch.automatic ? "true" : "false")
         << "},\n  \"notes\": \"min/mean_nn_over_r: nearest-neighbour distance over r_D (levels: 3D in U_D; patch "
            "sets: 2D in the window). power_low: mean radial power for f*r_D <= 0.35. power_max: largest periodogram "
            "value off DC.\",\n  \"levels\": [\n    "
         << levels_json.str() << "\n  ],\n  \"comparison\": ";
    if (compare.empty()) {
      json << "null";
    } else {
      json << "{\"level\": " << cmp_level << ", \"sets\": [\n    ";
      for (std::size_t i = 0; i < compare.size(); ++i) json << (i ? ",\n    " : "") << setJson(compare[i]);
      json << "\n  ]}";
    }
    json << "\n}\n";
    json.close();
  }
  // The plot script reads these files: they must be complete first.
  levels_csv.close();
  rdf_csv.close();
  spec_csv.close();
  folder.keep();
  std::cout << "wrote " << (out / "analysis.json").string() << ", levels.csv, rdf.csv, spectrum.csv and PNGs\n";

  if (a.no_plots) return;
  const std::string script = a.plot_script.empty() ? defaultPlotScript() : a.plot_script;
  if (!fs::exists(script)) {
    std::cerr << "hpds: warning: plot script " << script << " not found; curves not plotted (data is written)\n";
    return;
  }
  // Debian's interpreter first: that is where python3-matplotlib is installed, whatever python3 comes first on PATH.
  const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
  const std::string cmd = python + " " + shellQuote(script) + " analysis " + shellQuote(a.out_dir);
  if (std::system(cmd.c_str()) != 0)
    std::cerr << "hpds: warning: '" << cmd << "' failed (python3-matplotlib missing?); data is written\n";
}

}  // namespace

void addAnalyzeCommand(CLI::App &app) {
  auto a = std::make_shared<AnalyzeArgs>();
  CLI::App *cmd = app.add_subcommand(
      "analyze", "blue-noise analysis of a sampling per level (RDF, power spectrum) and, with --input, versus grids");
  cmd->add_option("sampling", a->sampling, "sampling written by hpds sample (x y z level)")->required();
  addCellSizeOptions(*cmd, a->cell);
  cmd->add_option("-o,--output", a->out_dir, "output directory")->required()->check(nonEmptyPath());
  auto *input = cmd->add_option("--input", a->inputs,
                                "the input clouds of the sampling: adds the grid baselines at equal count");
  // Both act on the --input clouds only: without them they would be dropped without a word.
  cmd->add_option("--poses", a->poses, "poses of the inputs, KITTI or TUM (as given to hpds sample)")->needs(input);
  cmd->add_option("--patch", a->patch, "cx,cy,size [m]: the square xy patch to analyse (default: found automatically)")
      ->delimiter(',')
      ->expected(3)
      ->check(finiteIn(-1e9, 1e9));
  cmd->add_option("--patch-size", a->patch_size, "[m] edge of the automatically found patch")
      ->capture_default_str()
      ->check(finiteIn(1e-6, 1e4));
  cmd->add_option("--plane-band", a->plane_band, "[m] samples within this distance of the patch plane are analysed")
      ->capture_default_str()
      ->check(finiteIn(0.0, 1e4));
  cmd->add_option("--grid-offset", a->grid_offset,
                  "baseline grids start at this fraction of a cell; 0.5 keeps a flat ground at z = 0 mid-cell")
      ->capture_default_str()
      ->check(finiteIn(0.0, 1.0));
  cmd->add_option("--compare-level", a->compare_level,
                  "with --input: level of the baseline comparison (default: the finest)")
      ->check(integerIn(-1, 21))
      ->needs(input);
  cmd->add_option("--frame", a->frame, "scan-mode files: the frame to analyse (default: the first)")
      ->check(integerIn(0, 4294967295));
  cmd->add_option("--seed", a->seed, "seed of the random baselines")->capture_default_str()->check(unsigned64());
  cmd->add_option("--rdf-bins", a->rdf_bins, "RDF bins")->capture_default_str()->check(integerIn(1, 10000));
  cmd->add_option("--rdf-max", a->rdf_max, "RDF range in units of r_D")->capture_default_str()->check(finiteIn(1e-3, 100.0));
  cmd->add_option("--freq-max", a->freq_max, "spectrum range in units of 1/r_D")
      ->capture_default_str()
      ->check(finiteIn(1e-3, 64.0));
  cmd->add_option("--threads", a->threads, "worker threads for the spectra, 0 = all cores")
      ->capture_default_str()
      ->check(integerIn(0, 1024));
  cmd->add_flag("--no-plots", a->no_plots, "write data and PNG images only, do not run the plot script");
  cmd->add_option("--plot-script", a->plot_script, "plot script (default: " + defaultPlotScript() + ")");
  cmd->callback([a] { runAnalyze(*a); });
}

}  // namespace hpds::cli
