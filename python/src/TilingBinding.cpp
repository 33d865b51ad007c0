// The tiled map build's tasks (hpds/tiling/) for python/hpds/map_build.py, which schedules them (in one process or
// on Dask). Every task takes the complete config as YAML text (dumpConfigYaml), so that a worker on another machine
// rebuilds the same struct, and returns its statistics as a dict.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <filesystem>
#include <tuple>

#include "Bindings.hpp"
#include "hpds/util/FrameMemory.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/points/FarViewpoint.hpp"
#include "hpds/tiling/TileBucket.hpp"
#include "hpds/tiling/TileBuild.hpp"

namespace py = pybind11;

namespace hpds::python {

namespace {

py::dict countersDict(const FrameCounters &c) {
  py::dict d;
  d["input"] = c.input;
  d["skipped_invalid"] = c.skipped_invalid;
  d["skipped_zero"] = c.skipped_zero;
  d["skipped_range"] = c.skipped_range;
  d["out_of_range"] = c.out_of_range;
  d["dropped_depth"] = c.dropped_depth;
  d["accepted"] = c.accepted;
  return d;
}

template <typename Array>
py::list levelList(const Array &per_level, int last) {
  py::list l;
  for (int d = 0; d <= last; ++d) l.append(per_level[static_cast<std::size_t>(d)]);
  return l;
}

HpdsConfig tiledConfig(const std::string &yaml) {
  const HpdsConfig config = loadConfigString(yaml);
  validateTiledConfig(config);
  return resolvedConfig(config);  // the cell the tiles run with: derived from output.spacing when cell_size is 0
}

std::string tileFileName(const TileKey &key, const char *ext) {
  return "tile_" + std::to_string(key.i) + "_" + std::to_string(key.j) + ext;
}

}  // namespace

void bindTiling(py::module_ &m) {
  m.def(
      "tiled_plan",
      [](const std::string &yaml, double tile_size) {
        const HpdsConfig config = tiledConfig(yaml);
        const TileGrid grid(config.hierarchy, tile_size);
        py::dict d;
        d["tile_size"] = grid.tileSize();
        d["cell_size"] = grid.cellSize();
        d["cells_per_tile"] = grid.cellsPerTile();
        d["insertion_ring"] = kInsertionRing;
        d["normal_ring"] = normalRing(config);
        d["border_ring"] = borderRing(config);
        d["output_level"] = resolveOutputLevel(config);
        d["output_radius"] = resolveOutput(config).radius;
        d["build_depth"] = Pipeline(tilePipelineConfig(config)).buildDepth();
        return d;
      },
      py::arg("config_yaml"), py::arg("tile_size"),
      "Checks a tiled build's config and tile size (ValueError naming the key) and returns its geometry.");
  m.def(
      "tile_cell",
      [](const std::string &yaml) {
        const HpdsConfig config = loadConfigString(yaml);
        validateTiledConfig(config);
        return py::make_tuple(resolveOutput(config).cell_size, config.hierarchy.cell_size == 0.0);
      },
      py::arg("config_yaml"),
      "(cell_size, derived): the level-0 cell a tiled build runs with, and whether it is derived from output.spacing "
      "(hierarchy.cell_size 0) rather than fixed by the config.");
  m.def(
      "tile_neighbours",
      [](const std::string &yaml, double tile_size, std::int32_t i, std::int32_t j, int ring) {
        const HpdsConfig config = resolvedConfig(loadConfigString(yaml));
        std::vector<std::pair<std::int32_t, std::int32_t>> out;
        for (const TileKey &k : TileGrid(config.hierarchy, tile_size).neighbours(TileKey{i, j}, ring))
          out.emplace_back(k.i, k.j);
        return out;
      },
      py::arg("config_yaml"), py::arg("tile_size"), py::arg("i"), py::arg("j"), py::arg("ring"),
      "Tiles other than (i, j) with a level-0 cell column within `ring` columns of it, row-major.");
  m.def(
      "tile_bounds",
      [](const std::string &yaml, double tile_size, std::int32_t i, std::int32_t j) {
        const HpdsConfig config = resolvedConfig(loadConfigString(yaml));
        const auto b = TileGrid(config.hierarchy, tile_size).bounds(TileKey{i, j});
        return std::vector<double>(b.begin(), b.end());
      },
      py::arg("config_yaml"), py::arg("tile_size"), py::arg("i"), py::arg("j"), "[x_min, y_min, x_max, y_max] of a tile.");
  m.def(
      "bucket_frames",
      [](const std::string &yaml, double tile_size, const std::vector<std::string> &inputs,
         const py::array_t<double, py::array::c_style | py::array::forcecast> &poses, std::uint32_t first_frame,
         const std::string &out_dir) {
        if (poses.ndim() != 3 || poses.shape(0) != static_cast<py::ssize_t>(inputs.size()) || poses.shape(1) != 4 ||
            poses.shape(2) != 4)
          throw py::value_error("poses: expected one 4x4 matrix per input");
        const HpdsConfig config = tiledConfig(yaml);
        const TileGrid grid(config.hierarchy, tile_size);
        std::vector<Eigen::Isometry3d> iso(inputs.size());
        for (std::size_t f = 0; f < inputs.size(); ++f)
          for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) iso[f].matrix()(r, c) = poses.at(static_cast<py::ssize_t>(f), r, c);
        FrameCounters totals;
        std::vector<std::tuple<std::int32_t, std::int32_t, std::uint64_t, std::string>> tiles;
        std::size_t bytes = 0;
        PointLayout layout;
        bool has_layout = false;
        // The first frame whose viewpoint is no sensor's position (isFarViewpoint): the start of the build's warning.
        std::string far_viewpoint;
        {
          py::gil_scoped_release unlocked;
          TileBucketer bucketer(config, grid);
          for (std::size_t f = 0; f < inputs.size(); ++f) {
            Frame frame;
            frame.points = readCloudFile(inputs[f], &frame.viewpoint);
            frame.sensor_to_fixed = iso[f];
            if (far_viewpoint.empty())
              if (const double d = nearestPointDistance(frame.points, frame.viewpoint); isFarViewpoint(d))
                far_viewpoint = farViewpointWarning(inputs[f], d, frame.viewpoint);
            try {
              totals += bucketer.addFrame(frame, first_frame + static_cast<std::uint32_t>(f));
            } catch (const std::invalid_argument &e) {
              throw std::invalid_argument("'" + inputs[f] + "': " + e.what());
            }
          }
          bytes = bucketer.memUsage();
          layout = bucketer.layout();
          has_layout = bucketer.hasLayout();
          std::filesystem::create_directories(out_dir);
          for (const auto &[key, n] : bucketer.tiles()) {
            const std::string path = (std::filesystem::path(out_dir) / tileFileName(key, ".bkt")).string();
            writeTileBucket(path, bucketer.layout(), bucketer.framesOf(key));
            tiles.emplace_back(key.i, key.j, n, path);
          }
        }
        py::dict d;
        d["tiles"] = tiles;
        d["counters"] = countersDict(totals);
        d["memory_bytes"] = bytes;
        d["far_viewpoint"] = far_viewpoint.empty() ? py::object(py::none()) : py::object(py::str(far_viewpoint));
        // The frames' point fields, which every bucketing task of one build must share (map mode's rule); None when
        // every frame of the task was empty (those take any fields).
        py::list fields;
        for (const PointField &f : layout.fields)
          fields.append(py::make_tuple(f.name, f.offset, fieldTypeName(f.type), f.count));
        d["layout"] = has_layout ? py::object(py::make_tuple(fields, layout.point_step)) : py::object(py::none());
        return d;
      },
      py::arg("config_yaml"), py::arg("tile_size"), py::arg("inputs"), py::arg("poses"), py::arg("first_frame"),
      py::arg("out_dir"),
      "Bucketing task: reads the inputs (frames first_frame, ...), files their points per tile into "
      "out_dir/tile_<i>_<j>.bkt; returns the tiles [(i, j, points, path)], the skip counters and the first frame "
      "whose viewpoint lies too far from all its points to be its sensor's: the start of its warning (farViewpointWarning), "
      "or None.");
  m.def(
      "build_tile",
      [](const std::string &yaml, double tile_size, std::int32_t i, std::int32_t j,
         const std::vector<std::string> &buckets, const std::vector<std::string> &borders, const std::string &map_path,
         const std::string &border_path) {
        const HpdsConfig config = tiledConfig(yaml);
        const TileGrid grid(config.hierarchy, tile_size);
        TileBuildStats s;
        {
          py::gil_scoped_release unlocked;
          s = buildTile(config, grid, TileKey{i, j}, buckets, borders, map_path, border_path);
        }
        py::dict d;
        d["counters"] = countersDict(s.counters);
        d["frames"] = s.frames;
        d["band_samples"] = s.band_samples;
        d["samples"] = s.samples;
        d["border_samples"] = s.border_samples;
        d["memory_bytes"] = s.memory_bytes;
        d["samples_per_level"] = levelList(s.counters.accepted_per_level, config.hierarchy.max_depth);
        return d;
      },
      py::arg("config_yaml"), py::arg("tile_size"), py::arg("i"), py::arg("j"), py::arg("buckets"),
      py::arg("borders"), py::arg("map_path"), py::arg("border_path"),
      "Phase task: builds tile (i, j) from its buckets on top of its earlier-phase neighbours' border files.");
  m.def(
      "finish_tile",
      [](const std::string &yaml, double tile_size, std::int32_t i, std::int32_t j, const std::string &map_path,
         const std::vector<std::string> &borders, const std::string &ply_path) {
        const HpdsConfig config = tiledConfig(yaml);
        const TileGrid grid(config.hierarchy, tile_size);
        TileFinishStats s;
        {
          py::gil_scoped_release unlocked;
          s = finishTile(config, grid, TileKey{i, j}, map_path, borders, ply_path);
        }
        py::dict d;
        d["samples"] = s.samples;
        d["samples_per_level"] = levelList(s.per_level, resolveOutputLevel(config));
        d["invalid_normals"] = s.invalid_normals;
        d["band_samples"] = s.band_samples;
        d["bounds"] = std::vector<double>(s.bounds.begin(), s.bounds.end());
        d["rounding"] = s.rounding;
        return d;
      },
      py::arg("config_yaml"), py::arg("tile_size"), py::arg("i"), py::arg("j"), py::arg("map_path"),
      py::arg("borders"), py::arg("ply_path"),
      "Output task: writes tile (i, j)'s PLY (normals read across its neighbours' border files).");
  m.def("keep_freed_frame_memory", &keepFreedFrameMemory,
        "Process-wide: glibc's malloc keeps freed memory for the next task (hpds::keepFreedFrameMemory). For the "
        "processes that run map_build's tasks; True when the setting took.");
  m.attr("frame_memory_can_be_kept") = kFreedFrameMemoryCanBeKept;
  m.def("rounding_warning", &positionRoundingWarning, py::arg("rounding"), py::arg("output_radius"), py::arg("key"),
        py::arg("input_rounding") = 0.0,
        "The warning `hpds sample` prints when float32 x y z round positions by more than 1 % of the output radius, "
        "or the inputs' own float32 x y z did (`input_rounding`) (empty below that).");
}

}  // namespace hpds::python
