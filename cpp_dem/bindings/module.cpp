// The compiled module cpp_dem._core. Type conversion only; physics lives in src/.
#include <omp.h>

#include "convert.hpp"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "Compiled DEM core of cpp_dem (private; use the cpp_dem package).";
  py::register_exception<cpp_dem::ParameterError>(m, "ParameterError", PyExc_ValueError);
  py::register_exception<cpp_dem::BlowUpError>(m, "BlowUpError", PyExc_RuntimeError);
  m.def("set_num_threads", [](int n) {
    if (n < 1) throw cpp_dem::ParameterError("threads=" + std::to_string(n) + ": must be >= 1");
    omp_set_num_threads(n);
  }, py::arg("threads"), "Sets the number of OpenMP threads used by every scene.");
  m.def("get_num_threads", []() { return omp_get_max_threads(); },
        "Number of OpenMP threads used by the next parallel region.");
  m.attr("GEOGRID") = py::bool_(cpp_dem::kGeogridBuilt);  // CMake option CPP_DEM_GEOGRID
  cpp_dem::bind::bind_material(m);
  cpp_dem::bind::bind_scene(m);
  cpp_dem::bind::bind_grid(m);
  cpp_dem::bind::bind_clumps(m);
  cpp_dem::bind::bind_controllers(m);
  cpp_dem::bind::bind_checkpoint(m);
  cpp_dem::bind::bind_cell(m);
  cpp_dem::bind::bind_bonds(m);
}
