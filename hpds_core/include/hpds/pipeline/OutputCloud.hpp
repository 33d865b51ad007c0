// OutputCloud: hierarchy samples as a point cloud with the layout every consumer (PLY, PointCloud2) shares.
//
// Layout (outputLayout): float32 x y z at offsets 0, 4, 8; then [float32 normal_x normal_y normal_z curvature],
// [float32 cov_xx cov_xy cov_xz cov_yy cov_yz cov_zz (SampleCovariance.hpp)], [uint32 frame], uint8 level and every
// input field except x/y/z and the names this output writes itself (same name, type, count and bytes), ordered by
// decreasing element size. Every field sits at an offset that is a multiple of its element
// size and point_step is a multiple of 4 and of the largest element size, so records can be read as aligned structs
// (as PCL's padded point types are); the padding bytes are zero. Consumers find fields by name, not position.
#pragma once

#include <string>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/sampling/Hierarchy.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/normals/SampleCovariance.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds {

/// The input fields an output with these parts does not carry because it keeps the name for a field of its own
/// (level and frame always; normal_x/y/z and curvature with normals, cov_* with covariances), in input order:
/// callers say so rather than drop them silently. Every other input field is carried, an input's own normals
/// included when the output has none. Rename such a field to keep it.
[[nodiscard]] std::vector<std::string> fieldsNotCarried(const PointLayout &input, bool with_normals,
                                                        bool with_covariances);
/// Why an output does not carry the input field `name` (one fieldsNotCarried returned), for the warning: "hpds writes
/// its own 'curvature'", or for level and frame, which are reserved even where the output has no such field, that
/// they are.
[[nodiscard]] std::string fieldNotCarriedReason(const std::string &name);

/// The type of the output's x y z: AsInput is float64 when the input's x, y and z are all float64, else float32; the
/// others force one (a float32 keeps about 7 digits: 0.5 m at 5e6 m, so georeferenced coordinates need float64;
/// PCL's point types need float32).
enum class XyzType { AsInput, Float32, Float64 };

/// What output.float64_xyz and output.float32_xyz ask for (validateConfig refuses both).
[[nodiscard]] XyzType outputXyzType(const OutputConfig &output);

/// x y z as `xyz` says, at offsets 0, 4, 8 (float32) or 0, 8, 16 (float64).
[[nodiscard]] PointLayout outputLayout(const PointLayout &input, bool with_normals, bool with_frame,
                                       bool with_covariances = false, XyzType xyz = XyzType::AsInput);

/// `normals`, `covariances`: null, or one entry per id (std::invalid_argument otherwise). Samples are written in the
/// order of `ids`; x y z as outputLayout says.
[[nodiscard]] PointBuffer buildOutputCloud(const Hierarchy &hierarchy, const std::vector<SampleId> &ids,
                                           const std::vector<SampleNormal> *normals, bool with_frame,
                                           const std::vector<SampleCovariance> *covariances = nullptr,
                                           XyzType xyz = XyzType::AsInput);

/// [m] How far `cloud`'s x y z may lie from the positions they were written from: half a float32 unit in the last
/// place at its largest |coordinate| (2^-24 of it), 0 when they are float64 (or the cloud is empty). Programs
/// compare it with the output radius and say when it is not small against it.
[[nodiscard]] double positionRounding(const PointBuffer &cloud);

/// [m] The largest finite |x|, |y| or |z| of `cloud`, whatever their type (0 for an empty cloud).
[[nodiscard]] double largestCoordinate(const PointBuffer &cloud);

/// Whether float32 positions that round by up to `rounding` metres (positionRounding) can break the sampling at
/// output radius `output_radius`: more than 1 % of it. The one threshold of every rounding warning, and of the
/// Python binding's move to a local origin.
[[nodiscard]] bool roundingMatters(double rounding, double output_radius);

/// The sentence the CLI, the node and the tiled build print when float32 x y z round positions (`rounding`,
/// positionRounding) by more than 1 % of the output radius: samples may then come out closer than it. Empty below
/// that. `key` is what the reader sets there to get float64 x y z ("output.float64_xyz: true", a flag, a
/// parameter). `input_rounding` is the inputs' own positionRounding (0 when unknown or float64): when it is over
/// 1 % of the radius (whatever the output's type), the input itself holds no finer positions, so the sentence says
/// that float64 output cannot restore them and suggests a local frame instead of `key`.
[[nodiscard]] std::string positionRoundingWarning(double rounding, double output_radius, const std::string &key,
                                                  double input_rounding = 0.0);

/// Where poses place a run's samples far from the origin (georeferenced maps), float32 x y z would break the spacing
/// asked for. When neither output key chooses a type (outputXyzType AsInput) and float32 would round positions
/// around sensors at `largest_translation` (the largest |component| of the frames' pose translations, metres) by
/// more than 1 % of the output radius (roundingMatters), this sets output.float64_xyz and returns the sentence that
/// says so and names `float32_key` (what the reader sets to keep float32 for a float32-only reader); otherwise it
/// changes nothing and returns "". Samples lie a sensor's range beyond its pose: positionRoundingWarning on the
/// written cloud still catches what this bound misses.
std::string widenXyzForPoses(HpdsConfig &config, double largest_translation, const std::string &float32_key);

}  // namespace hpds
