// Files in: point clouds (as `hpds sample` reads them) and KITTI pose files, as NumPy arrays.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "Bindings.hpp"
#include "hpds/io/InputFolders.hpp"
#include "hpds/io/KittiBin.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/io/SamplingRecord.hpp"
#ifdef HPDS_PYTHON_WITH_PCL
#include "hpds/pcl/PointCloudFile.hpp"
#endif

namespace py = pybind11;

namespace hpds::python {

PointBuffer readCloudFile(const std::string &path, Eigen::Vector3d *viewpoint) {
#ifdef HPDS_PYTHON_WITH_PCL
  return readPointCloud(path, viewpoint);
#else
  if (viewpoint) viewpoint->setZero();
  std::string ext = path.size() >= 4 ? path.substr(path.size() - 4) : "";
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext != ".bin")
    throw std::runtime_error(path + ": this build of hpds has no PCL: only KITTI .bin files can be read");
  return readKittiBin(path);
#endif
}

namespace {

/// NumPy's little-endian type string of a field type ('<f4', ...).
const char *numpyType(FieldType type) {
  switch (type) {
    case FieldType::Int8: return "i1";
    case FieldType::UInt8: return "u1";
    case FieldType::Int16: return "<i2";
    case FieldType::UInt16: return "<u2";
    case FieldType::Int32: return "<i4";
    case FieldType::UInt32: return "<u4";
    case FieldType::Float32: return "<f4";
    case FieldType::Float64: return "<f8";
  }
  throw std::logic_error("numpyType: not a field type");
}

/// The records of `cloud` as a structured array: one field per point field, at its offset, itemsize point_step
/// (padding kept as such), so the bytes are the file's records as hpds read them.
py::array structuredArray(const PointBuffer &cloud) {
  const PointLayout &l = cloud.layout();
  py::list names, formats, offsets;
  for (const PointField &f : l.fields) {
    names.append(f.name);
    if (f.count == 1)
      formats.append(numpyType(f.type));
    else
      formats.append(py::make_tuple(numpyType(f.type), py::make_tuple(f.count)));
    offsets.append(f.offset);
  }
  py::dict spec;
  spec["names"] = names;
  spec["formats"] = formats;
  spec["offsets"] = offsets;
  spec["itemsize"] = l.point_step;
  const py::dtype dtype = py::dtype::from_args(spec);
  py::array out(dtype, std::vector<py::ssize_t>{static_cast<py::ssize_t>(cloud.size())});
  if (cloud.size()) std::memcpy(out.mutable_data(), cloud.bytes().data(), cloud.size() * l.point_step);
  return out;
}

/// Reads `path` (without the GIL), refuses a cloud without x/y/z, and returns `toArray(cloud)`, with the viewpoint
/// as a (3,) float64 array beside it when asked.
template <typename ToArray>
py::object readXyzCloud(const std::string &path, bool return_viewpoint, ToArray toArray) {
  PointBuffer cloud;
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
  {
    py::gil_scoped_release unlocked;
    cloud = readCloudFile(path, &viewpoint);
  }
  const PointLayout &l = cloud.layout();
  if (!l.find("x") || !l.find("y") || !l.find("z")) throw std::runtime_error(path + ": no x/y/z fields");
  py::array out = toArray(cloud);
  if (!return_viewpoint) return std::move(out);
  py::array_t<double> vp(3);
  for (int a = 0; a < 3; ++a) vp.mutable_data()[a] = viewpoint[a];
  return py::make_tuple(out, vp);
}

}  // namespace

void bindIo(py::module_ &m) {
  m.def(
      "read_cloud",
      [](const std::string &path, bool return_viewpoint) {
        return readXyzCloud(path, return_viewpoint, [](const PointBuffer &cloud) { return structuredArray(cloud); });
      },
      py::arg("path"), py::arg("return_viewpoint") = false,
      "Every point of a .pcd/.ply/.bin file with all its fields as a structured array (field names, types and "
      "offsets as read; PCL's packed rgb as the uint32 it is); with return_viewpoint also the sensor position.");
  m.def(
      "read_points",
      [](const std::string &path, bool return_viewpoint) {
        return readXyzCloud(path, return_viewpoint, [](const PointBuffer &cloud) {
          const PointLayout &l = cloud.layout();
          const PointField *f[3] = {l.find("x"), l.find("y"), l.find("z")};
          py::array_t<double> xyz({static_cast<py::ssize_t>(cloud.size()), py::ssize_t(3)});
          double *out = xyz.mutable_data();
          for (std::size_t i = 0; i < cloud.size(); ++i)
            for (int a = 0; a < 3; ++a) out[3 * i + a] = readAsDouble(cloud.record(i), *f[a]);
          return py::array(std::move(xyz));
        });
      },
      py::arg("path"), py::arg("return_viewpoint") = false,
      "x, y, z of every point of a .pcd/.ply/.bin file as an (N, 3) float64 array (exact); with return_viewpoint "
      "also the sensor position (PCD VIEWPOINT; zeros without one) as a (3,) float64 array.");
  m.def(
      "read_poses",
      [](const std::string &path) {
        PoseCorrection correction;
        const std::vector<Eigen::Isometry3d> poses = readKittiPoses(path, correction);
        py::array_t<double> out({static_cast<py::ssize_t>(poses.size()), py::ssize_t(4), py::ssize_t(4)});
        double *o = out.mutable_data();
        for (std::size_t k = 0; k < poses.size(); ++k)
          for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) o[16 * k + 4 * r + c] = poses[k].matrix()(r, c);
        return py::make_tuple(out, poseCorrectionWarning(path, correction));
      },
      py::arg("path"),
      "Poses of a KITTI or TUM pose file as an (N, 4, 4) float64 array of sensor-to-world matrices, and the warning "
      "for rotations the reading had to correct by more than printing rounds, or ''.");
  // The input list rules of `hpds sample`, for the tiled map build: one implementation, the same order and texts.
  m.def(
      "expand_inputs",
      [](const std::vector<std::string> &given) {
        std::ostringstream notes;
        std::vector<std::string> inputs = expandInputFolders(given, notes);
        return py::make_tuple(inputs, notes.str());
      },
      py::arg("paths"), "(inputs, notes): every folder of `paths` replaced by its frames in natural name order.");
  m.def("check_poses_match_inputs", &checkPosesMatchInputs, py::arg("poses_path"), py::arg("poses"),
        py::arg("inputs"),
        "ValueError when the pose count is not the input count; else '' or a warning that the files of one folder "
        "are not in natural name order.");
  m.def("ply_marked_as_samples", &plyMarkedAsSamples, py::arg("path"),
        "Whether a PLY file carries the header comment of a sampling's output.");
  m.attr("PLY_SAMPLES_COMMENT") = kPlySamplesComment;
  m.def(
      "read_sampling_record",
      [](const std::string &path) -> py::object {
        const std::optional<SamplingRecord> r = readSamplingRecord(path);
        if (!r) return py::none();
        return py::make_tuple(r->cell_size, r->max_depth, r->output_level);
      },
      py::arg("path"),
      "(cell_size, max_depth, output_level) recorded in a sampling's PLY header, or None; RuntimeError when the "
      "line is malformed.");
  m.def(
      "sampling_record_line",
      [](double cell_size, int max_depth, int output_level) {
        return samplingRecordLine(SamplingRecord{cell_size, max_depth, output_level});
      },
      py::arg("cell_size"), py::arg("max_depth"), py::arg("output_level"),
      "The PLY header line recording a sampling's cell, max_depth and output level.");
}

}  // namespace hpds::python
