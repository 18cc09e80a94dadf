// Shape pair sphere–sphere: the contact frame from the two centres, in either vector form of
// core/simd.hpp (the pair pass), and the full ContactGeometry record (the composed law).
#pragma once

#include "cpp_dem/core/simd.hpp"
#include "cpp_dem/geometry/contact_geometry.hpp"

namespace cpp_dem {

/// Spheres i and j (radii ri, rj, m) whose centres are d = x_j - x_i apart (|d| = dist > 0 or
/// 0, m) and overlap by `overlap` (m): the unit normal n from i to j, the branch lengths
/// li = ri - overlap/2 and lj (the contact point sits in the middle of the overlap, 000 eq 6;
/// branch vectors li n and -lj n), and the velocity of j relative to i at the contact point,
/// v_j + w_j x (-lj n) - (v_i + w_i x li n) (m/s), with one cross product.
/// kYadeShear (ShearKinematics::Yade): instead the relative velocity of Yade's ScGeom with
/// avoidGranularRatcheting, alpha (v_j - v_i) - (rj w_j + ri w_i) x n with
/// alpha = (ri + rj) / (ri + rj - overlap): the centres' relative velocity is scaled up by
/// the ratio of the undeformed to the present centre distance and the spins act on the full
/// radii, so a closed cycle of normal approach and rotation leaves no shear (no ratcheting).
/// The branch lengths li, lj (for the moments) are the same in both.
template <class Ops, bool kYadeShear = false, class V>
ALWAYS_INLINE void sphere_sphere_frame(const V& d, Real dist, Real overlap, Real ri, Real rj,
                                       const V& vi, const V& vj, const V& wi, const V& wj, V& n,
                                       Real& li, Real& lj, V& rel_vel) {
  n = dist > 0 ? V(d * (1.0 / dist)) : Ops::unit_z();
  li = ri - 0.5 * overlap;
  lj = rj - 0.5 * overlap;
  if constexpr (kYadeShear) {
    const Real rsum = ri + rj;
    const Real alpha = rsum / (rsum - overlap);  // rsum - overlap is the distance, > 0 here
    rel_vel = alpha * (vj - vi) - Ops::cross(rj * wj + ri * wi, n);
  } else {
    rel_vel = (vj - vi) - Ops::cross(lj * wj + li * wi, n);
  }
}

/// The ContactGeometry record of a sphere–sphere contact from its frame (sphere_sphere_frame)
/// and the sum and difference w_j - w_i of the spins (rad/s). Side 1 is i, side 2 is j.
inline ContactGeometry sphere_sphere_geometry(const Vec3& n, Real overlap, Real li, Real lj,
                                              const Vec3& rel_vel, const Vec3& angvel_sum,
                                              const Vec3& rel_angvel) {
  ContactGeometry g;
  g.normal = n;
  g.overlap = overlap;
  g.branch1 = li * n;
  g.branch2 = -lj * n;
  g.rel_vel = rel_vel;
  g.angvel_sum = angvel_sum;
  g.rel_angvel = rel_angvel;
  return g;
}

}  // namespace cpp_dem
