#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/util/SplitMix64.hpp"
#include "SceneShapes.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace hpds {

namespace {

using synthetic::Candidate;
using synthetic::Geometry;
using synthetic::Shape;
using synthetic::intersectGround;
using synthetic::intersectShape;
using synthetic::shapeDistance;

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;

constexpr double kBlockLength = 20.0;       // [m] of street per procedural block
constexpr double kMinCurvatureRadius = 25.0;  // [m] below it the inner buildings would reach the path
constexpr double kCorridor = 3.2;           // [m] half-width kept free around the path
constexpr double kMinIncidenceCos = 0.01;   // weaker returns are lost in real sensors; also keeps dot(n,-p) > 0 robust
constexpr double kNoiseTruncation = 4.0;    // [sigma] so "on the surface within 4 sigma" is a guarantee, not a hope
constexpr int kAzimuthBins = 360;           // azimuth culling resolution


// Everything random derives from SplitMix64: cheap, portable, good avalanche.
std::uint64_t mix64(std::uint64_t x) { return splitMix64Mix(x + kSplitMix64Increment); }

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  double uniform(double lo, double hi) {
    state_ += kSplitMix64Increment;
    return lo + (hi - lo) * unitInterval(mix64(state_));
  }
  bool chance(double p) { return uniform(0.0, 1.0) < p; }

 private:
  std::uint64_t state_;
};

// Box-Muller on hashed bits instead of std::normal_distribution: the latter's algorithm is implementation-defined.
double truncatedGaussian(std::uint64_t key) {
  const std::uint64_t h1 = mix64(key);
  const std::uint64_t h2 = mix64(h1 ^ 0xD1B54A32D192ED03ull);
  const double u1 = (static_cast<double>(h1 >> 11) + 1.0) * 0x1.0p-53;  // (0, 1]: log stays finite
  const double z = std::sqrt(-2.0 * std::log(u1)) * std::cos(kTwoPi * unitInterval(h2));
  return std::clamp(z, -kNoiseTruncation, kNoiseTruncation);
}

std::int64_t floorDiv(std::int64_t a, std::int64_t b) {
  const std::int64_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

// The street centre line = the sensor path: an arc of curvature kappa from the origin heading +x.
struct Street {
  double kappa = 0.0;

  double heading(double s) const { return kappa * s; }
  Eigen::Vector2d at(double s, double lateral) const {
    if (kappa == 0.0) return {s, lateral};
    const double th = kappa * s;
    const double sn = std::sin(th), cs = std::cos(th);
    return {sn / kappa - lateral * sn, (1.0 - cs) / kappa + lateral * cs};
  }
  // Inverse of at(): (arc length, lateral) of a world xy. Arc length is only meaningful within half a lap.
  Eigen::Vector2d local(const Eigen::Vector2d &xy) const {
    if (kappa == 0.0) return xy;
    const double sg = kappa > 0.0 ? 1.0 : -1.0;
    const Eigen::Vector2d w(xy.x(), xy.y() - 1.0 / kappa);
    const double lateral = 1.0 / kappa - sg * w.norm();
    const double th = std::atan2(sg * w.x(), -sg * w.y());
    return {th / kappa, lateral};
  }
};

struct Builder {
  const Street &street;
  std::vector<Shape> &shapes;

  void box(ObjectKind kind, double s, double lateral, double length, double width, double z0, double z1,
           double reflectivity) {
    Shape b;
    b.geometry = Geometry::Box;
    b.kind = kind;
    b.reflectivity = reflectivity;
    const Eigen::Vector2d xy = street.at(s, lateral);
    b.center = Eigen::Vector3d(xy.x(), xy.y(), 0.5 * (z0 + z1));
    b.half = Eigen::Vector3d(0.5 * length, 0.5 * width, 0.5 * (z1 - z0));
    b.cos_yaw = std::cos(street.heading(s));
    b.sin_yaw = std::sin(street.heading(s));
    b.bound_radius = b.half.norm();
    shapes.push_back(b);
  }
  void cylinder(double s, double lateral, double radius, double z0, double z1, double reflectivity) {
    Shape c;
    c.geometry = Geometry::Cylinder;
    c.kind = ObjectKind::Cylinder;
    c.reflectivity = reflectivity;
    const Eigen::Vector2d xy = street.at(s, lateral);
    c.center = Eigen::Vector3d(xy.x(), xy.y(), 0.5 * (z0 + z1));
    c.radius = radius;
    c.half_height = 0.5 * (z1 - z0);
    c.bound_radius = std::hypot(radius, c.half_height);
    shapes.push_back(c);
  }
  void sphere(double s, double lateral, double z, double radius, double reflectivity) {
    Shape sp;
    sp.geometry = Geometry::Sphere;
    sp.kind = ObjectKind::Sphere;
    sp.reflectivity = reflectivity;
    const Eigen::Vector2d xy = street.at(s, lateral);
    sp.center = Eigen::Vector3d(xy.x(), xy.y(), z);
    sp.radius = radius;
    sp.bound_radius = radius;
    shapes.push_back(sp);
  }
  void sculpture(double s, double lateral, Rng &rng) {
    Shape sc;
    sc.geometry = Geometry::Sculpture;
    sc.kind = ObjectKind::Sculpture;
    sc.reflectivity = 0.8;
    sc.radius = rng.uniform(0.9, 1.1);
    const Eigen::Vector2d xy = street.at(s, lateral);
    sc.center = Eigen::Vector3d(xy.x(), xy.y(), sc.radius + 0.35);  // at chest height, where most beams cross it
    const double tilt = rng.uniform(0.0, 0.6);
    sc.cos_yaw = std::cos(tilt);
    sc.sin_yaw = std::sin(tilt);
    for (int i = 0; i < 3; ++i) sc.phase1[i] = rng.uniform(0.0, kTwoPi);
    for (int i = 0; i < 3; ++i) sc.phase2[i] = rng.uniform(0.0, kTwoPi);
    sc.bound_radius = sc.radius + synthetic::sculptureMargin() + 1e-3;
    shapes.push_back(sc);
    cylinder(s, lateral, 0.3, 0.0, 0.5, 0.5);  // plinth, overlapping the sculpture's underside
  }

  // Two buildings per side of a block, sometimes missing (side streets, open views to max range).
  void buildings(double s0, double side, Rng &rng) {
    for (int j = 0; j < 2; ++j) {
      const double a = s0 + j * 0.5 * kBlockLength + rng.uniform(0.3, 1.5);
      const double b = s0 + (j + 1) * 0.5 * kBlockLength - rng.uniform(0.3, 1.5);
      const double face = rng.uniform(8.0, 10.0), depth = rng.uniform(6.0, 12.0), height = rng.uniform(4.0, 16.0);
      const double refl = rng.uniform(0.35, 0.6);
      if (rng.chance(0.15)) continue;
      box(ObjectKind::Wall, 0.5 * (a + b), side * (face + 0.5 * depth), b - a, depth, 0.0, height, refl);
    }
  }
  void parkedCar(double s0, double side, Rng &rng, bool allowed) {
    const double s = s0 + rng.uniform(3.0, kBlockLength - 3.0);
    const bool present = rng.chance(0.35);
    // Ground clearance: rays under the car reach the road, as in real scans.
    if (present && allowed) box(ObjectKind::Box, s, side * 4.1, 4.3, 1.8, 0.25, 1.5, 0.4);
  }

  void urbanBlock(std::int64_t k, Rng &rng) {
    const double s0 = static_cast<double>(k) * kBlockLength;
    const bool has_sculpture = floorDiv(k, 4) * 4 == k;
    const double sculpture_side = floorDiv(k, 4) % 2 == 0 ? 1.0 : -1.0;
    for (const double side : {1.0, -1.0}) {
      const bool free_side = !(has_sculpture && side == sculpture_side);
      buildings(s0, side, rng);
      const int poles = rng.chance(0.5) ? 2 : 1;
      for (int m = 0; m < poles; ++m) {
        const double s = s0 + rng.uniform(1.0, kBlockLength - 1.0);
        const double lateral = side * rng.uniform(6.2, 6.8);
        const double r = rng.uniform(0.06, 0.15), h = rng.uniform(3.5, 8.0);
        const double globe = rng.uniform(0.18, 0.3);
        cylinder(s, lateral, r, 0.0, h, 0.6);
        if (rng.chance(0.5)) sphere(s, lateral, h + 0.8 * globe, globe, 0.9);
      }
      parkedCar(s0, side, rng, free_side);
      const double r = rng.uniform(0.4, 1.0);
      const double s = s0 + rng.uniform(1.0, kBlockLength - 1.0), lateral = side * rng.uniform(5.2, 7.0);
      if (rng.chance(0.3) && free_side) sphere(s, lateral, r, r, 0.7);
    }
    if (has_sculpture) sculpture(s0 + 8.0, sculpture_side * 4.6, rng);
  }

  void planarBlock(std::int64_t k, Rng &rng) {
    const double s0 = static_cast<double>(k) * kBlockLength;
    for (const double side : {1.0, -1.0}) {
      buildings(s0, side, rng);
      const int pillars = rng.chance(0.5) ? 2 : 1;
      for (int m = 0; m < pillars; ++m) {
        const double s = s0 + rng.uniform(1.0, kBlockLength - 1.0);
        const double w = rng.uniform(0.2, 0.4), h = rng.uniform(3.0, 6.0);
        box(ObjectKind::Box, s, side * rng.uniform(6.2, 6.8), w, w, 0.0, h, 0.6);
      }
      parkedCar(s0, side, rng, true);
      const double s = s0 + rng.uniform(1.0, kBlockLength - 1.0), lateral = side * rng.uniform(5.0, 7.0);
      if (rng.chance(0.5)) box(ObjectKind::Box, s, lateral, 0.6, 0.6, 0.0, 1.0, 0.5);  // bin
    }
  }

  void curvedBlock(std::int64_t k, Rng &rng) {
    const double s0 = static_cast<double>(k) * kBlockLength;
    const double sculpture_s = s0 + 8.0;
    const double sculpture_side = ((k % 2) + 2) % 2 == 0 ? 1.0 : -1.0;
    for (const double side : {1.0, -1.0}) {
      // Push objects on the sculpture's side out of its stretch of street so that none swallows it.
      auto pick_s = [&](double clearance) {
        const double s = s0 + rng.uniform(1.0, kBlockLength - 1.0);
        if (side != sculpture_side || std::abs(s - sculpture_s) >= clearance) return s;
        return s < sculpture_s ? sculpture_s - clearance : sculpture_s + clearance;
      };
      // Every draw is its own statement: argument evaluation order is unspecified and would break determinism.
      for (int m = 0; m < 3; ++m) {
        const double r = rng.uniform(0.3, 1.5);
        const double lateral = side * rng.uniform(kCorridor + r, 10.0 + r);
        const double lift = rng.chance(0.3) ? rng.uniform(0.2, 1.0) : 0.0;
        const double reflectivity = rng.uniform(0.5, 0.9);
        const double s = pick_s(2.2 + r);
        sphere(s, lateral, r + lift, r, reflectivity);
      }
      for (int m = 0; m < 2; ++m) {
        const double r = rng.uniform(0.1, 0.8), h = rng.uniform(1.0, 6.0);
        const double lateral = side * rng.uniform(kCorridor + r, 10.0 + r);
        const double reflectivity = rng.uniform(0.4, 0.8);
        const double s = pick_s(2.2 + r);
        cylinder(s, lateral, r, 0.0, h, reflectivity);
      }
    }
    sculpture(sculpture_s, sculpture_side * 4.6, rng);
  }
};

// Lane markings give the intensity channel some texture that geometry-only methods must ignore.
double groundReflectivity(const Street &street, const Eigen::Vector3d &p) {
  const Eigen::Vector2d sl = street.local(p.head<2>());
  const double lateral = sl.y();
  if (std::abs(std::abs(lateral) - 5.5) < 0.075) return 0.85;  // solid edge lines
  if (std::abs(std::abs(lateral) - 1.75) < 0.075) {               // dashed lane lines, 3 m on / 3 m off
    const double phase = sl.x() - 6.0 * std::floor(sl.x() / 6.0);
    if (phase < 3.0) return 0.85;
  }
  return 0.18;
}

void requireFinite(const char *key, double v) {
  if (!std::isfinite(v)) throw std::invalid_argument(std::string("SyntheticLidarConfig.") + key + " must be finite");
}
[[noreturn]] void invalid(const char *key, const std::string &why) {
  throw std::invalid_argument(std::string("SyntheticLidarConfig.") + key + ": " + why);
}

void validate(const SyntheticLidarConfig &c) {
  if (c.beams < 1 || c.beams > 65535) invalid("beams", "must be in 1..65535, got " + std::to_string(c.beams));
  if (c.azimuth_steps < 1 || c.azimuth_steps > 1000000)
    invalid("azimuth_steps", "must be in 1..1000000, got " + std::to_string(c.azimuth_steps));
  requireFinite("min_elevation_deg", c.min_elevation_deg);
  requireFinite("max_elevation_deg", c.max_elevation_deg);
  if (c.min_elevation_deg <= -90.0 || c.max_elevation_deg >= 90.0 || c.min_elevation_deg > c.max_elevation_deg)
    invalid("min_elevation_deg", "need -90 < min_elevation_deg <= max_elevation_deg < 90");
  for (const auto &[key, v] : {std::pair<const char *, double>{"min_range", c.min_range}, {"max_range", c.max_range},
                               {"range_noise", c.range_noise}, {"sensor_height", c.sensor_height},
                               {"speed", c.speed}, {"yaw_rate", c.yaw_rate}, {"frame_period", c.frame_period}})
    requireFinite(key, v);
  if (c.min_range < 0.0) invalid("min_range", "must be >= 0");
  if (c.max_range <= c.min_range || c.max_range > 10000.0) invalid("max_range", "must be in (min_range, 10000]");
  if (c.range_noise < 0.0) invalid("range_noise", "must be >= 0");
  if (c.sensor_height <= 0.0) invalid("sensor_height", "must be > 0");
  if (c.frames < 0) invalid("frames", "must be >= 0");
  if (c.frame_period <= 0.0) invalid("frame_period", "must be > 0");
  if (c.speed != 0.0 && std::abs(c.yaw_rate / c.speed) > 1.0 / kMinCurvatureRadius)
    invalid("yaw_rate", "path radius speed / yaw_rate must be >= 25 m so buildings stay off the path");
  if (std::abs(c.speed) * std::max(c.frames, 1) > 1e6) invalid("speed", "path longer than 1000 km");
}

}  // namespace

const char *toString(ObjectKind kind) {
  switch (kind) {
    case ObjectKind::None:
      return "none";
    case ObjectKind::Ground:
      return "ground";
    case ObjectKind::Wall:
      return "wall";
    case ObjectKind::Box:
      return "box";
    case ObjectKind::Cylinder:
      return "cylinder";
    case ObjectKind::Sphere:
      return "sphere";
    case ObjectKind::Sculpture:
      return "sculpture";
  }
  return "?";
}

const char *toString(SceneKind kind) {
  switch (kind) {
    case SceneKind::Urban:
      return "urban";
    case SceneKind::PlanarUrban:
      return "planar_urban";
    case SceneKind::CurvedObjects:
      return "curved_objects";
  }
  return "?";
}

struct SyntheticLidar::Scene {
  Street street;
  std::vector<Shape> shapes;

  Candidate cast(const Eigen::Vector3d &o, const Eigen::Vector3d &d, double max_t) const {
    Candidate best;
    best.t = max_t;
    intersectGround(o, d, best);
    for (std::size_t i = 0; i < shapes.size(); ++i) intersectShape(shapes[i], static_cast<int>(i), o, d, best);
    return best;
  }
  ObjectKind kindOf(int shape) const { return shape < 0 ? ObjectKind::Ground : shapes[shape].kind; }
};

SyntheticLidar::SyntheticLidar(SyntheticLidarConfig config) : config_(config), scene_(std::make_unique<Scene>()) {
  validate(config_);
  Scene &scene = *scene_;
  scene.street.kappa = config_.speed != 0.0 ? config_.yaw_rate / config_.speed : 0.0;

  // Blocks must cover every object within max_range of any pose. Along an arc the chord is at least 2/pi of the arc
  // length up to half a lap, and half a lap either way covers the whole circle.
  const double path_end = std::max(config_.frames - 1, 0) * config_.speed;
  double margin = 0.5 * kPi * config_.max_range + 30.0;
  if (scene.street.kappa != 0.0) margin = std::min(margin, kPi / std::abs(scene.street.kappa));
  const double s_lo = std::min(0.0, path_end) - margin, s_hi = std::max(0.0, path_end) + margin;
  const auto k_lo = static_cast<std::int64_t>(std::floor(s_lo / kBlockLength));
  const auto k_hi = static_cast<std::int64_t>(std::floor(s_hi / kBlockLength));

  Builder builder{scene.street, scene.shapes};
  const std::uint64_t scene_key = mix64(mix64(config_.seed) ^ (static_cast<std::uint64_t>(config_.scene) + 1));
  for (std::int64_t k = k_lo; k <= k_hi; ++k) {
    Rng rng(mix64(scene_key ^ static_cast<std::uint64_t>(k) * 0xA24BAED4963EE407ull));
    switch (config_.scene) {
      case SceneKind::Urban:
        builder.urbanBlock(k, rng);
        break;
      case SceneKind::PlanarUrban:
        builder.planarBlock(k, rng);
        break;
      case SceneKind::CurvedObjects:
        builder.curvedBlock(k, rng);
        break;
    }
  }
}

SyntheticLidar::~SyntheticLidar() = default;
SyntheticLidar::SyntheticLidar(SyntheticLidar &&) noexcept = default;
SyntheticLidar &SyntheticLidar::operator=(SyntheticLidar &&) noexcept = default;

const SyntheticLidarConfig &SyntheticLidar::config() const { return config_; }
std::size_t SyntheticLidar::objectCount() const { return scene_->shapes.size(); }

PointLayout SyntheticLidar::pointLayout() {
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  layout.append("intensity", FieldType::Float32);
  layout.append("ring", FieldType::UInt16);
  layout.point_step += 2;  // pad so `time` is 4-byte aligned, as driver layouts are
  layout.append("time", FieldType::Float32);
  return layout;
}

Eigen::Isometry3d SyntheticLidar::pose(int index) const {
  const double s = index * config_.speed;
  const Eigen::Vector2d xy = scene_->street.at(s, 0.0);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(index * config_.yaw_rate, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(xy.x(), xy.y(), config_.sensor_height);
  return pose;
}

SceneQuery SyntheticLidar::queryScene(const Eigen::Vector3d &p) const {
  SceneQuery best;
  best.signed_distance = p.z();
  best.normal = Eigen::Vector3d::UnitZ();
  best.kind = ObjectKind::Ground;
  // Union of solids = minimum of signed distances; the bounding sphere skips shapes that cannot beat the best.
  for (const Shape &s : scene_->shapes) {
    if ((p - s.center).norm() - s.bound_radius > std::max(best.signed_distance, 0.0) + 1e-9) continue;
    Eigen::Vector3d n;
    const double d = shapeDistance(s, p, n);
    if (d < best.signed_distance) {
      best.signed_distance = d;
      best.normal = n;
      best.kind = s.kind;
    }
  }
  return best;
}

std::optional<RayHit> SyntheticLidar::castRay(const Eigen::Vector3d &origin, const Eigen::Vector3d &unit_direction,
                                              double max_t) const {
  const Candidate c = scene_->cast(origin, unit_direction, max_t);
  if (c.t >= max_t || c.unresolved) return std::nullopt;
  RayHit hit;
  hit.t = c.t;
  hit.normal = c.normal;
  hit.kind = scene_->kindOf(c.shape);
  return hit;
}

SyntheticFrame SyntheticLidar::frame(int index) const {
  if (index < 0 || index >= config_.frames)
    throw std::out_of_range("SyntheticLidar::frame(" + std::to_string(index) + "): stream has " +
                            std::to_string(config_.frames) + " frames");
  const Scene &scene = *scene_;
  const Eigen::Isometry3d sensor_to_world = pose(index);
  const Eigen::Vector3d origin = sensor_to_world.translation();
  const double yaw = index * config_.yaw_rate;
  const double cyaw = std::cos(yaw), syaw = std::sin(yaw);
  const int beams = config_.beams, steps = config_.azimuth_steps;

  // Azimuth culling: each shape's bounding sphere spans an azimuth interval seen from the sensor; only shapes of the
  // column's bin are tested. Valid because the pose has no roll/pitch: azimuth is the same at every elevation.
  const int bins = std::min(kAzimuthBins, steps);
  const double bin_width = kTwoPi / bins;
  std::vector<std::vector<int>> bin_shapes(bins);
  for (std::size_t i = 0; i < scene.shapes.size(); ++i) {
    const Shape &s = scene.shapes[i];
    const Eigen::Vector3d rel = s.center - origin;
    if (rel.norm() - s.bound_radius > config_.max_range) continue;
    const double horizontal = std::hypot(rel.x(), rel.y());
    int first = 0, last = bins - 1;
    if (horizontal > s.bound_radius) {
      const double centre = std::atan2(-syaw * rel.x() + cyaw * rel.y(), cyaw * rel.x() + syaw * rel.y());
      const double half = std::asin(s.bound_radius / horizontal) + 1e-6;
      first = static_cast<int>(std::floor((centre - half) / bin_width));
      last = static_cast<int>(std::floor((centre + half) / bin_width));
    }
    for (int b = first; b <= last; ++b) bin_shapes[((b % bins) + bins) % bins].push_back(static_cast<int>(i));
  }

  std::vector<double> cos_el(beams), sin_el(beams);
  for (int b = 0; b < beams; ++b) {
    const double step_deg = beams > 1 ? (config_.max_elevation_deg - config_.min_elevation_deg) / (beams - 1) : 0.0;
    const double el = (config_.min_elevation_deg + b * step_deg) * kPi / 180.0;
    cos_el[b] = std::cos(el);
    sin_el[b] = std::sin(el);
  }

  struct Return {
    float xyz[3] = {0.f, 0.f, 0.f};
    float intensity = 0.f;
    Eigen::Vector3f normal = Eigen::Vector3f::Zero();
    ObjectKind kind = ObjectKind::None;
  };
  std::vector<Return> returns(static_cast<std::size_t>(beams) * steps);  // organized index ring * steps + column
  const std::uint64_t noise_key = mix64(mix64(config_.seed ^ 0x6E6F697365ull) ^ static_cast<std::uint64_t>(index));

  for (int col = 0; col < steps; ++col) {
    const double az = kTwoPi * col / steps;
    const double ca = std::cos(az), sa = std::sin(az);
    const std::vector<int> &candidates = bin_shapes[static_cast<std::size_t>(col) * bins / steps];
    for (int ring = 0; ring < beams; ++ring) {
      const Eigen::Vector3d ds(cos_el[ring] * ca, cos_el[ring] * sa, sin_el[ring]);
      const Eigen::Vector3d dw(cyaw * ds.x() - syaw * ds.y(), syaw * ds.x() + cyaw * ds.y(), ds.z());
      Candidate best;
      best.t = config_.max_range;
      intersectGround(origin, dw, best);
      for (const int id : candidates) intersectShape(scene.shapes[id], id, origin, dw, best);
      if (best.t >= config_.max_range || best.unresolved || best.t < config_.min_range) continue;
      const double cos_inc = -best.normal.dot(dw);
      if (cos_inc < kMinIncidenceCos) continue;

      const std::size_t ray = static_cast<std::size_t>(ring) * steps + col;
      double range = best.t;
      if (config_.range_noise > 0.0) {
        range += config_.range_noise * truncatedGaussian(noise_key ^ mix64(ray));
        if (range < config_.min_range) continue;
      }
      const double reflectivity = best.shape < 0 ? groundReflectivity(scene.street, origin + best.t * dw)
                                                 : scene.shapes[best.shape].reflectivity;
      Return &r = returns[ray];
      r.xyz[0] = static_cast<float>(range * ds.x());
      r.xyz[1] = static_cast<float>(range * ds.y());
      r.xyz[2] = static_cast<float>(range * ds.z());
      r.intensity = static_cast<float>(
          std::clamp(255.0 * reflectivity * (0.3 + 0.7 * cos_inc) * std::exp(-best.t / 120.0), 0.0, 255.0));
      const Eigen::Vector3d n = best.normal;
      r.normal = Eigen::Vector3d(cyaw * n.x() + syaw * n.y(), -syaw * n.x() + cyaw * n.y(), n.z()).cast<float>();
      r.kind = scene.kindOf(best.shape);
    }
  }

  SyntheticFrame out;
  out.frame.stamp = index * config_.frame_period;
  out.frame.sensor_to_fixed = sensor_to_world;
  const bool organized = config_.organized && config_.emit_no_returns;
  std::vector<std::size_t> order;
  order.reserve(returns.size());
  if (organized) {
    for (std::size_t i = 0; i < returns.size(); ++i) order.push_back(i);
  } else {
    for (int col = 0; col < steps; ++col)
      for (int ring = 0; ring < beams; ++ring) {
        const std::size_t ray = static_cast<std::size_t>(ring) * steps + col;
        if (config_.emit_no_returns || returns[ray].kind != ObjectKind::None) order.push_back(ray);
      }
  }

  const PointLayout layout = pointLayout();
  const std::uint32_t off_x = layout.find("x")->offset, off_i = layout.find("intensity")->offset;
  const std::uint32_t off_ring = layout.find("ring")->offset, off_time = layout.find("time")->offset;
  PointBuffer &points = out.frame.points;
  points = PointBuffer(layout, order.size());
  out.normals.resize(order.size());
  out.kinds.resize(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) {
    const std::size_t ray = order[i];
    const Return &r = returns[ray];
    const auto ring = static_cast<std::uint16_t>(ray / steps);
    const auto time = static_cast<float>(static_cast<double>(ray % steps) / steps * config_.frame_period);
    std::uint8_t *rec = points.record(i);
    std::memcpy(rec + off_x, r.xyz, sizeof(r.xyz));
    std::memcpy(rec + off_i, &r.intensity, sizeof(float));
    std::memcpy(rec + off_ring, &ring, sizeof(ring));
    std::memcpy(rec + off_time, &time, sizeof(time));
    out.normals[i] = r.normal;
    out.kinds[i] = r.kind;
  }
  if (organized) points.setOrganization(static_cast<std::uint32_t>(steps), static_cast<std::uint32_t>(beams));
  return out;
}

std::vector<SyntheticFrame> SyntheticLidar::stream() const {
  std::vector<SyntheticFrame> frames;
  frames.reserve(static_cast<std::size_t>(config_.frames));
  for (int i = 0; i < config_.frames; ++i) frames.push_back(frame(i));
  return frames;
}

}  // namespace hpds
