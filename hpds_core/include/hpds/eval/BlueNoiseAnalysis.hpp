// BlueNoiseAnalysis: the statistics the PSA tool (Schlömer & Deussen) reports for 2D point sets, plus the steps that
// turn a planar piece of a 3D lidar sampling into such a set.
//
// Contract
// - A 2D set lives in a square window [x0, x0 + size) x [y0, y0 + size); points outside it are ignored.
// - Radial distribution function g(r): pair-distance histogram normalised by what a uniform random (Poisson) process
//   of the same density would give, so g -> 1 for uncorrelated points and g = 0 below the disk radius of a
//   Poisson-disk set. Bins are [r_max * b / bins, r_max * (b + 1) / bins).
//   - periodic: the window is a torus (minimum-image distances); every point is a reference point; r_max <= size / 2.
//   - otherwise (a patch cut out of a larger set): only points at least r_max from the window border are reference
//     points ("minus sampling"), so no annulus is cut by the border and no edge correction is needed;
//     r_max < size / 2 is required so that some reference region remains.
// - Power spectrum (periodogram): P(f) = |sum_j exp(-2 pi i f . x_j)|^2 / N on the frequencies f = k / size,
//   k in [-K, K]^2. At these frequencies the transform of the square window itself vanishes except at k = 0, so a
//   uniform density leaks no energy into k != 0 (no windowing needed). P(0) = N; a Poisson process gives P ~ 1;
//   blue noise is low at low |f| and ~1 at high |f|. The radial average over annuli |k| in [b - 1/2, b + 1/2),
//   b = 1..K (DC excluded), is what PSA plots.
// - Plane patches: a least-squares plane (PCA) and an orthonormal in-plane basis, so that distances within the plane
//   are preserved by the projection.
// - Deterministic; the spectrum may use `threads` (result independent of the count).
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hpds {

struct SquareWindow {
  double x0 = 0.0, y0 = 0.0;  ///< lower corner
  double size = 1.0;          ///< edge length, > 0
};

struct RadialDistribution {
  std::vector<double> r;  ///< bin centres [same unit as the points]
  std::vector<double> g;  ///< g(r); 0 where no pair falls
  double density = 0.0;   ///< points per unit area inside the window
  std::size_t reference_points = 0;
};

/// g(r) of the points inside `window` (see contract). Throws std::invalid_argument for bins < 1, r_max <= 0 or an
/// r_max the window cannot hold.
[[nodiscard]] RadialDistribution radialDistribution(const std::vector<Eigen::Vector2d> &points,
                                                    const SquareWindow &window, double r_max, int bins,
                                                    bool periodic);

struct PowerSpectrum {
  int half_extent = 0;         ///< K: integer frequencies -K..K per axis
  double frequency_step = 0.0; ///< 1 / window size [cycles per unit length]
  std::size_t points = 0;      ///< N inside the window
  /// (2K+1)^2 values, row-major: index (ky + K) * (2K+1) + (kx + K).
  std::vector<double> power;
  /// Radial average, bin b = 1..K stored at index b - 1: frequency b * frequency_step.
  std::vector<double> radial_frequency;
  std::vector<double> radial_power;

  [[nodiscard]] double at(int kx, int ky) const {
    return power[static_cast<std::size_t>(ky + half_extent) * (2 * half_extent + 1) + (kx + half_extent)];
  }
};

/// Periodogram of the points inside `window` up to integer frequency K = half_extent (>= 1).
[[nodiscard]] PowerSpectrum powerSpectrum(const std::vector<Eigen::Vector2d> &points, const SquareWindow &window,
                                          int half_extent, int threads = 1);

/// Distance from every point to its nearest other point (3D, brute-force free: a k-d tree). +inf for a lone point.
[[nodiscard]] std::vector<double> nearestNeighborDistances(const std::vector<Eigen::Vector3d> &points);

struct PlaneFit {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit; oriented with normal.z() >= 0
  Eigen::Vector3d u = Eigen::Vector3d::UnitX();       ///< in-plane unit axes, (u, v, normal) right-handed
  Eigen::Vector3d v = Eigen::Vector3d::UnitY();
  double rms = 0.0;  ///< RMS distance of the fitted points to the plane
  bool valid = false;
};

/// Least-squares plane through `points` (needs >= 3 non-collinear points, else valid = false).
[[nodiscard]] PlaneFit fitPlane(const std::vector<Eigen::Vector3d> &points);

/// In-plane coordinates (dot with u and v, relative to the centroid) of the points within `max_distance` of the plane;
/// `kept` (optional) receives their indices.
[[nodiscard]] std::vector<Eigen::Vector2d> projectToPlane(const std::vector<Eigen::Vector3d> &points,
                                                          const PlaneFit &plane, double max_distance,
                                                          std::vector<std::uint32_t> *kept = nullptr);

struct PlanarPatch {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();  ///< xy centre of the square patch (world frame)
  double size = 0.0;                                 ///< patch edge [m]
  PlaneFit plane;                                    ///< fitted to the patch's near-plane points
  std::size_t inliers = 0;
  bool found = false;
};

/// The square xy patch of edge `size` holding the most points that lie on one near-horizontal plane: candidates on a
/// grid of step size/2 (the 64 most populated; when none of them qualifies, the others in order of population) qualify when their plane fit is within `max_tilt_deg` of horizontal
/// and keeps >= 80 % of their points within `inlier_distance`; the one with the most such inliers wins (ties: the
/// more populated, then the lower cell index). Meant for lidar ground, the densest flat region of a street scan.
[[nodiscard]] PlanarPatch findPlanarPatch(const std::vector<Eigen::Vector3d> &points, double size,
                                          double inlier_distance, double max_tilt_deg = 15.0);

}  // namespace hpds
