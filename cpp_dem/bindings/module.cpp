// The compiled module cpp_dem._core. Type conversion only; physics lives in src/.
#include <omp.h>

#include "convert.hpp"
#include "cpp_dem/core/simd.hpp"

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
  m.def("simd_dispatch", []() {
    py::dict d;
    d["ops"] = cpp_dem::use_wide_ops() ? "wide" : "narrow";
#if defined(CPP_DEM_CLONES)
    __builtin_cpu_init();
    d["clones"] = true;
    d["level"] = __builtin_cpu_supports("x86-64-v4")   ? "x86-64-v4"
                 : __builtin_cpu_supports("x86-64-v3") ? "x86-64-v3"
                                                       : "baseline";
#else
    d["clones"] = false;
    d["level"] = "built for one target";
#endif
    d["linear_batch"] = cpp_dem::linear_batch_available();
    return d;
  }, "The step's SIMD path in this process: ops 'wide' (4-lane vector ops) or 'narrow' "
     "(CPP_DEM_NARROW=1, or a CPU without AVX2 + FMA); with clones (the hot loops compiled "
     "for x86-64-v4, -v3 and baseline), the level the loader picks on this CPU; "
     "linear_batch: whether the pair pass runs active linear contacts eight at a time "
     "(wide, on a CPU with AVX-512).");
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
