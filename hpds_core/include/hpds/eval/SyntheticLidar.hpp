// SyntheticLidar: a deterministic spinning multi-beam lidar that ray-casts a procedural street scene.
//
// It is the project's built-in data source (demo, tests, benchmarks): frames look like a real driver's output
// (rings, no-return zeros, range noise, sparse gaps between scan lines) and come with exact ground truth.
//
// Contract
// - World ("fixed") frame: metres, z up, ground plane z = 0. Sensor frame: x forward, y left, z up.
// - Path: the sensor starts at (0, 0, sensor_height) heading +x and drives along a circular arc of curvature
//   yaw_rate / speed (straight when yaw_rate = 0; turning on the spot when speed = 0). Frame i is taken at arc length
//   i * speed with yaw i * yaw_rate and no roll/pitch; frame.sensor_to_fixed is that pose, frame.stamp = i * period.
// - Each frame is one full sweep from that single pose (no motion skew); `time` only labels the firing instant.
// - Scene: a street laid along the path (sensor in the middle, free corridor |lateral| < 3.2 m), built from 20 m blocks
//   whose content depends only on (seed, scene, block index) and the path curvature. The frame count only decides how
//   many blocks exist, so frame(i) is the same for any `frames` > i unless the path and margins wrap a full circle.
// - Determinism: the same config gives byte-identical frames on the same build; frame(i) does not depend on which
//   other frames were generated (noise comes from a counter-based hash of seed, frame and ray, not a stream).
// - Point record (natural alignment, point_step 24): x y z float32 [m, sensor frame], intensity float32 [0..255],
//   ring uint16 (beam index, 0 = lowest elevation), time float32 [s since sweep start = column / azimuth_steps *
//   frame_period, so in [0, frame_period)]. Column c fires at azimuth 2*pi*c/azimuth_steps, counter-clockwise from +x.
// - Order: organized (organized && emit_no_returns) is height = beams rows (row = ring) by width = azimuth_steps
//   columns. Otherwise height 1 in firing order (for each column, rings 0..beams-1), without no-returns when
//   emit_no_returns is false (an organized grid cannot omit cells, so that combination is unorganized).
// - No-return: nothing within max_range, closer than min_range, grazing incidence (cos < 0.01) or a ray the sculpture
//   tracer could not resolve. Emitted as x = y = z = 0, intensity 0, zero normal, ObjectKind::None (ring/time kept).
// - Range noise: Gaussian along the ray with sigma range_noise, truncated at +-4 sigma, so every return lies within
//   4 * range_noise of the true surface. Normals are the exact surface normals at the noise-free hit.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "hpds/points/Frame.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds {

enum class SceneKind : std::uint8_t {
  Urban,          ///< buildings, parked cars, poles with lamp globes, spheres, a sculpture every 80 m
  PlanarUrban,    ///< planes and boxes only: buildings, cars, square pillars, bins
  CurvedObjects,  ///< open ground with spheres, cylinders and a sculpture in every block
};

/// What a return hit. Geometry: Wall/Box = oriented boxes, Cylinder = vertical capped cylinder, Sculpture = the
/// curved detailed object (bumpy sphere with a ring, 1-2 cm ripples at 10 cm and 5 cm ripples at 30 cm scale).
enum class ObjectKind : std::uint8_t { None = 0, Ground, Wall, Box, Cylinder, Sphere, Sculpture };
inline constexpr int kObjectKindCount = 7;
[[nodiscard]] const char *toString(ObjectKind kind);
[[nodiscard]] const char *toString(SceneKind kind);

struct SyntheticLidarConfig {
  int beams = 32;                   ///< 1..65535, evenly spaced in elevation (a single beam sits at min_elevation)
  double min_elevation_deg = -25.0;  ///< lowest beam, (-90, 90)
  double max_elevation_deg = 15.0;   ///< highest beam, >= min_elevation_deg
  int azimuth_steps = 1800;         ///< columns per revolution
  double min_range = 0.5;           ///< [m] closer returns are dropped, as drivers do
  double max_range = 80.0;          ///< [m] farther surfaces give no return
  double range_noise = 0.01;        ///< [m] Gaussian sigma along the ray (truncated at 4 sigma); 0 = exact
  double sensor_height = 1.8;       ///< [m] above the ground, > 0
  int frames = 5;                   ///< frames in stream()
  double speed = 1.0;               ///< [m per frame] along the path
  double yaw_rate = 0.02;           ///< [rad per frame]; |yaw_rate / speed| <= 1/25 keeps the street drivable
  double frame_period = 0.1;        ///< [s] stamps are i * frame_period; times span one period
  bool organized = true;            ///< width = azimuth_steps, height = beams (needs emit_no_returns)
  bool emit_no_returns = true;      ///< no-return rays become (0,0,0) points; else they are omitted
  std::uint64_t seed = 1;           ///< object placement and noise
  SceneKind scene = SceneKind::Urban;
};

/// One generated sweep plus its ground truth, all arrays parallel to frame.points.
struct SyntheticFrame {
  Frame frame;
  std::vector<Eigen::Vector3f> normals;  ///< unit, sensor frame, dot(n, -p) > 0; zero for no-returns
  std::vector<ObjectKind> kinds;         ///< what each point hit; None for no-returns
};

/// Nearest scene surface to a world point.
struct SceneQuery {
  double signed_distance = 0.0;  ///< [m] union of all solids: > 0 outside, < 0 inside (below ground is inside)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< outward unit normal at the nearest surface point
  ObjectKind kind = ObjectKind::None;
};

/// A noise-free ray hit in the world frame.
struct RayHit {
  double t = 0.0;  ///< [m] along the unit direction
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, facing the ray origin
  ObjectKind kind = ObjectKind::None;
};

class SyntheticLidar {
 public:
  /// Validates the config (std::invalid_argument naming the field) and builds the scene.
  explicit SyntheticLidar(SyntheticLidarConfig config);
  ~SyntheticLidar();
  SyntheticLidar(SyntheticLidar &&) noexcept;
  SyntheticLidar &operator=(SyntheticLidar &&) noexcept;

  /// Frame `index` in [0, frames); std::out_of_range otherwise. Single-threaded, thread-safe (const).
  [[nodiscard]] SyntheticFrame frame(int index) const;
  /// frame(0) ... frame(frames - 1).
  [[nodiscard]] std::vector<SyntheticFrame> stream() const;
  [[nodiscard]] const SyntheticLidarConfig &config() const;

  /// sensor_to_fixed of frame `index` (defined for any index, also outside the stream).
  [[nodiscard]] Eigen::Isometry3d pose(int index) const;
  /// Nearest surface of the whole scene to `world_point`. Exact for the analytic shapes; for the sculpture a
  /// projection onto its surface, accurate within a few centimetres of it (what point-on-surface checks need).
  [[nodiscard]] SceneQuery queryScene(const Eigen::Vector3d &world_point) const;
  /// First noise-free hit along a world ray within max_t; nullopt for a miss or a ray the sculpture tracer cannot
  /// resolve. No incidence or min-range filtering (those are sensor effects applied by frame()).
  [[nodiscard]] std::optional<RayHit> castRay(const Eigen::Vector3d &origin, const Eigen::Vector3d &unit_direction,
                                              double max_t) const;
  /// Number of scene objects besides the ground (for reports).
  [[nodiscard]] std::size_t objectCount() const;

  /// The record layout of every frame (see the contract above).
  [[nodiscard]] static PointLayout pointLayout();

 private:
  struct Scene;
  SyntheticLidarConfig config_;
  std::unique_ptr<Scene> scene_;
};

}  // namespace hpds
