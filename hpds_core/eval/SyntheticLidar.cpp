#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/util/SplitMix64.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace hpds {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr double kInf = std::numeric_limits<double>::infinity();

constexpr double kBlockLength = 20.0;       // [m] of street per procedural block
constexpr double kMinCurvatureRadius = 25.0;  // [m] below it the inner buildings would reach the path
constexpr double kCorridor = 3.2;           // [m] half-width kept free around the path
constexpr double kMinIncidenceCos = 0.01;   // weaker returns are lost in real sensors; also keeps dot(n,-p) > 0 robust
constexpr double kNoiseTruncation = 4.0;    // [sigma] so "on the surface within 4 sigma" is a guarantee, not a hope
constexpr int kAzimuthBins = 360;           // azimuth culling resolution

// Sculpture: a bumpy sphere f = |q| - R - b(q) unioned with a tilted torus around its equator (creases where they
// meet). |grad b| <= A1*k1 + A2*k2 (each sin*sin*sin term has gradient norm <= k: the sum of squares is multilinear
// in sin^2, maximal at a vertex of [0,1]^3 where it is 1). Keeping that sum < 1 makes the bumpy sphere star-shaped
// (one crossing per radial line) and bounds the Lipschitz constant for sphere tracing.
constexpr double kRipple1Amp = 0.05;                // [m]
constexpr double kRipple1K = kTwoPi / 0.6;          // 30 cm bumps
constexpr double kRipple2Amp = 0.01;                // [m]
constexpr double kRipple2K = kTwoPi / 0.2;          // 10 cm bumps
constexpr double kTorusTube = 0.1;                  // [m]
constexpr double kSculptureLipschitz = 1.0 + kRipple1Amp * kRipple1K + kRipple2Amp * kRipple2K;
constexpr double kTraceEpsilon = 1e-4;              // [m] of SDF value at which tracing stops
constexpr int kTraceMaxSteps = 256;

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

enum class Geometry : std::uint8_t { Box, Cylinder, Sphere, Sculpture };

struct Shape {
  Geometry geometry = Geometry::Sphere;
  ObjectKind kind = ObjectKind::Sphere;
  double reflectivity = 0.5;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // cylinders: axis point at mid-height
  Eigen::Vector3d half = Eigen::Vector3d::Zero();    // box half extents in its own axes (x along the street)
  double cos_yaw = 1.0, sin_yaw = 0.0;               // box axes; sculpture torus tilt (about local x)
  double radius = 0.0;                               // sphere, cylinder, sculpture base sphere
  double half_height = 0.0;                          // cylinder
  double bound_radius = 0.0;                         // bounding sphere about `center`
  Eigen::Vector3d phase1 = Eigen::Vector3d::Zero();  // sculpture ripple phases
  Eigen::Vector3d phase2 = Eigen::Vector3d::Zero();
};

// ---- sculpture SDF -------------------------------------------------------------------------------------------

double ripple(const Eigen::Vector3d &q, double amp, double k, const Eigen::Vector3d &ph, Eigen::Vector3d *grad) {
  const double ax = k * q.x() + ph.x(), ay = k * q.y() + ph.y(), az = k * q.z() + ph.z();
  const double sx = std::sin(ax), sy = std::sin(ay), sz = std::sin(az);
  if (grad) {
    const double cx = std::cos(ax), cy = std::cos(ay), cz = std::cos(az);
    *grad += amp * k * Eigen::Vector3d(cx * sy * sz, sx * cy * sz, sx * sy * cz);
  }
  return amp * sx * sy * sz;
}

// Value (and optionally gradient) of the sculpture SDF at local offset q from its centre.
double sculptureSdf(const Shape &s, const Eigen::Vector3d &q, Eigen::Vector3d *grad) {
  const double r = std::max(q.norm(), 1e-12);
  Eigen::Vector3d bump_grad = Eigen::Vector3d::Zero();
  Eigen::Vector3d *bg = grad ? &bump_grad : nullptr;
  const double bumps = ripple(q, kRipple1Amp, kRipple1K, s.phase1, bg) + ripple(q, kRipple2Amp, kRipple2K, s.phase2, bg);
  const double f_sphere = r - s.radius - bumps;

  // Torus about the local z axis after tilting by the stored angle about x.
  const double c = s.cos_yaw, sn = s.sin_yaw;
  const Eigen::Vector3d t(q.x(), c * q.y() + sn * q.z(), -sn * q.y() + c * q.z());
  const double rho = std::max(std::hypot(t.x(), t.y()), 1e-12);
  const double a = rho - s.radius;
  const double len = std::max(std::hypot(a, t.z()), 1e-12);
  const double f_torus = len - kTorusTube;

  if (f_sphere <= f_torus) {
    if (grad) *grad = q / r - bump_grad;
    return f_sphere;
  }
  if (grad) {
    const Eigen::Vector3d gt(a / len * t.x() / rho, a / len * t.y() / rho, t.z() / len);
    *grad = Eigen::Vector3d(gt.x(), c * gt.y() - sn * gt.z(), sn * gt.y() + c * gt.z());
  }
  return f_torus;
}

// ---- ray intersections (world frame, unit direction, entry hits only: the sensor is never inside a solid) --------

struct Candidate {
  double t = kInf;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  int shape = -1;            // -1: ground
  bool unresolved = false;   // sculpture tracer gave up here: the ray is blocked but the surface is unknown
};

void intersectBox(const Shape &b, int id, const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best) {
  const Eigen::Vector3d rel = o - b.center;
  const double c = b.cos_yaw, s = b.sin_yaw;
  const double lo[3] = {c * rel.x() + s * rel.y(), -s * rel.x() + c * rel.y(), rel.z()};
  const double ld[3] = {c * d.x() + s * d.y(), -s * d.x() + c * d.y(), d.z()};
  double t_near = -kInf, t_far = kInf;
  int axis = -1;
  for (int i = 0; i < 3; ++i) {
    if (std::abs(ld[i]) < 1e-15) {
      if (std::abs(lo[i]) > b.half[i]) return;
      continue;
    }
    const double inv = 1.0 / ld[i];
    double t0 = (-b.half[i] - lo[i]) * inv, t1 = (b.half[i] - lo[i]) * inv;
    if (t0 > t1) std::swap(t0, t1);
    if (t0 > t_near) {
      t_near = t0;
      axis = i;
    }
    t_far = std::min(t_far, t1);
  }
  if (axis < 0 || t_near > t_far || t_near <= 0.0 || t_near >= best.t) return;
  double nl[3] = {0.0, 0.0, 0.0};
  nl[axis] = ld[axis] > 0.0 ? -1.0 : 1.0;
  best = {t_near, Eigen::Vector3d(c * nl[0] - s * nl[1], s * nl[0] + c * nl[1], nl[2]), id, false};
}

void intersectCylinder(const Shape &cy, int id, const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best) {
  const Eigen::Vector3d rel = o - cy.center;
  const double a = d.x() * d.x() + d.y() * d.y();
  const double r2 = cy.radius * cy.radius;
  if (a > 1e-18) {
    const double b = rel.x() * d.x() + rel.y() * d.y();
    const double c = rel.x() * rel.x() + rel.y() * rel.y() - r2;
    const double disc = b * b - a * c;
    if (disc < 0.0) return;  // the infinite cylinder is missed, so are the caps
    const double t = (-b - std::sqrt(disc)) / a;
    if (t > 0.0 && t < best.t && std::abs(rel.z() + t * d.z()) <= cy.half_height) {
      const Eigen::Vector3d n((rel.x() + t * d.x()) / cy.radius, (rel.y() + t * d.y()) / cy.radius, 0.0);
      best = {t, n, id, false};
      return;  // a side entry is the first contact; a cap cannot come earlier
    }
  }
  if (std::abs(d.z()) > 1e-15) {
    const double cap = d.z() < 0.0 ? cy.half_height : -cy.half_height;
    const double t = (cap - rel.z()) / d.z();
    if (t > 0.0 && t < best.t) {
      const double x = rel.x() + t * d.x(), y = rel.y() + t * d.y();
      if (x * x + y * y <= r2) best = {t, Eigen::Vector3d(0.0, 0.0, d.z() < 0.0 ? 1.0 : -1.0), id, false};
    }
  }
}

// Entry/exit of a ray with a sphere, clipped to (0, t_max); false when empty.
bool sphereSpan(const Eigen::Vector3d &rel, const Eigen::Vector3d &d, double radius, double &t0, double &t1) {
  const double b = rel.dot(d);
  const double c = rel.squaredNorm() - radius * radius;
  const double disc = b * b - c;
  if (disc < 0.0) return false;
  const double sq = std::sqrt(disc);
  t0 = -b - sq;
  t1 = -b + sq;
  return t1 > 0.0;
}

void intersectSphere(const Shape &sp, int id, const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best) {
  const Eigen::Vector3d rel = o - sp.center;
  double t0, t1;
  if (!sphereSpan(rel, d, sp.radius, t0, t1) || t0 <= 0.0 || t0 >= best.t) return;
  best = {t0, (rel + t0 * d) / sp.radius, id, false};
}

void intersectSculpture(const Shape &sc, int id, const Eigen::Vector3d &o, const Eigen::Vector3d &d,
                        Candidate &best) {
  const Eigen::Vector3d rel = o - sc.center;
  double t0, t1;
  if (!sphereSpan(rel, d, sc.bound_radius, t0, t1)) return;
  t0 = std::max(t0, 0.0);
  t1 = std::min(t1, best.t);
  if (t0 >= t1) return;
  // Sphere tracing with steps f / Lipschitz never passes the first crossing.
  double t = t0;
  double f = 0.0;
  bool converged = false;
  for (int step = 0; step < kTraceMaxSteps; ++step) {
    f = sculptureSdf(sc, rel + t * d, nullptr);
    if (f < kTraceEpsilon) {
      converged = true;
      break;
    }
    t += f / kSculptureLipschitz;
    if (t >= t1) return;
  }
  if (!converged) {
    best = {t, Eigen::Vector3d::Zero(), id, true};
    return;
  }
  // Newton along the ray puts the point on the level set to ~1e-9 (tracing alone leaves it up to 1e-4 outside).
  for (int it = 0; it < 3 && std::abs(f) > 1e-9; ++it) {
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    sculptureSdf(sc, rel + t * d, &g);
    const double slope = g.dot(d);
    if (slope > -1e-3) break;  // near-grazing: Newton could jump to another sheet
    const double t_new = t - f / slope;
    if (std::abs(t_new - t) > 0.01) break;
    const double f_new = sculptureSdf(sc, rel + t_new * d, nullptr);
    if (std::abs(f_new) >= std::abs(f)) break;
    t = t_new;
    f = f_new;
  }
  if (t <= 0.0 || t >= best.t) return;
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  sculptureSdf(sc, rel + t * d, &g);
  const double gn = g.norm();
  if (gn < 1e-9) {
    best = {t, Eigen::Vector3d::Zero(), id, true};
    return;
  }
  best = {t, g / gn, id, false};
}

void intersectShape(const Shape &s, int id, const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best) {
  switch (s.geometry) {
    case Geometry::Box:
      return intersectBox(s, id, o, d, best);
    case Geometry::Cylinder:
      return intersectCylinder(s, id, o, d, best);
    case Geometry::Sphere:
      return intersectSphere(s, id, o, d, best);
    case Geometry::Sculpture:
      return intersectSculpture(s, id, o, d, best);
  }
}

void intersectGround(const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best) {
  if (d.z() >= 0.0 || o.z() <= 0.0) return;
  const double t = -o.z() / d.z();
  if (t < best.t) best = {t, Eigen::Vector3d::UnitZ(), -1, false};
}

// ---- signed distances (world frame) ---------------------------------------------------------------------------

double boxDistance(const Shape &b, const Eigen::Vector3d &p, Eigen::Vector3d &normal) {
  const Eigen::Vector3d rel = p - b.center;
  const double c = b.cos_yaw, s = b.sin_yaw;
  const Eigen::Vector3d l(c * rel.x() + s * rel.y(), -s * rel.x() + c * rel.y(), rel.z());
  const Eigen::Vector3d q = l.cwiseAbs() - b.half;
  const Eigen::Vector3d outside = q.cwiseMax(0.0);
  const double out_len = outside.norm();
  Eigen::Vector3d nl;
  double dist;
  if (out_len > 0.0) {
    nl = outside.cwiseProduct(l.cwiseSign()) / out_len;
    dist = out_len;
  } else {
    int axis = 0;
    dist = q.maxCoeff(&axis);
    nl = Eigen::Vector3d::Zero();
    nl[axis] = l[axis] < 0.0 ? -1.0 : 1.0;
  }
  normal = Eigen::Vector3d(c * nl.x() - s * nl.y(), s * nl.x() + c * nl.y(), nl.z());
  return dist;
}

double cylinderDistance(const Shape &cy, const Eigen::Vector3d &p, Eigen::Vector3d &normal) {
  const Eigen::Vector3d rel = p - cy.center;
  const double rho = std::hypot(rel.x(), rel.y());
  const Eigen::Vector3d radial = rho > 1e-12 ? Eigen::Vector3d(rel.x() / rho, rel.y() / rho, 0.0)
                                             : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d axial(0.0, 0.0, rel.z() < 0.0 ? -1.0 : 1.0);
  const double qr = rho - cy.radius, qz = std::abs(rel.z()) - cy.half_height;
  const double mr = std::max(qr, 0.0), mz = std::max(qz, 0.0);
  const double out_len = std::hypot(mr, mz);
  if (out_len > 0.0) {
    normal = (mr * radial + mz * axial) / out_len;
    return out_len;
  }
  normal = qr > qz ? radial : axial;
  return std::max(qr, qz);
}

double sphereDistance(const Shape &sp, const Eigen::Vector3d &p, Eigen::Vector3d &normal) {
  const Eigen::Vector3d rel = p - sp.center;
  const double r = rel.norm();
  normal = r > 1e-12 ? Eigen::Vector3d(rel / r) : Eigen::Vector3d::UnitZ();
  return r - sp.radius;
}

// The sculpture SDF is not a distance (its gradient norm varies), so project onto the surface with Newton steps and
// measure the offset; near the surface this is the true distance to first order in the offset times the curvature.
double sculptureDistance(const Shape &sc, const Eigen::Vector3d &p, Eigen::Vector3d &normal) {
  const Eigen::Vector3d q0 = p - sc.center;
  Eigen::Vector3d g0 = Eigen::Vector3d::Zero();
  const double f0 = sculptureSdf(sc, q0, &g0);
  Eigen::Vector3d q = q0;
  double f = f0;
  Eigen::Vector3d g = g0;
  for (int it = 0; it < 12 && std::abs(f) > 1e-10; ++it) {
    const double g2 = g.squaredNorm();
    if (g2 < 1e-12) break;
    q -= f * g / g2;
    g.setZero();
    f = sculptureSdf(sc, q, &g);
  }
  const double gn = g.norm();
  if (std::abs(f) > 1e-6 || gn < 1e-9) {  // projection failed (far away or at a singular point): first-order estimate
    const double g0n = std::max(g0.norm(), 1e-9);
    normal = g0 / g0n;
    return f0 / g0n;
  }
  normal = g / gn;
  const double dist = (q0 - q).norm();
  return f0 < 0.0 ? -dist : dist;
}

double shapeDistance(const Shape &s, const Eigen::Vector3d &p, Eigen::Vector3d &normal) {
  switch (s.geometry) {
    case Geometry::Box:
      return boxDistance(s, p, normal);
    case Geometry::Cylinder:
      return cylinderDistance(s, p, normal);
    case Geometry::Sphere:
      return sphereDistance(s, p, normal);
    case Geometry::Sculpture:
      return sculptureDistance(s, p, normal);
  }
  return kInf;
}

// ---- scene construction --------------------------------------------------------------------------------------

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
    sc.bound_radius = sc.radius + std::max(kRipple1Amp + kRipple2Amp, kTorusTube) + 1e-3;
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
