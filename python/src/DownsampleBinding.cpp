// hpds.downsample: the one-call API (hpds/hpds.hpp) on a NumPy array.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cstring>
#include <string>

#include "Bindings.hpp"
#include "hpds/hpds.hpp"

namespace py = pybind11;

namespace hpds::python {

namespace {

std::string shapeText(const py::array &a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

// float64 coordinates are rounded to float32, as the C++ API's Eigen::Vector3f would store them.
std::vector<Eigen::Vector3f> pointsFrom(const py::handle &object) {
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
  const auto f32 = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
  if (!f32) throw py::error_already_set();
  std::vector<Eigen::Vector3f> points(static_cast<std::size_t>(f32.shape(0)));
  if (!points.empty()) std::memcpy(points[0].data(), f32.data(), points.size() * sizeof(Eigen::Vector3f));
  return points;
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
        const std::vector<Eigen::Vector3f> points = pointsFrom(points_object);
        if (viewpoint.size() != 3)
          throw py::value_error("viewpoint: expected 3 coordinates (x, y, z), got " + std::to_string(viewpoint.size()));
        Samples s;
        {
          py::gil_scoped_release unlocked;
          s = downsample(points, config, Eigen::Vector3d(viewpoint[0], viewpoint[1], viewpoint[2]));
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
