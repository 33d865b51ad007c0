#include "hpds/config/Config.hpp"

#include <cmath>
#include <stdexcept>

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
  if (v < 0.0) fail(key, "must be >= 0, got " + std::to_string(v));
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

void validateConfig(const HpdsConfig &c) {
  requireFinite("hierarchy.cell_size", c.hierarchy.cell_size);
  if (c.hierarchy.cell_size <= 0.0) fail("hierarchy.cell_size", "must be > 0, got " + std::to_string(c.hierarchy.cell_size));
  if (c.hierarchy.cell_size > 1e6) fail("hierarchy.cell_size", "must be <= 1e6 m");
  if (c.hierarchy.max_depth < 0 || c.hierarchy.max_depth > 21)
    fail("hierarchy.max_depth", "must be in 0..21, got " + std::to_string(c.hierarchy.max_depth));
  requireNonNegative("order.feature_radius", c.order.feature_radius);
  if (c.output.level < -1 || c.output.level > c.hierarchy.max_depth)
    fail("output.level", "must be -1 or in 0..hierarchy.max_depth (" + std::to_string(c.hierarchy.max_depth) +
                             "), got " + std::to_string(c.output.level));
  requireNonNegative("output.spacing", c.output.spacing);
  if (c.output.level < 0 && c.output.spacing > 0.0 &&
      c.output.spacing < poissonRadius(c.hierarchy.cell_size, c.hierarchy.max_depth))
    fail("output.spacing", "is finer than the finest level's radius " +
                               std::to_string(poissonRadius(c.hierarchy.cell_size, c.hierarchy.max_depth)) +
                               " m; raise hierarchy.max_depth or the spacing");
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
  requireNonNegative("map.evict_distance", c.map.evict_distance);
  requireNonNegative("input.min_range", c.input.min_range);
  requireNonNegative("input.max_range", c.input.max_range);
  if (c.input.max_range > 0.0 && c.input.max_range <= c.input.min_range)
    fail("input.max_range", "must be 0 (off) or > input.min_range");
  if (c.threads < 0 || c.threads > 1024) fail("threads", "must be in 0..1024 (0 = all cores), got " + std::to_string(c.threads));
}

double cellEdge(double cell_size, int depth) { return std::ldexp(cell_size, -depth); }

double poissonRadius(double cell_size, int depth) { return 0.5 * std::sqrt(3.0) * cellEdge(cell_size, depth); }

int resolveOutputLevel(const HpdsConfig &c) {
  if (c.output.level >= 0) return c.output.level;
  if (c.output.spacing > 0.0) {
    for (int d = 0; d <= c.hierarchy.max_depth; ++d)
      if (poissonRadius(c.hierarchy.cell_size, d) <= c.output.spacing) return d;
  }
  return c.hierarchy.max_depth;
}

}  // namespace hpds
