// `hpds render CLOUD -o DIR`: PNG pictures of a sampling (or any cloud) seen from the top, the front and the side,
// coloured by level, by normal (RGB) and by a local feature value. Writes DIR/<prefix>_<colour>_<view>.png.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "CliOptions.hpp"
#include "Commands.hpp"
#include "OutputPaths.hpp"
#include "QualityIo.hpp"
#include "hpds/eval/BlueNoiseAnalysis.hpp"
#include "hpds/sampling/InsertionOrderer.hpp"
#include "hpds/eval/PointRender.hpp"

namespace hpds::cli {

namespace {

namespace fs = std::filesystem;

struct RenderArgs {
  std::string cloud;
  std::string out_dir;
  std::string prefix = "render";
  std::vector<std::string> colors = {"level", "normal", "feature"};
  std::vector<std::string> views = {"top", "front", "side"};
  std::vector<double> crop;  // x0,y0,z0,x1,y1,z1
  int max_level = -1;
  long frame = -1;
  int width = 1600;
  int height = 1000;
  double splat = 0.0;
  std::string feature = "curvature";
  double feature_radius = 0.0;
  int threads = 0;
};

ViewDirection parseView(const std::string &v) {
  if (v == "top") return ViewDirection::Top;
  if (v == "front") return ViewDirection::Front;
  if (v == "side") return ViewDirection::Side;
  throw std::invalid_argument("--view: expected top, front or side, got '" + v + "'");
}

double medianSpacing(const std::vector<Eigen::Vector3d> &pts) {
  if (pts.size() < 2) return 0.0;
  std::vector<double> nn = nearestNeighborDistances(pts);
  nn.erase(std::remove_if(nn.begin(), nn.end(), [](double d) { return !std::isfinite(d); }), nn.end());
  if (nn.empty()) return 0.0;
  std::nth_element(nn.begin(), nn.begin() + static_cast<long>(nn.size() / 2), nn.end());
  return nn[nn.size() / 2];
}

/// Feature per point scaled to [0, 1] by its 98th percentile (so a few extreme values do not flatten the picture).
std::vector<double> featureValues(const SamplingCloud &c, const RenderArgs &a, double spacing) {
  std::vector<double> f(c.xyz.size(), NAN);
  if (a.feature == "curvature" && !c.curvature.empty()) {
    for (std::size_t i = 0; i < f.size(); ++i) f[i] = c.curvature[i];
  } else {
    const InsertionOrder kind = a.feature == "sphericity" ? InsertionOrder::Sphericity : InsertionOrder::SurfaceVariation;
    const double radius = a.feature_radius > 0.0 ? a.feature_radius : 3.0 * spacing;
    // One point, or all at one spot: no spacing to derive a radius from, and no neighbourhood to have a feature.
    if (!(radius > 0.0)) return f;
    std::vector<double> xyz(3 * c.xyz.size());
    for (std::size_t i = 0; i < c.xyz.size(); ++i)
      for (int k = 0; k < 3; ++k) xyz[3 * i + static_cast<std::size_t>(k)] = c.xyz[i][k];
    std::vector<std::uint32_t> all(c.xyz.size());
    for (std::uint32_t i = 0; i < all.size(); ++i) all[i] = i;
    const std::vector<float> v = localFeature(xyz.data(), all, kind, radius, a.threads);
    for (std::size_t i = 0; i < f.size(); ++i) f[i] = v[i];
  }
  std::vector<double> finite;
  for (double v : f)
    if (std::isfinite(v)) finite.push_back(v);
  if (finite.empty()) return f;
  const std::size_t k = std::min(finite.size() - 1, static_cast<std::size_t>(0.98 * static_cast<double>(finite.size())));
  std::nth_element(finite.begin(), finite.begin() + static_cast<long>(k), finite.end());
  const double top = finite[k] > 0.0 ? finite[k] : 1.0;
  for (double &v : f) v = std::isfinite(v) ? std::min(1.0, v / top) : NAN;
  return f;
}

void runRender(const RenderArgs &a) {
  for (const std::string &colour : a.colors)
    if (colour != "level" && colour != "normal" && colour != "feature")
      throw std::invalid_argument("--color: expected level, normal or feature, got '" + colour + "'");
  for (const std::string &view : a.views) (void)parseView(view);
  // Checked here, not where the feature pictures are drawn: that comes after the level and normal ones.
  if (a.feature != "curvature" && a.feature != "surface_variation" && a.feature != "sphericity")
    throw std::invalid_argument("--feature: expected curvature, surface_variation or sphericity, got '" + a.feature +
                                "'");
  std::vector<std::string> pictures;
  for (const std::string &colour : a.colors)
    for (const std::string &view : a.views) pictures.push_back(a.prefix + "_" + colour + "_" + view + ".png");
  checkPaths({{"input", a.cloud}}, {}, {{"-o", a.out_dir, pictures}});
  if (!a.crop.empty() && a.crop.size() != 6) throw std::invalid_argument("--crop: expected x0,y0,z0,x1,y1,z1");
  for (int k = 0; k < 3 && !a.crop.empty(); ++k)
    if (a.crop[k] > a.crop[k + 3])
      throw std::invalid_argument(std::string("--crop: ") + "xyz"[k] + "0 = " + std::to_string(a.crop[k]) + " > " +
                                  "xyz"[k] + "1 = " + std::to_string(a.crop[k + 3]) +
                                  " (the box is x0,y0,z0 of its lower corner, then x1,y1,z1 of its upper one)");
  SamplingCloud c = loadSampling(a.cloud);
  if (a.frame >= 0) {
    if (!c.has_frame)
      throw std::invalid_argument("--frame: '" + a.cloud + "' has no 'frame' field (only a scan-mode output of several "
                                  "frames has one)");
    c = keepFrame(c, static_cast<std::uint32_t>(a.frame));
    if (c.xyz.empty())
      throw std::invalid_argument("--frame: '" + a.cloud + "' holds no sample of frame " + std::to_string(a.frame));
  }
  // Keep what will be drawn, so spacing and features describe the picture, not the whole file.
  Eigen::AlignedBox3d box;
  if (!a.crop.empty()) box = Eigen::AlignedBox3d(Eigen::Vector3d(a.crop[0], a.crop[1], a.crop[2]),
                                                 Eigen::Vector3d(a.crop[3], a.crop[4], a.crop[5]));
  SamplingCloud kept;
  for (std::size_t i = 0; i < c.xyz.size(); ++i) {
    if (!c.xyz[i].allFinite() || (!box.isEmpty() && !box.contains(c.xyz[i]))) continue;
    if (a.max_level >= 0 && !c.level.empty() && c.level[i] > a.max_level) continue;
    kept.xyz.push_back(c.xyz[i]);
    if (!c.level.empty()) kept.level.push_back(c.level[i]);
    if (!c.normal.empty()) kept.normal.push_back(c.normal[i]);
    if (!c.curvature.empty()) kept.curvature.push_back(c.curvature[i]);
  }
  if (kept.xyz.empty())
    throw std::invalid_argument(a.cloud + ": no points to render (check --crop / --max-level; points with a NaN or "
                                          "infinite coordinate are not drawn)");
  const double spacing = medianSpacing(kept.xyz);
  RunFolder folder(a.out_dir);
  std::vector<std::string> written;

  RenderOptions o;
  o.max_width = a.width;
  o.max_height = a.height;
  o.crop = box;
  // The splat in pixels is what costs: bounded at each view's scale before anything is drawn (the default, half
  // the median spacing, shrinks to fit).
  std::vector<double> splat;
  for (const std::string &view : a.views) {
    o.view = parseView(view);
    const double scale = renderScale(kept.xyz, o);
    const double max_splat = scale > 0.0 ? kMaxSplatPixels / scale : 0.0;
    if (a.splat > max_splat && scale > 0.0)
      throw std::invalid_argument("--splat: " + std::to_string(a.splat) + " m is " +
                                  std::to_string(std::lround(a.splat * scale)) + " px in the " + view +
                                  " view, more than the " + std::to_string(int(kMaxSplatPixels)) +
                                  " px a splat may have (at most " + std::to_string(max_splat) + " m here)");
    splat.push_back(a.splat > 0.0 ? a.splat : std::min(0.5 * spacing, max_splat));
  }
  for (const std::string &colour : a.colors) {
    std::vector<Rgb> rgb(kept.xyz.size());
    std::vector<double> priority;
    if (colour == "level") {
      if (kept.level.empty()) {
        std::cerr << "hpds: warning: " << a.cloud << " has no level field; skipping --color level\n";
        continue;
      }
      // Coarse levels on top: they are few and would otherwise vanish under the dense fine levels.
      for (std::size_t i = 0; i < rgb.size(); ++i) {
        rgb[i] = levelColor(kept.level[i]);
        priority.push_back(-kept.level[i]);
      }
    } else if (colour == "normal") {
      if (kept.normal.empty()) {
        std::cerr << "hpds: warning: " << a.cloud << " has no normals (sample with --normals); skipping --color normal\n";
        continue;
      }
      for (std::size_t i = 0; i < rgb.size(); ++i) rgb[i] = normalColor(kept.normal[i]);
    } else if (colour == "feature") {
      const std::vector<double> f = featureValues(kept, a, spacing);
      for (std::size_t i = 0; i < rgb.size(); ++i) rgb[i] = scalarColor(f[i]);
    } else {
      throw std::invalid_argument("--color: expected level, normal or feature, got '" + colour + "'");
    }
    for (std::size_t v = 0; v < a.views.size(); ++v) {
      const std::string &view = a.views[v];
      o.view = parseView(view);
      o.splat_radius = splat[v];
      const std::string name = a.prefix + "_" + colour + "_" + view + ".png";
      writePng(folder.file(name), renderPoints(kept.xyz, rgb, o, priority.empty() ? nullptr : &priority));
      written.push_back((fs::path(a.out_dir) / name).string());
    }
  }
  folder.keep();
  for (const std::string &path : written) std::cout << "wrote " << path << "\n";
}

}  // namespace

void addRenderCommand(CLI::App &app) {
  auto a = std::make_shared<RenderArgs>();
  CLI::App *cmd = app.add_subcommand("render", "PNG pictures of a sampling: top/front/side views by level, normal, feature");
  cmd->add_option("cloud", a->cloud, "sampling (or any cloud) to draw")->required();
  cmd->add_option("-o,--output", a->out_dir, "output directory")->required()->check(nonEmptyPath());
  cmd->add_option("--prefix", a->prefix, "file name prefix (no '/')")
      ->capture_default_str()
      ->check(fileNamePrefix());
  cmd->add_option("--color", a->colors, "level, normal, feature (comma separated)")->delimiter(',')->capture_default_str();
  cmd->add_option("--view", a->views, "top, front, side (comma separated)")->delimiter(',')->capture_default_str();
  cmd->add_option("--crop", a->crop, "x0,y0,z0,x1,y1,z1 [m]: draw only this box")
      ->delimiter(',')
      ->expected(6)
      ->check(finiteIn(-1e9, 1e9));
  cmd->add_option("--max-level", a->max_level, "draw levels 0..D only")->check(integerIn(-1, 21));
  cmd->add_option("--frame", a->frame, "scan-mode files: draw this frame only")->check(integerIn(0, 4294967295));
  // A picture of 8192 x 8192 already takes 0.7 GB (colour and depth buffers). The smallest one has a pixel or more
  // inside its margins (renderPoints refuses less).
  const int min_side = 2 * RenderOptions{}.margin_px + 2;
  cmd->add_option("--width", a->width, "[px] maximum image width")
      ->capture_default_str()
      ->check(integerIn(min_side, 8192));
  cmd->add_option("--height", a->height, "[px] maximum image height")
      ->capture_default_str()
      ->check(integerIn(min_side, 8192));
  cmd->add_option("--splat", a->splat, "[m] point disc radius (default: half the median spacing)")
      ->check(finiteIn(0.0, 1e6));
  cmd->add_option("--feature", a->feature, "curvature (the file's, else surface variation) | surface_variation | "
                                           "sphericity")->capture_default_str();
  cmd->add_option("--feature-radius", a->feature_radius, "[m] PCA radius of computed features (default: 3 x spacing)")
      ->check(finiteIn(0.0, 1e6));
  cmd->add_option("--threads", a->threads, "worker threads, 0 = all cores")->capture_default_str()->check(integerIn(0, 1024));
  cmd->callback([a] { runRender(*a); });
}

}  // namespace hpds::cli
