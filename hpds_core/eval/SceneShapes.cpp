#include "SceneShapes.hpp"

#include <algorithm>
#include <cmath>

namespace hpds::synthetic {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr double kInf = std::numeric_limits<double>::infinity();

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

// ---- scene construction --------------------------------------------------------------------------------------

}  // namespace

double sculptureMargin() { return std::max(kRipple1Amp + kRipple2Amp, kTorusTube); }

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

}  // namespace hpds::synthetic
