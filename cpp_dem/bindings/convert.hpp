// NumPy <-> Eigen/std::vector conversion helpers for the bindings. No physics here.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstring>
#include <string>
#include <vector>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem::bind {

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

/// (n, 3) float64 array copied from a vector of Vec3.
inline py::array_t<double> vec3_array(const std::vector<Vec3>& v) {
  py::array_t<double> out({static_cast<py::ssize_t>(v.size()), py::ssize_t(3)});
  static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 must be 3 packed doubles");
  if (!v.empty()) std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(Vec3));
  return out;
}

/// (n,) float64 array copied from a vector of Real.
inline py::array_t<double> real_array(const std::vector<Real>& v) {
  py::array_t<double> out(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(Real));
  return out;
}

/// Reads an (n, 3) array (or a single 3-vector when n is -1 and one row is given).
inline std::vector<Vec3> to_vec3_list(const Array& a, const char* field) {
  if (a.ndim() == 1 && a.shape(0) == 3) return {Vec3(a.at(0), a.at(1), a.at(2))};
  if (a.ndim() != 2 || a.shape(1) != 3)
    throw ParameterError(std::string(field) + ": expected an array of shape (n, 3), got " +
                         std::to_string(a.ndim()) + " dimensions");
  std::vector<Vec3> v(a.shape(0));
  if (!v.empty()) std::memcpy(static_cast<void*>(v.data()), a.data(), v.size() * sizeof(Vec3));
  return v;
}

inline std::vector<Real> to_real_list(const Array& a, const char* field) {
  if (a.ndim() != 1)
    throw ParameterError(std::string(field) + ": expected a 1-D array, got " +
                         std::to_string(a.ndim()) + " dimensions");
  return std::vector<Real>(a.data(), a.data() + a.shape(0));
}

inline Vec3 to_vec3(const Array& a, const char* field) {
  if (a.ndim() != 1 || a.shape(0) != 3)
    throw ParameterError(std::string(field) + ": expected 3 values (x, y, z)");
  return Vec3(a.at(0), a.at(1), a.at(2));
}

/// A number argument (a Python int or float, or a NumPy scalar; not a bool or a string), or
/// ParameterError "<field>=<value>: must be a number (<unit>)".
inline double number_arg(const py::handle& v, const char* field, const char* unit) {
  if (!py::isinstance<py::bool_>(v) && !py::isinstance<py::str>(v) &&
      !py::isinstance<py::bytes>(v)) {
    const double x = PyFloat_AsDouble(v.ptr());
    if (!(x == -1.0 && PyErr_Occurred())) return x;
    PyErr_Clear();
  }
  throw ParameterError(std::string(field) + "=" + py::repr(v).cast<std::string>() +
                       ": must be a number (" + unit + ")");
}

void bind_material(py::module_& m);
void bind_scene(py::module_& m);
void bind_grid(py::module_& m);
void bind_clumps(py::module_& m);
void bind_controllers(py::module_& m);  // samples: controllers and checkpoint
void bind_checkpoint(py::module_& m);
void bind_cell(py::module_& m);  // after bind_controllers (CellController)
void bind_bonds(py::module_& m);

}  // namespace cpp_dem::bind
