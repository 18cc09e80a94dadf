// Contact-law part: viscous damping (normal and shear), a dashpot beside each spring.
// Pure kernels of plain values.
#pragma once

#include <cmath>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// Viscous damping coefficient, N s/m: c = 2 beta sqrt(m* k), beta the ratio of critical.
inline Real viscous_coefficient(Real beta, Real mass_eff, Real stiffness) {
  return 2.0 * beta * std::sqrt(mass_eff * stiffness);
}

}  // namespace cpp_dem
