// Internal to hpds_eval: the solids of SyntheticLidar's scenes (boxes, cylinders, spheres, the ripple-and-torus
// sculpture), exact ray intersections and signed distances. World frame, metres.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>

#include "hpds/eval/SyntheticLidar.hpp"

namespace hpds::synthetic {

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

/// The nearest entry hit of a ray so far.
struct Candidate {
  double t = std::numeric_limits<double>::infinity();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  int shape = -1;            // -1: ground
  bool unresolved = false;   // sculpture tracer gave up here: the ray is blocked but the surface is unknown
};

/// Keeps in `best` the nearer of it and the ray's entry into `s` (shape number `id`). `d` is a unit direction and
/// the origin `o` is never inside a solid.
void intersectShape(const Shape &s, int id, const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best);
/// Same for the ground plane z = 0.
void intersectGround(const Eigen::Vector3d &o, const Eigen::Vector3d &d, Candidate &best);
/// How far a sculpture's surface (ripples, torus tube) reaches beyond its base sphere radius [m].
double sculptureMargin();
/// Signed distance from `p` to `s` (> 0 outside) and the outward unit normal at the nearest surface point.
double shapeDistance(const Shape &s, const Eigen::Vector3d &p, Eigen::Vector3d &normal);

}  // namespace hpds::synthetic
