#include "hpds/eval/PointRender.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace hpds {

namespace {

// (right, up, toward viewer) coordinates of a world point for each view.
Eigen::Vector3d viewCoords(const Eigen::Vector3d &p, ViewDirection v) {
  switch (v) {
    case ViewDirection::Top:
      return {p.x(), p.y(), p.z()};
    case ViewDirection::Front:
      return {p.x(), p.z(), -p.y()};
    case ViewDirection::Side:
      return {p.y(), p.z(), p.x()};
  }
  return p;
}

// The extent drawn and its scale, shared by renderPoints and renderScale.
struct Framing {
  Eigen::AlignedBox2d extent;
  std::vector<std::size_t> used;  // the points drawn
  double scale = 0.0;             // pixels per metre
};

Framing frame(const std::vector<Eigen::Vector3d> &points, const RenderOptions &o) {
  if (o.max_width <= 2 * o.margin_px + 1 || o.max_height <= 2 * o.margin_px + 1)
    throw std::invalid_argument("renderPoints: image too small for its margin");
  if (o.max_width > kMaxRenderSide || o.max_height > kMaxRenderSide)
    throw std::invalid_argument("renderPoints: " + std::to_string(o.max_width) + " x " + std::to_string(o.max_height) +
                                " px, more than the " + std::to_string(kMaxRenderSide) + " px a side may have");
  Framing f;
  const bool cropped = !o.crop.isEmpty();
  f.used.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite() || (cropped && !o.crop.contains(points[i]))) continue;
    f.used.push_back(i);
    if (!cropped) f.extent.extend(viewCoords(points[i], o.view).head<2>());
  }
  if (cropped) {
    f.extent.extend(viewCoords(o.crop.min(), o.view).head<2>());
    f.extent.extend(viewCoords(o.crop.max(), o.view).head<2>());
  }
  if (f.extent.isEmpty()) return f;
  const Eigen::Vector2d span = (f.extent.max() - f.extent.min()).cwiseMax(1e-9);
  // The extent maps onto pixel centres, so its far edge needs one pixel more than span * scale.
  const double avail_w = o.max_width - 2 * o.margin_px - 1, avail_h = o.max_height - 2 * o.margin_px - 1;
  f.scale = std::min(avail_w / span.x(), avail_h / span.y());
  return f;
}

}  // namespace

double renderScale(const std::vector<Eigen::Vector3d> &points, const RenderOptions &options) {
  return frame(points, options).scale;
}

RgbImage renderPoints(const std::vector<Eigen::Vector3d> &points, const std::vector<Rgb> &colors,
                      const RenderOptions &o, const std::vector<double> *priority) {
  if (colors.size() != points.size()) throw std::invalid_argument("renderPoints: one colour per point is required");
  if (priority && priority->size() != points.size())
    throw std::invalid_argument("renderPoints: one priority per point is required");
  if (!(std::isfinite(o.splat_radius) && o.splat_radius >= 0.0))
    throw std::invalid_argument("splat_radius: must be a finite number >= 0 [m]");
  const Framing f = frame(points, o);
  const Eigen::AlignedBox2d &extent = f.extent;
  const double scale = f.scale;
  if (extent.isEmpty()) return RgbImage(o.max_width, o.max_height, o.background[0], o.background[1], o.background[2]);
  const Eigen::Vector2d span = (extent.max() - extent.min()).cwiseMax(1e-9);
  const int w = static_cast<int>(std::ceil(span.x() * scale - 1e-9)) + 1 + 2 * o.margin_px;
  const int h = static_cast<int>(std::ceil(span.y() * scale - 1e-9)) + 1 + 2 * o.margin_px;
  const double rp = std::max(0.5, o.splat_radius * scale);
  // A disc costs its area per point: larger ones made a render of a million points run for hours.
  if (rp > kMaxSplatPixels)
    throw std::invalid_argument("splat_radius: " + std::to_string(o.splat_radius) + " m is " +
                                std::to_string(std::lround(rp)) + " px at this picture's scale, more than the " +
                                std::to_string(int(kMaxSplatPixels)) + " px a splat may have (at most " +
                                std::to_string(kMaxSplatPixels / scale) + " m here)");
  const std::vector<std::size_t> &used = f.used;
  RgbImage img(w, h, o.background[0], o.background[1], o.background[2]);
  std::vector<double> depth(static_cast<std::size_t>(w) * h, -std::numeric_limits<double>::infinity());
  const int reach = static_cast<int>(std::ceil(rp));
  for (std::size_t i : used) {
    const Eigen::Vector3d v = viewCoords(points[i], o.view);
    const double px = o.margin_px + 0.5 + (v.x() - extent.min().x()) * scale;
    const double py = o.margin_px + 0.5 + (extent.max().y() - v.y()) * scale;
    const int cx = static_cast<int>(std::floor(px)), cy = static_cast<int>(std::floor(py));
    for (int dy = -reach; dy <= reach; ++dy)
      for (int dx = -reach; dx <= reach; ++dx) {
        const int x = cx + dx, y = cy + dy;
        if (x < 0 || y < 0 || x >= w || y >= h) continue;
        const double ex = x + 0.5 - px, ey = y + 0.5 - py;
        if (ex * ex + ey * ey > rp * rp && !(dx == 0 && dy == 0)) continue;
        double &d = depth[static_cast<std::size_t>(y) * w + x];
        const double z = priority ? (*priority)[i] : v.z();
        if (z <= d) continue;
        d = z;
        img.set(x, y, colors[i][0], colors[i][1], colors[i][2]);
      }
  }
  return img;
}

Rgb levelColor(int level) {
  // Hand-picked to stay distinguishable next to each other and on white.
  static const Rgb palette[12] = {{200, 30, 30},  {240, 130, 0},  {200, 180, 0},  {90, 170, 30},
                                  {0, 150, 110},  {0, 160, 200},  {30, 80, 200},  {110, 50, 190},
                                  {190, 40, 160}, {120, 80, 40},  {90, 90, 90},   {0, 0, 0}};
  return palette[((level % 12) + 12) % 12];
}

Rgb normalColor(const Eigen::Vector3d &n) {
  if (!n.allFinite()) return {160, 160, 160};
  Rgb c;
  for (int a = 0; a < 3; ++a)
    c[static_cast<std::size_t>(a)] = static_cast<std::uint8_t>(std::lround(std::clamp((n[a] + 1.0) * 0.5, 0.0, 1.0) * 255.0));
  return c;
}

Rgb scalarColor(double t) {
  if (std::isnan(t)) return {160, 160, 160};
  t = std::clamp(t, 0.0, 1.0);
  // Control points of a monotone-lightness ramp (own choice, close in spirit to viridis).
  static const double stops[6][3] = {{40, 20, 90}, {50, 70, 150}, {30, 130, 150}, {50, 180, 110}, {170, 210, 50},
                                     {250, 230, 30}};
  const double s = t * 5.0;
  const int i = std::min(4, static_cast<int>(s));
  const double f = s - i;
  Rgb c;
  for (int a = 0; a < 3; ++a)
    c[static_cast<std::size_t>(a)] =
        static_cast<std::uint8_t>(std::lround(stops[i][a] + f * (stops[i + 1][a] - stops[i][a])));
  return c;
}

}  // namespace hpds
