// hpds.downsample: the one-call API (hpds/hpds.hpp) on a NumPy array.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <future>
#include <string>
#include <thread>

#include "Bindings.hpp"
#include "hpds/hpds.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/points/FarViewpoint.hpp"

namespace py = pybind11;

namespace hpds::python {

namespace {

std::string shapeText(const py::array &a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

/// The points as the C++ API takes them: float32 arrays as Eigen::Vector3f, float64 ones as Eigen::Vector3d, which
/// the API samples at full precision (georeferenced coordinates: float32 keeps only 0.5 m at 5e6 m).
struct ApiPoints {
  std::vector<Eigen::Vector3f> f32;
  std::vector<Eigen::Vector3d> f64;
  bool is_f64 = false;
};

ApiPoints pointsFrom(const py::handle &object) {
  if (!py::isinstance<py::array>(object))
    throw py::type_error("points: expected an (N, 3) NumPy array of float32 or float64, got " +
                         std::string(py::str(py::type::of(object).attr("__name__"))) +
                         " (numpy.asarray(points, dtype=numpy.float64) makes one)");
  const auto array = py::reinterpret_borrow<py::array>(object);
  // By kind and size, not dtype identity: byte-swapped ('>f8') and metadata-carrying float dtypes are floats too
  // (forcecast below converts them).
  const py::dtype dtype = array.dtype();
  if (dtype.kind() != 'f' || (dtype.itemsize() != 4 && dtype.itemsize() != 8))
    throw py::type_error("points: expected float32 or float64 coordinates, got dtype " +
                         std::string(py::str(static_cast<const py::handle &>(dtype))) +
                         (dtype.kind() == 'V' ? " (hpds.downsample takes a structured array's float fields x, y, z)"
                                              : " (points.astype(numpy.float64) converts it)"));
  if (array.ndim() != 2 || array.shape(1) != 3)
    throw py::value_error("points: expected shape (N, 3), got " + shapeText(array));
  ApiPoints out;
  if (dtype.itemsize() == 8) {
    const auto f64 = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
    if (!f64) throw py::error_already_set();
    out.is_f64 = true;
    out.f64.resize(static_cast<std::size_t>(f64.shape(0)));
    if (!out.f64.empty()) std::memcpy(out.f64[0].data(), f64.data(), out.f64.size() * sizeof(Eigen::Vector3d));
    return out;
  }
  const auto f32 = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
  if (!f32) throw py::error_already_set();
  out.f32.resize(static_cast<std::size_t>(f32.shape(0)));
  if (!out.f32.empty()) std::memcpy(out.f32[0].data(), f32.data(), out.f32.size() * sizeof(Eigen::Vector3f));
  return out;
}

/// Runs `work` on a thread of its own while the calling (Python) thread waits without the GIL, waking every 50 ms
/// to let Python run its signal handlers: when one raises (Ctrl-C's KeyboardInterrupt), `interrupt` is set, the work
/// stops at its next stage boundary (hpds/util/Interrupt.hpp) and the handler's exception propagates. A call of
/// seconds on millions of points could otherwise not be stopped from a terminal or a notebook.
template <typename Result, typename Work>
Result runInterruptibly(Work &&work, std::atomic<bool> &interrupt) {
  std::packaged_task<Result()> task(std::forward<Work>(work));
  std::future<Result> done = task.get_future();
  std::thread worker(std::move(task));
  for (;;) {
    bool ready;
    {
      py::gil_scoped_release unlocked;
      ready = done.wait_for(std::chrono::milliseconds(50)) == std::future_status::ready;
    }
    if (ready) break;
    if (PyErr_CheckSignals() != 0) {
      interrupt = true;
      {
        py::gil_scoped_release unlocked;
        worker.join();
      }
      throw py::error_already_set();
    }
  }
  worker.join();
  return done.get();
}

/// The warning for float32 points whose own rounding (half an ulp at their largest |coordinate|) is over 1 % of the
/// output radius (positionRoundingWarning, as the CLI gives it for a file): empty for float64 or small coordinates.
std::string inputRoundingWarning(const ApiPoints &points, const HpdsConfig &config) {
  if (points.is_f64) return {};
  double largest = 0.0;
  for (const Eigen::Vector3f &p : points.f32)
    for (int a = 0; a < 3; ++a)
      if (std::isfinite(p[a])) largest = std::max(largest, static_cast<double>(std::fabs(p[a])));
  return positionRoundingWarning(0.0, resolveOutput(config).radius, "", std::ldexp(largest, -24));
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
  static_assert(sizeof(Eigen::Vector3d) == 3 * sizeof(double), "Vector3d is three packed doubles");
  m.def(
      "downsample",
      [](const py::handle &points_object, const std::string &yaml_text, const std::string &path,
         const std::vector<double> &viewpoint) {
        const HpdsConfig config = configFrom(yaml_text, path);
        const ApiPoints points = pointsFrom(points_object);
        if (viewpoint.size() != 3)
          throw py::value_error("viewpoint: expected 3 coordinates (x, y, z), got " + std::to_string(viewpoint.size()));
        const Eigen::Vector3d at(viewpoint[0], viewpoint[1], viewpoint[2]);
        std::atomic<bool> interrupt{false};
        const Samples s = runInterruptibly<Samples>(
            [&] {
              return points.is_f64 ? downsampleDoubles(points.f64, config, at, interrupt)
                                   : downsample(points.f32, config, at, interrupt);
            },
            interrupt);
        std::string rounding;
        double nearest = 0.0;
        {
          py::gil_scoped_release unlocked;
          rounding = inputRoundingWarning(points, config);
          nearest = points.is_f64 ? nearestPointDistance(points.f64, at) : nearestPointDistance(points.f32, at);
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
        py::dict skipped;
        skipped["invalid"] = s.skipped_invalid;
        skipped["zero"] = s.skipped_zero;
        skipped["range"] = s.skipped_range;
        skipped["out_of_range"] = s.out_of_range;
        skipped["evicted"] = s.evicted;
        py::dict resolution;
        resolution["output_level"] = s.output_level;
        resolution["radius"] = s.radius;
        resolution["cell_size"] = s.cell_size;
        return py::make_tuple(out, skipped, rounding, resolution, isFarViewpoint(nearest) ? nearest : 0.0);
      },
      py::arg("points"), py::arg("config_yaml"), py::arg("config_path"), py::arg("viewpoint"),
      "Samples of `points` ((N, 3) float32/float64) with the config (file `config_path` if not empty, else "
      "`config_yaml`) and normals facing `viewpoint` (x, y, z in the points' frame): (dict of index, level and, with "
      "normals, normal and curvature, with covariances covariance; dict of the points left out by reason; the "
      "warning for float32 points rounded by more than 1 % of the output radius, or ''; the resolution: output_level, "
      "radius, cell_size; the distance from `viewpoint` to the nearest point when it is too far to be the sensor's "
      "position (isFarViewpoint), else 0).");
}

}  // namespace hpds::python
