// Terms of the leapfrog shared by the integration pass (integrate.cpp) and the clump pass
// (clumps.cpp): Cundall local damping and the orientation update. Included only by those two
// units (both compiled as CPP_DEM_HOT), so a sphere and a one-sphere clump get the same
// arithmetic.
#pragma once

#include <cmath>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {
namespace integrate_terms {
/// Steps between two renormalisations of the orientation quaternions (rotate_orientation).
constexpr long kRenormalizePeriod = 64;

/// Cundall local damping of one component of an acceleration (Yade's 2nd-order form).
__attribute__((always_inline)) inline Real damp_component(Real a, Real v, Real dt, Real lambda) {
  const Real vm = v + 0.5 * dt * a;
  // sign(a vm) without a branch: in a quasi-static packing the signs are noise, and a
  // mispredicted branch per component cost a fifth of the integration (perf, N = 1e3).
  const Real p = a * vm;
  const Real s = p != 0 ? std::copysign(1.0, p) : 0.0;  // a mask, not a jump
  return a * (1.0 - lambda * s);
}

/// Turns q by the rotation |w| dt about w (w in rad/s, dt in s): q <- (cos h, sin h w/|w|) q
/// with h = |w| dt / 2. For the small angles of a stable step, series in h^2 replace sin/cos
/// and the division by |w| (truncation < h^6/720: below 2e-11 for h < 0.05), so the step
/// needs no square root and no division. The rotation is a unit quaternion to round-off, so
/// |q| drifts by about one ulp per step; with `renormalize` (every kRenormalizePeriod steps)
/// one Newton step for 1/|q| brings it back (|q|^2 = 1 + e, the step leaves O(e^2)).
/// The rotation quaternion r and the Hamilton product r q of rotate_orientation, written
/// for one body's doubles: q = (x, y, z, w) in Eigen's storage order, w = spin (rad/s).
/// `series`: h^2 < 0.0025 (the caller checked), so no sin/cos.
template <bool kRenormalize>
__attribute__((always_inline)) inline void rotate_quat(Real* q, Real wx, Real wy, Real wz,
                                                        Real dt, Real w2, bool series) {
  const Real h2 = 0.25 * dt * dt * w2;
  Real ch, sh_over_wn;
  if (series) {
    ch = 1 - h2 * (0.5 - h2 * (1.0 / 24));
    sh_over_wn = 0.5 * dt * (1 - h2 * (1.0 / 6 - h2 * (1.0 / 120)));
  } else {
    const Real wn = std::sqrt(w2);
    const Real h = 0.5 * wn * dt;
    ch = std::cos(h);
    sh_over_wn = std::sin(h) / wn;
  }
  const Real rw = ch, rx = sh_over_wn * wx, ry = sh_over_wn * wy, rz = sh_over_wn * wz;
  const Real qx = q[0], qy = q[1], qz = q[2], qw = q[3];
  // Hamilton product r q.
  Real nw = rw * qw - rx * qx - ry * qy - rz * qz;
  Real nx = rw * qx + rx * qw + ry * qz - rz * qy;
  Real ny = rw * qy - rx * qz + ry * qw + rz * qx;
  Real nz = rw * qz + rx * qy - ry * qx + rz * qw;
  if (kRenormalize) {
    const Real k = 1.5 - 0.5 * (nw * nw + nx * nx + ny * ny + nz * nz);
    nw *= k;
    nx *= k;
    ny *= k;
    nz *= k;
  }
  q[0] = nx;
  q[1] = ny;
  q[2] = nz;
  q[3] = nw;
}

/// h^2 = (|w| dt / 2)^2 below which rotate_quat uses its series.
constexpr Real kSeriesH2 = 0.0025;

__attribute__((always_inline)) inline void rotate_orientation(Quat& q, const Vec3& w, Real dt, bool renormalize) {
  const Real w2 = w.squaredNorm();
  const bool series = 0.25 * dt * dt * w2 < kSeriesH2;
  if (renormalize) rotate_quat<true>(q.coeffs().data(), w[0], w[1], w[2], dt, w2, series);
  else rotate_quat<false>(q.coeffs().data(), w[0], w[1], w[2], dt, w2, series);
}

/// rotate_orientation for `count` bodies: q, 4 doubles per body (x, y, z, w); w, 3 per body.
/// Every |w| dt / 2 must be in the series range (the caller checked); the loop vectorises
/// across bodies.
template <bool kRenormalize>
inline void rotate_orientations(Real* __restrict q, const Real* __restrict w, long count,
                                Real dt) {
#pragma omp simd
  for (long b = 0; b < count; ++b) {
    const Real wx = w[3 * b], wy = w[3 * b + 1], wz = w[3 * b + 2];
    const Real w2 = wx * wx + wy * wy + wz * wz;
    rotate_quat<kRenormalize>(q + 4 * b, wx, wy, wz, dt, w2, true);
  }
}

/// The leapfrog velocity update of the three components of v_old (m/s or rad/s) under the
/// force or torque f (N or N m) on a mass or moment m (inv_m = 1 / m), with Cundall local
/// damping lambda; components whose bit (first_dof << a) is in `dofs` are blocked (they keep
/// their velocity, and the constraint's work -f v dt is booked). With kEnergy, the damping's
/// dissipation and the work of the imposed part `ext` of f are booked too (J). The one form
/// of the update for the energy pass and the clump pass.
template <bool kEnergy>
__attribute__((always_inline)) inline Vec3 leapfrog_velocity(
    const Vec3& f, const Vec3& ext, Real m, Real inv_m, std::uint8_t dofs, int first_dof,
    const Vec3& v_old, Real dt, Real lambda, Real& dissip, Real& work) {
  Vec3 v = v_old;
  for (int a = 0; a < 3; ++a) {
    if (dofs & (first_dof << a)) {
      work += -f[a] * v_old[a] * dt;
      continue;
    }
    Real acc = f[a] * inv_m;
    if (lambda > 0) {
      const Real damped = damp_component(acc, v_old[a], dt, lambda);
      if (kEnergy) dissip += -(damped - acc) * m * (v_old[a] + 0.5 * dt * damped) * dt;
      acc = damped;
    }
    v[a] = v_old[a] + acc * dt;
    if (kEnergy) work += ext[a] * 0.5 * (v_old[a] + v[a]) * dt;
  }
  return v;
}

}  // namespace integrate_terms
}  // namespace cpp_dem
