// The pieces of the extension module hpds._hpds, one registration function per concern.
//
// Contract (every binding)
// - C++ exceptions become Python ones: std::invalid_argument -> ValueError (a bad config names its key, as the CLI
//   does), std::runtime_error -> RuntimeError (file errors name the file); a wrong argument type -> TypeError.
// - Long computations release the GIL, so Python threads (Dask's worker threads) run beside them.
#pragma once

#include <pybind11/pybind11.h>

#include <string>

#include <Eigen/Core>

#include "hpds/config/Config.hpp"
#include "hpds/points/PointBuffer.hpp"

namespace hpds::python {

/// config_dict(config_yaml, config_path), config_yaml(config_yaml, config_path, overlay).
void bindConfig(pybind11::module_ &m);
/// downsample(points, config_yaml, config_path).
void bindDownsample(pybind11::module_ &m);
/// read_points(path), read_poses(path).
void bindIo(pybind11::module_ &m);
/// The tiled map build's tasks: tiled_plan, tile_neighbours, tile_bounds, bucket_frames, build_tile, finish_tile.
void bindTiling(pybind11::module_ &m);

/// A point cloud file read as `hpds sample` reads it (.pcd/.ply through PCL when built with it, KITTI .bin).
/// `viewpoint` (optional): where the sensor was among the points (a PCD's VIEWPOINT; else the origin).
[[nodiscard]] PointBuffer readCloudFile(const std::string &path, Eigen::Vector3d *viewpoint = nullptr);

/// The config a Python call names: the YAML file at `path` when it is not empty, else `yaml_text` over the
/// defaults (empty: the defaults). Validated; std::invalid_argument names the key (or the file).
[[nodiscard]] HpdsConfig configFrom(const std::string &yaml_text, const std::string &path);

}  // namespace hpds::python
