// PointRender: orthographic splat renderings of point sets, for pictures a person inspects (no GPU, no window).
//
// Contract
// - Views: Top looks down -z (image right = +x, image up = +y); Front looks along +y (right = +x, up = +z); Side
//   looks along -x (right = +y, up = +z). The scale fits the points' (or the crop box's) extent into
//   max_width x max_height pixels, keeping the aspect ratio, with a `margin_px` border.
// - Each point is a filled disc of `splat_radius` metres (at least 1 pixel across); the point nearest the viewer wins
//   a pixel (a depth buffer), so front surfaces hide what lies behind them. With `priority` (one value per point) the
//   largest priority wins instead, whatever the depth: e.g. coarse levels drawn over the dense fine ones.
// - Colour helpers: levelColor is a fixed palette of 12 distinct hues cycling with the level; normalColor maps a unit
//   normal n to ((n + 1) / 2) * 255 per axis (x red, y green, z blue), the paper's normal images; scalarColor maps
//   t in [0, 1] (clamped; NaN -> grey) through a dark-blue -> teal -> yellow ramp with increasing lightness, so
//   the value order survives greyscale printing.
// - Bounds (std::invalid_argument beyond them): each side at most kMaxRenderSide px; a splat of at most
//   kMaxSplatPixels px radius, since a disc costs its area per point; a finite splat_radius >= 0.
// - Non-finite points are skipped. Deterministic.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <vector>

#include "hpds/eval/PngWriter.hpp"

namespace hpds {

using Rgb = std::array<std::uint8_t, 3>;

enum class ViewDirection { Top, Front, Side };

struct RenderOptions {
  ViewDirection view = ViewDirection::Top;
  int max_width = 1600;      ///< [px]
  int max_height = 1200;     ///< [px]
  int margin_px = 8;
  double splat_radius = 0.0; ///< [m]; 0 = one pixel
  Rgb background{255, 255, 255};
  Eigen::AlignedBox3d crop;  ///< empty (default): every point; else only points inside, and the view fits the box
};

inline constexpr int kMaxRenderSide = 16384;
inline constexpr double kMaxSplatPixels = 16.0;

/// Pixels per metre renderPoints uses for these points and options (0 when nothing is drawn).
[[nodiscard]] double renderScale(const std::vector<Eigen::Vector3d> &points, const RenderOptions &options);

[[nodiscard]] RgbImage renderPoints(const std::vector<Eigen::Vector3d> &points, const std::vector<Rgb> &colors,
                                    const RenderOptions &options, const std::vector<double> *priority = nullptr);

[[nodiscard]] Rgb levelColor(int level);
[[nodiscard]] Rgb normalColor(const Eigen::Vector3d &normal);
[[nodiscard]] Rgb scalarColor(double t);

}  // namespace hpds
