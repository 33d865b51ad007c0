#include "hpds/config/Config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "hpds/config/YamlScalar.hpp"
#include "hpds/sampling/CellKey.hpp"

namespace hpds {

namespace {
[[noreturn]] void fail(const std::string &key, const std::string &why) {
  throw std::invalid_argument(key + ": " + why);
}
void requireFinite(const std::string &key, double v) {
  if (!std::isfinite(v)) fail(key, "must be a finite number");
}
void requireNonNegative(const std::string &key, double v) {
  requireFinite(key, v);
  if (v < 0.0) fail(key, "must be >= 0, got " + yaml::formatNumber(v));
}
}  // namespace

const char *toString(InsertionOrder order) {
  switch (order) {
    case InsertionOrder::Random:
      return "random";
    case InsertionOrder::Input:
      return "input";
    case InsertionOrder::Sphericity:
      return "sphericity";
    case InsertionOrder::SurfaceVariation:
      return "surface_variation";
  }
  return "?";
}

const char *toString(Mode mode) { return mode == Mode::Map ? "map" : "scan"; }

InsertionOrder parseInsertionOrder(const std::string &text, const std::string &key) {
  if (text == "random") return InsertionOrder::Random;
  if (text == "input") return InsertionOrder::Input;
  if (text == "sphericity") return InsertionOrder::Sphericity;
  if (text == "surface_variation") return InsertionOrder::SurfaceVariation;
  fail(key, "unknown order '" + text + "' (expected random, input, sphericity or surface_variation)");
}

Mode parseMode(const std::string &text, const std::string &key) {
  if (text == "scan") return Mode::Scan;
  if (text == "map") return Mode::Map;
  fail(key, "unknown mode '" + text + "' (expected scan or map)");
}

namespace {
constexpr double kMaxCellSize = 1e6;
/// [m] How far from the origin the finest level's exact cell keys must reach at least: less holds no lidar frame.
constexpr double kMinKeyReach = 100.0;

// The cell edge of level `level` whose radius is `spacing`, as a level-0 edge: the smallest double whose r_level is
// not below the spacing (the product may round a bit low).
double cellSizeForRadius(double spacing, int level) {
  double cell = std::ldexp(2.0 * spacing / std::sqrt(3.0), level);
  while (poissonRadius(cell, level) < spacing) cell = std::nextafter(cell, INFINITY);
  return cell;
}

// Derived cell: the level whose 2^L multiple of the spacing's edge stays within kDefaultCellSize.
int derivedOutputLevel(double spacing, int max_depth) {
  const double edge = 2.0 * spacing / std::sqrt(3.0);
  int level = 0;
  while (level < max_depth && std::ldexp(edge, level + 1) <= kDefaultCellSize) ++level;
  return level;
}

std::string metres(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g m", v);
  return buf;
}

// Neighbourhood sizes bound the work per frame: a PCA reads every sample (normals) or point (feature orders) inside
// its neighbourhood, so k, and a radius measured in the radii of the finest level read, must stay well below the
// values that took 30-60 s per frame (normals.k 2e9, normals.radius 1e6 m, order.feature_radius 1e6 m).
constexpr int kMaxNeighbours = 1024;
constexpr double kMaxRadiusInLevelRadii = 64.0;

void validateNeighbourhoods(const HpdsConfig &c) {
  if (c.normals.k > kMaxNeighbours)
    fail("normals.k", "must be in 0.." + std::to_string(kMaxNeighbours) + ", got " + std::to_string(c.normals.k));
  if (c.normals.min_neighbors > kMaxNeighbours)
    fail("normals.min_neighbors",
         "must be in 3.." + std::to_string(kMaxNeighbours) + ", got " + std::to_string(c.normals.min_neighbors));
  // After min_neighbors' own bounds, so that an error names the key that is out of range. Below min_neighbors
  // every search would fail; that matters only where covariances are made.
  if (c.normals.covariance_k < 0 || c.normals.covariance_k > kMaxNeighbours ||
      (c.normals.covariances && c.normals.covariance_k != 0 && c.normals.covariance_k < c.normals.min_neighbors))
    fail("normals.covariance_k", "must be 0 (the output normal's plane) or in normals.min_neighbors (" +
                                     std::to_string(c.normals.min_neighbors) + ").." +
                                     std::to_string(kMaxNeighbours) + ", got " + std::to_string(c.normals.covariance_k));
  const OutputResolution resolved = resolveOutput(c);  // a derived cell (0) is measured as the pipeline runs it
  const int output = resolved.level;
  // Normals read the samples of levels up to output + neighborhood_level_offset; feature orders raw points, which
  // the feature cell cap keeps bounded anyway, measured against the output level.
  const int finest = std::min(c.hierarchy.max_depth, output + c.normals.neighborhood_level_offset);
  const auto bound = [&](const std::string &key, double value, int level, const std::string &what) {
    const double limit = kMaxRadiusInLevelRadii * poissonRadius(resolved.cell_size, level);
    if (value > limit)
      fail(key, "must be <= " + yaml::formatNumber(limit) + " m (64 radii of level " + std::to_string(level) + ", " +
                    what + "), got " + yaml::formatNumber(value));
  };
  bound("normals.radius", c.normals.radius, finest, "the finest level the normals read");
  bound("order.feature_radius", c.order.feature_radius, output, "the output level");
}

}  // namespace

void validateConfig(const HpdsConfig &c) {
  // Only reachable through a cast (a config the caller decoded itself), which would otherwise run as some default.
  if (c.mode != Mode::Scan && c.mode != Mode::Map)
    fail("mode", "is no mode (" + std::to_string(static_cast<int>(c.mode)) + "): expected scan or map");
  if (c.order.type != InsertionOrder::Random && c.order.type != InsertionOrder::Input &&
      c.order.type != InsertionOrder::Sphericity && c.order.type != InsertionOrder::SurfaceVariation)
    fail("order.type", "is no insertion order (" + std::to_string(static_cast<int>(c.order.type)) +
                           "): expected random, input, sphericity or surface_variation");
  requireFinite("hierarchy.cell_size", c.hierarchy.cell_size);
  if (c.hierarchy.cell_size < 0.0)
    fail("hierarchy.cell_size", "must be > 0, or 0 = derived from output.spacing, got " + yaml::formatNumber(c.hierarchy.cell_size));
  if (c.hierarchy.cell_size > kMaxCellSize) fail("hierarchy.cell_size", "must be <= 1e6 m");
  if (c.hierarchy.max_depth < 0 || c.hierarchy.max_depth > 21)
    fail("hierarchy.max_depth", "must be in 0..21, got " + std::to_string(c.hierarchy.max_depth));
  requireNonNegative("order.feature_radius", c.order.feature_radius);
  if (c.output.level < -1 || c.output.level > c.hierarchy.max_depth)
    fail("output.level", "must be -1 or in 0..hierarchy.max_depth (" + std::to_string(c.hierarchy.max_depth) +
                             "), got " + std::to_string(c.output.level));
  requireNonNegative("output.spacing", c.output.spacing);
  if (c.output.level < 0 && c.output.spacing > 0.0) {
    if (c.hierarchy.cell_size == 0.0 &&
        !(cellSizeForRadius(c.output.spacing, derivedOutputLevel(c.output.spacing, c.hierarchy.max_depth)) <= kMaxCellSize))
      fail("output.spacing", "is too large: the derived hierarchy.cell_size would exceed 1e6 m");
  }
  if (c.output.float32_xyz && c.output.float64_xyz)
    fail("output.float32_xyz", "cannot go with output.float64_xyz: true (x y z are written as one type); set one of "
                               "them");
  requireNonNegative("normals.radius", c.normals.radius);
  if (c.normals.k < 0) fail("normals.k", "must be >= 0, got " + std::to_string(c.normals.k));
  if (c.normals.min_neighbors < 3)
    fail("normals.min_neighbors", "must be >= 3 (a plane needs three points), got " +
                                      std::to_string(c.normals.min_neighbors));
  if (c.normals.k > 0 && c.normals.k < c.normals.min_neighbors)
    fail("normals.k", "must be >= normals.min_neighbors (" + std::to_string(c.normals.min_neighbors) + ")");
  if (c.normals.neighborhood_level_offset < 0 || c.normals.neighborhood_level_offset > 21)
    fail("normals.neighborhood_level_offset",
         "must be in 0..21, got " + std::to_string(c.normals.neighborhood_level_offset));
  requireFinite("normals.max_growth", c.normals.max_growth);
  if (c.normals.max_growth < 1.0 || c.normals.max_growth > 1024.0)
    fail("normals.max_growth", "must be in 1..1024 (1 = off), got " + std::to_string(c.normals.max_growth));
  if (c.normals.covariances && !c.normals.enabled)
    fail("normals.covariances", "needs normals.enabled (a covariance is built from the sample's normal): set "
                                "normals.enabled: true, or normals.covariances: false");
  requireFinite("normals.covariance_epsilon", c.normals.covariance_epsilon);
  // Below 1e-4 the float32 output would not resolve the normal's variance against the in-plane 1.
  if (c.normals.covariance_epsilon < 1e-4 || c.normals.covariance_epsilon > 1.0)
    fail("normals.covariance_epsilon",
         "must be in 1e-4..1, got " + yaml::formatNumber(c.normals.covariance_epsilon));
  requireFinite("normals.covariance_line_ratio", c.normals.covariance_line_ratio);
  if (c.normals.covariance_line_ratio < 0.0 || c.normals.covariance_line_ratio > 1.0)
    fail("normals.covariance_line_ratio",
         "must be in 0..1 (0 = every neighbourhood a plane), got " + yaml::formatNumber(c.normals.covariance_line_ratio));
  requireNonNegative("map.evict_distance", c.map.evict_distance);
  if (c.map.keep_depth < -1 || c.map.keep_depth > c.hierarchy.max_depth)
    fail("map.keep_depth", "must be -1 or in 0..hierarchy.max_depth (" + std::to_string(c.hierarchy.max_depth) +
                               "), got " + std::to_string(c.map.keep_depth));
  requireNonNegative("input.min_range", c.input.min_range);
  requireNonNegative("input.max_range", c.input.max_range);
  if (c.input.max_range > 0.0 && c.input.max_range <= c.input.min_range)
    fail("input.max_range", "must be 0 (off) or > input.min_range");
  if (c.threads < 0 || c.threads > 1024) fail("threads", "must be in 0..1024 (0 = all cores), got " + std::to_string(c.threads));
  // Cells so small that the finest level's exact keys cannot hold a lidar frame: every point would be counted out
  // of key range and every output empty.
  const double finest_edge = cellEdge(resolveOutput(c).cell_size, c.hierarchy.max_depth);
  const double reach = (kMaxCellCoord - 8.0) * finest_edge;
  if (!(reach >= kMinKeyReach)) {
    // A derived cell makes the output level's cell 2 S / sqrt(3) whatever max_depth is: only the spacing helps.
    const bool derived = c.hierarchy.cell_size == 0.0;
    fail(derived ? "output.spacing" : "hierarchy.cell_size",
         "is too small: level " + std::to_string(c.hierarchy.max_depth) + " (hierarchy.max_depth) gets cells of " +
             metres(finest_edge) + ", whose exact keys reach only " + metres(reach) + " from the origin (at least " +
             metres(kMinKeyReach) + " are needed); " +
             (derived ? std::string("raise it") : std::string("raise it or lower hierarchy.max_depth")));
  }
  validateNeighbourhoods(c);
}

double cellEdge(double cell_size, int depth) { return std::ldexp(cell_size, -depth); }

double poissonRadius(double cell_size, int depth) { return 0.5 * std::sqrt(3.0) * cellEdge(cell_size, depth); }

OutputResolution resolveOutput(const HpdsConfig &c) {
  OutputResolution r;
  const bool by_spacing = c.output.level < 0 && c.output.spacing > 0.0;
  const bool derived = c.hierarchy.cell_size == 0.0;
  const std::string spacing = "output.spacing " + metres(c.output.spacing);
  bool clamped = false;  // the fixed cell's finest level is coarser than the spacing
  if (by_spacing && derived) {
    r.level = derivedOutputLevel(c.output.spacing, c.hierarchy.max_depth);
    r.cell_size = cellSizeForRadius(c.output.spacing, r.level);
  } else {
    r.cell_size = derived ? kDefaultCellSize : c.hierarchy.cell_size;
    r.level = c.output.level >= 0 ? c.output.level : c.hierarchy.max_depth;
    if (by_spacing) {
      clamped = true;  // unless a level reaches the spacing
      for (int d = 0; d <= c.hierarchy.max_depth; ++d)
        if (poissonRadius(r.cell_size, d) <= c.output.spacing) {
          r.level = d;
          clamped = false;
          break;
        }
    }
  }
  r.radius = poissonRadius(r.cell_size, r.level);
  if (by_spacing) r.spacing_asked = c.output.spacing;
  const std::string result = "output level " + std::to_string(r.level) + ", r_" + std::to_string(r.level) + " = " +
                             metres(r.radius) + ", level-0 cell " + metres(r.cell_size);
  const std::string cell =
      !derived ? "hierarchy.cell_size " + metres(c.hierarchy.cell_size)
      : c.output.spacing > 0.0
          ? "hierarchy.cell_size 0 (" + spacing + " is not used, as output.level is set: the default " +
                metres(kDefaultCellSize) + ")"
          : "hierarchy.cell_size 0 (no output.spacing to derive it from: " + metres(kDefaultCellSize) + ")";
  if (by_spacing && derived) {
    r.reason = result + ": the spacing asked (" + spacing + "), with the cell derived from it (hierarchy.cell_size 0)";
  } else if (clamped) {
    r.reason = result + ": hierarchy.max_depth " + std::to_string(c.hierarchy.max_depth) + ", since even its radius is "
               "coarser than " + spacing + " at the fixed " + cell + " (raise hierarchy.max_depth, or set "
               "hierarchy.cell_size 0 to get the spacing exactly)";
  } else if (by_spacing) {
    r.reason = result + ": the coarsest level with r_D <= " + spacing + " at the fixed " + cell +
               " (radii halve from level to level; hierarchy.cell_size 0 gives the spacing exactly)";
  } else if (c.output.level >= 0) {
    r.reason = result + ": output.level " + std::to_string(c.output.level) + " at " + cell;
  } else {
    r.reason = result + ": output.level -1 and output.spacing 0, so hierarchy.max_depth " +
               std::to_string(c.hierarchy.max_depth) + " at " + cell;
  }
  return r;
}

std::string keyRangeAdvice(const HpdsConfig &c) {
  const auto reach = [](const HpdsConfig &x) {
    return (kMaxCellCoord - 8.0) * cellEdge(resolveOutput(x).cell_size, x.hierarchy.max_depth);
  };
  const OutputResolution r = resolveOutput(c);
  const int depth = c.hierarchy.max_depth;
  const double here = reach(c);
  std::string s = "the exact keys of level " + std::to_string(depth) + " (hierarchy.max_depth; cells of " +
                  metres(cellEdge(r.cell_size, depth)) + ") reach " + metres(here) +
                  " from the origin: give the points in a local frame (subtract an offset)";
  // Keys are made at max_depth even where fewer levels are built, so levels below the output widen the reach only by
  // being dropped. A derived level-0 cell stays within (2, 4] m for most spacings: a coarser spacing then moves the
  // output level, not the keys' cells, so it is named only where it does widen the reach.
  if (depth > r.level) s += ", or lower hierarchy.max_depth toward the output level " + std::to_string(r.level);
  HpdsConfig coarser = c;
  if (c.hierarchy.cell_size == 0.0) {
    coarser.output.spacing *= 2.0;
    if (reach(coarser) > here) s += ", or raise output.spacing";
  } else {
    s += ", or raise hierarchy.cell_size";
  }
  return s;
}

int resolveOutputLevel(const HpdsConfig &c) { return resolveOutput(c).level; }

int normalsAveragingLevel(const HpdsConfig &c, int output_level) {
  if (!c.normals.enabled || c.normals.neighborhood_level_offset <= 0) return -1;
  const int fine = std::min(c.hierarchy.max_depth, output_level + c.normals.neighborhood_level_offset);
  return fine > output_level ? fine : -1;
}

HpdsConfig resolvedConfig(const HpdsConfig &c) {
  const OutputResolution r = resolveOutput(c);
  HpdsConfig out = c;
  out.hierarchy.cell_size = r.cell_size;
  out.output.level = r.level;
  return out;
}

}  // namespace hpds
