// hpds._hpds: the C++ side of the Python package `hpds` (python/hpds/__init__.py wraps it).
#include "Bindings.hpp"

PYBIND11_MODULE(_hpds, m) {
  m.doc() = "C++ core of the hpds package (use the wrappers in hpds)";
  m.attr("__version__") = HPDS_VERSION;
  hpds::python::bindConfig(m);
  hpds::python::bindDownsample(m);
  hpds::python::bindIo(m);
  hpds::python::bindTiling(m);
}
