// Contact-law kernels: pure functions of plain values, testable alone.
// The bookkeeping (which contact, which bodies) lives in contact.cpp.
#pragma once

#include <cmath>

#include "cpp_dem/material.hpp"

namespace cpp_dem {

/// Normal force magnitude of the linear law, N: F_n = k_n u_n (000 eq 1).
inline Real linear_normal_force(Real kn, Real overlap) { return kn * overlap; }

/// Hertz normal force magnitude, N: F_n = K delta^(3/2), K = 4/3 E* sqrt(R*).
inline Real hertz_normal_force(Real k_hertz, Real overlap) {
  return k_hertz * overlap * std::sqrt(overlap);
}

/// Hertz tangent normal stiffness dF_n/d delta, N/m: 3/2 K delta^(1/2).
inline Real hertz_normal_stiffness(Real k_hertz, Real overlap) {
  return 1.5 * k_hertz * std::sqrt(overlap);
}

/// Mindlin no-slip tangential stiffness, N/m: k_t = 8 G* sqrt(R* delta) = C sqrt(delta).
inline Real mindlin_shear_stiffness(Real c_mindlin, Real overlap) {
  return c_mindlin * std::sqrt(overlap);
}

/// Elastic energy stored in the normal spring, J.
inline Real normal_elastic_energy(ContactModel m, Real kn, Real overlap) {
  if (m == ContactModel::Linear) return 0.5 * kn * overlap * overlap;
  return 0.4 * kn * overlap * overlap * std::sqrt(overlap);  // int K d^1.5 = 2/5 K d^2.5
}

/// Viscous damping coefficient, N s/m: c = 2 beta sqrt(m* k).
inline Real viscous_coefficient(Real beta, Real mass_eff, Real stiffness) {
  return 2.0 * beta * std::sqrt(mass_eff * stiffness);
}

/// Coulomb cap (000 eq 3). Scales the trial shear force fs to at most tan_phi |fn| and
/// returns the energy dissipated by the slip, J (Yade's plastic dissipation: (fs_trial -
/// fs) . fs / k_s). fs is modified in place.
inline Real coulomb_cap(Vec3& fs, Real fn_abs, Real tan_phi, Real ks) {
  const Real cap = tan_phi * fn_abs;
  const Real norm2 = fs.squaredNorm();
  if (norm2 <= cap * cap) return 0.0;
  const Real norm = std::sqrt(norm2);
  const Vec3 trial = fs;
  fs *= (norm > 0 ? cap / norm : 0.0);
  return ks > 0 ? (trial - fs).dot(fs) / ks : 0.0;
}

/// Caps a rolling moment to rolling_cap |fn|, in place; returns the dissipated energy, J.
inline Real rolling_cap_apply(Vec3& mr, Real fn_abs, Real rolling_cap, Real kr) {
  const Real cap = rolling_cap * fn_abs;
  const Real norm2 = mr.squaredNorm();
  if (norm2 <= cap * cap) return 0.0;
  const Real norm = std::sqrt(norm2);
  const Vec3 trial = mr;
  mr *= (norm > 0 ? cap / norm : 0.0);
  return kr > 0 ? (trial - mr).dot(mr) / kr : 0.0;
}

}  // namespace cpp_dem
