// Contact-law part: the incremental tangential spring, kept in the turning contact frame, and
// the Coulomb cap (000 eqs 2-3). Written once as templates over the 3-vector operations of
// core/simd.hpp (WideOps, NarrowOps), so the short kernels of the hot loops, the composed law
// (laws/contact_law.hpp), the rolling part and the geogrid's beam links run the same lines.
#pragma once

#include <cmath>

#include "cpp_dem/core/simd.hpp"

namespace cpp_dem {

/// The turn of a contact frame over one step of dt (s): the normal turned from n_old to n
/// (rotation axis n_old x n) and spun about n by half the summed spin of the two sides,
/// angvel_sum (rad/s): twist = dt/2 (n . angvel_sum) n.
template <class Ops, class V>
ALWAYS_INLINE void frame_turn(const V& n_old, const V& n, const V& angvel_sum, Real dt, V& axis,
                              V& twist) {
  axis = Ops::cross(n_old, n);
  twist = (0.5 * dt * Ops::dot(n, angvel_sum)) * n;
}

/// Carries a vector stored in the contact's tangent plane (a shear force, a rolling or
/// bending moment) into the turned frame (frame_turn), and drops what the turn left normal.
template <class Ops, class V>
ALWAYS_INLINE void turn_into_frame(V& f, const V& axis, const V& twist, const V& n) {
  f -= Ops::cross(f, axis);
  f -= Ops::cross(f, twist);
  f -= Ops::dot(f, n) * n;
}

/// The Coulomb cap, 000 eq (3), of a tangential force whose spring part is `spring` and whose
/// total (spring plus dashpot, or the spring alone) is `total`: when |total| > cap (N), the
/// spring takes the capped total (slip) and the energy the slip dissipates,
/// (spring - capped) . capped / k (J; Yade's plastic dissipation), is added to `dissipated`
/// when the spring stiffness k (N/m) is > 0. Returns whether it slipped. The same cap limits
/// the rolling moment (laws/rolling.hpp) and the beam moments (laws/beam.hpp).
template <class Ops, class V>
ALWAYS_INLINE bool cap_spring(V& spring, const V& total, Real cap, Real k, Real& dissipated) {
  const Real t2 = Ops::dot(total, total);
  if (!(t2 > cap * cap)) return false;
  const Real norm = std::sqrt(t2);
  const V capped = norm > 0 ? V(total * (cap / norm)) : Ops::zero();
  if (k > 0) dissipated += Ops::dot(spring - capped, capped) / k;
  spring = capped;
  return true;
}

/// cap_spring of a spring alone.
template <class Ops, class V>
ALWAYS_INLINE bool cap_magnitude(V& spring, Real cap, Real k, Real& dissipated) {
  return cap_spring<Ops>(spring, spring, cap, k, dissipated);
}

}  // namespace cpp_dem
