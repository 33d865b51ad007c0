// hpds.downsample: the one-call API (hpds/hpds.hpp) on a NumPy array.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "Bindings.hpp"
#include "hpds/hpds.hpp"
#include "hpds/pipeline/OutputCloud.hpp"

namespace py = pybind11;

namespace hpds::python {

namespace {

std::string shapeText(const py::array &a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

/// The points as the C++ API takes them (float32), and the translation they were given on the way.
struct ApiPoints {
  std::vector<Eigen::Vector3f> points;
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();  ///< subtracted from every point (and so from the viewpoint)
};

/// float64 coordinates are rounded to float32, as the C++ API's Eigen::Vector3f stores them. Far from the origin
/// (georeferenced: a UTM northing of 5e6 m rounds by 0.3 m) that breaks the sampling's guarantees, so where the
/// rounding would exceed 1 % of the output radius the points are first moved by an origin near them: a whole number
/// of level-0 cells, so that every level's cells, and with them the sampling, stay where they were. Samples are
/// named by index and normals do not change under a translation, so nothing else shows it. The range limits measure
/// from the sensor at the origin, so with those set the points cannot move: a UserWarning says what is lost.
ApiPoints pointsFrom(const py::handle &object, const HpdsConfig &config) {
  if (!py::isinstance<py::array>(object))
    throw py::type_error("points: expected an (N, 3) NumPy array of float32 or float64, got " +
                         std::string(py::str(py::type::of(object).attr("__name__"))));
  const auto array = py::reinterpret_borrow<py::array>(object);
  // By kind and size, not dtype identity: byte-swapped ('>f8') and metadata-carrying float dtypes are floats too
  // (forcecast below converts them).
  const py::dtype dtype = array.dtype();
  if (dtype.kind() != 'f' || (dtype.itemsize() != 4 && dtype.itemsize() != 8))
    throw py::type_error("points: expected float32 or float64 coordinates, got dtype " +
                         std::string(py::str(static_cast<const py::handle &>(dtype))));
  if (array.ndim() != 2 || array.shape(1) != 3)
    throw py::value_error("points: expected shape (N, 3), got " + shapeText(array));
  ApiPoints out;
  if (dtype.itemsize() == 8) {
    const auto f64 = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
    if (!f64) throw py::error_already_set();
    const std::size_t n = static_cast<std::size_t>(f64.shape(0));
    const double *p = f64.data();
    double largest = 0.0;
    const double *first = nullptr;
    for (std::size_t i = 0; i < n; ++i) {
      const double *q = p + 3 * i;
      if (!(std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2]))) continue;
      if (!first) first = q;
      largest = std::max({largest, std::fabs(q[0]), std::fabs(q[1]), std::fabs(q[2])});
    }
    const OutputResolution res = resolveOutput(config);
    const double rounding = std::ldexp(largest, -24);
    if (roundingMatters(rounding, res.radius)) {
      if (config.input.min_range > 0.0 || config.input.max_range > 0.0) {
        const std::string text = "hpds.downsample: float32 rounds these float64 points by up to " +
                                 std::to_string(rounding) + " m, more than 1 % of the output radius " +
                                 std::to_string(res.radius) +
                                 " m, and input.min_range/max_range keep them from being moved to a local origin: "
                                 "samples may come out closer than the radius; pass sensor-frame points";
        if (PyErr_WarnEx(PyExc_UserWarning, text.c_str(), 1) != 0) throw py::error_already_set();
      } else {
        for (int a = 0; a < 3; ++a) out.shift[a] = std::floor(first[a] / res.cell_size) * res.cell_size;
      }
    }
    out.points.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) out.points[i][a] = static_cast<float>(p[3 * i + a] - out.shift[a]);
    return out;
  }
  const auto f32 = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
  if (!f32) throw py::error_already_set();
  out.points.resize(static_cast<std::size_t>(f32.shape(0)));
  if (!out.points.empty()) std::memcpy(out.points[0].data(), f32.data(), out.points.size() * sizeof(Eigen::Vector3f));
  return out;
}

template <typename T>
py::array_t<T> arrayOf(const std::vector<T> &v) {
  py::array_t<T> a(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(T));
  return a;
}

}  // namespace

void bindDownsample(py::module_ &m) {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "Vector3f is three packed floats");
  m.def(
      "downsample",
      [](const py::handle &points_object, const std::string &yaml_text, const std::string &path,
         const std::vector<double> &viewpoint) {
        const HpdsConfig config = configFrom(yaml_text, path);
        const ApiPoints points = pointsFrom(points_object, config);
        if (viewpoint.size() != 3)
          throw py::value_error("viewpoint: expected 3 coordinates (x, y, z), got " + std::to_string(viewpoint.size()));
        Samples s;
        {
          py::gil_scoped_release unlocked;
          s = downsample(points.points, config,
                         Eigen::Vector3d(viewpoint[0], viewpoint[1], viewpoint[2]) - points.shift);
        }
        py::dict out;
        out["index"] = arrayOf(s.index);
        out["level"] = arrayOf(s.level);
        if (config.normals.enabled) {
          py::array_t<float> normal({static_cast<py::ssize_t>(s.size()), py::ssize_t(3)});
          if (s.size()) std::memcpy(normal.mutable_data(), s.normal.data(), s.size() * sizeof(Eigen::Vector3f));
          out["normal"] = normal;
          out["curvature"] = arrayOf(s.curvature);
        }
        if (config.normals.covariances) {
          // Symmetric: Eigen's column-major storage reads the same as NumPy's row-major (n, 3, 3).
          static_assert(sizeof(Eigen::Matrix3f) == 9 * sizeof(float), "Matrix3f is nine packed floats");
          py::array_t<float> cov({static_cast<py::ssize_t>(s.size()), py::ssize_t(3), py::ssize_t(3)});
          if (s.size()) std::memcpy(cov.mutable_data(), s.covariance.data(), s.size() * sizeof(Eigen::Matrix3f));
          out["covariance"] = cov;
        }
        return out;
      },
      py::arg("points"), py::arg("config_yaml"), py::arg("config_path"), py::arg("viewpoint"),
      "Samples of `points` ((N, 3) float32/float64) with the config (file `config_path` if not empty, else "
      "`config_yaml`) and normals facing `viewpoint` (x, y, z in the points' frame): dict of index, level and, with "
      "normals, normal and curvature, with covariances covariance.");
}

}  // namespace hpds::python
