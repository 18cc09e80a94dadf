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

/// The short kernels' common part: the tangential spring of a contact without dashpots or
/// rolling resistance, given its normal force fn (N) and its tangent shear stiffness ks
/// (N/m), on plain values, for the hot loops (either vector form). fs: the stored shear force
/// on side 2 (N), updated; n_old: the previous normal (zero for a new contact); n: the unit
/// normal from side 1 to side 2; rel_vel: velocity of side 2 minus side 1 at the contact point
/// (m/s); angvel_sum: the sum of the two spins (rad/s); tan_phi (-); dt (s). Slip energy (J)
/// is added to dissip_friction. The composed law's lines (apply_composed_law) with those
/// parts off, in its order: the same bits.
template <class Ops, class V>
ALWAYS_INLINE void frictional_spring(V& fs, const V& n_old, const V& n, Real fn,
                                     const V& rel_vel, const V& angvel_sum, Real ks,
                                     Real tan_phi, Real dt, Real& dissip_friction) {
  const Real vn = Ops::dot(rel_vel, n);
  const V vt = rel_vel - vn * n;
  if (Ops::dot(n_old, n_old) > 0) {
    V axis, twist;
    frame_turn<Ops>(n_old, n, angvel_sum, dt, axis, twist);
    turn_into_frame<Ops>(fs, axis, twist, n);
  }
  fs -= (ks * dt) * vt;  // 000 eq (2)
  cap_magnitude<Ops>(fs, tan_phi * (fn > 0 ? fn : 0.0), ks, dissip_friction);  // 000 eq (3)
}

}  // namespace cpp_dem
