// The clump pass: runs after the integration pass, only in scenes with clumps. The members'
// resultant forces (the integration pass summed their contacts, imposed forces and the weight
// of their mass share; a block of members only gets nothing else there, a member in a mixed
// block is moved as a fully blocked body) go to their clump; the clump moves by leapfrog in
// its principal axes; the members take their clump's state, which overwrites any move.
//
// Rotation: the leapfrog of Fincham (1992, "Leapfrog rotational algorithms", Mol. Simul. 8)
// for the angular momentum L and a quaternion, as Yade's NewtonIntegrator applies it to
// aspherical bodies: L at the half step, the orientation advanced through a predicted
// half-step orientation. Local damping of the torque is Yade's first-order form
// (T_a (1 - lambda sign(T_a w_a))), of the force the same second-order form as for spheres.
// ClumpRotation::Yade takes Yade 2023's variant instead (NewtonIntegrator::
// leapfrogAsphericalRotate: the half-step body spin from the start-of-step frame, the global
// spin from the end-of-step frame): first order in the energy of free rotation (1.9e-3 of the
// kinetic energy after 2 s at 20 rad/s and dt = 5e-5 s, against 3.7e-10 with Fincham's), for
// comparisons with Yade on the same input.
// A clump with three equal principal moments takes the spheres' update (Euler's equations
// have no gyroscopic term then), so a one-sphere clump moves bitwise as the sphere.
#include <algorithm>
#include <cmath>
#include <limits>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/scene.hpp"
#include "terms.hpp"

namespace cpp_dem {

namespace {
using namespace integrate_terms;

/// dq/dt of orientation q for the body-frame spin wb: q (0, wb) / 2.
inline Quat quat_rate(const Quat& q, const Vec3& wb) {
  const Quat p = q * Quat(0, wb[0], wb[1], wb[2]);
  return Quat(0.5 * p.w(), 0.5 * p.x(), 0.5 * p.y(), 0.5 * p.z());
}

/// m g, rounded on its own: the integration pass rounded the same product into the member's
/// force, so force - weight(m, g) is exactly the contact part (a fused multiply-subtract would
/// leave the product's rounding error as a spurious force). The empty asm makes each product
/// a value the compiler must produce as it is, so it cannot fuse it, yet the function inlines.
__attribute__((always_inline)) inline Vec3 weight(Real m, const Vec3& g) {
  Real x = m * g[0], y = m * g[1], z = m * g[2];
  asm("" : "+x"(x), "+x"(y), "+x"(z));
  return Vec3(x, y, z);
}

/// q / |q| for a q near unit length, as the leapfrog's half and full steps give (|q|^2 = 1 + e
/// with e of order (w dt)^2): 1/sqrt(1 + e) by its series to e^2 (error 5 e^3 / 16 < 4e-19
/// for |e| < 1e-6), with no square root and no division on the step's chain of dependent
/// operations; farther from unit length the exact normalisation.
__attribute__((always_inline)) inline void normalize_near_unit(Quat& q) {
  const Real e = q.squaredNorm() - 1.0;
  if (std::abs(e) < 1e-6) q.coeffs() *= 1.0 - e * (0.5 - 0.375 * e);
  else q.normalize();
}

inline Quat quat_axpy(const Quat& q, Real h, const Quat& d) {
  return Quat(q.w() + h * d.w(), q.x() + h * d.x(), q.y() + h * d.y(), q.z() + h * d.z());
}
}  // namespace

void Scene::integrate_clumps(long& err_clump) { integrate_clumps_hot(err_clump); }

void Scene::integrate_clumps_hot(long& err_clump) {
  const int nc = clumps_.size();
  const Real dt = dt_;
  const Real lambda = local_damping_;
  const bool energy = track_energy_;
  const bool renormalize = step_ % kRenormalizePeriod == 0;
  const bool yade_rotation = clump_rotation_ == ClumpRotation::Yade;
  long err = std::numeric_limits<long>::max();
  Real worst = 0;
#pragma omp parallel for schedule(static) reduction(min : err) reduction(max : worst) \
    if (nc > kParallelMin)
  for (int c = 0; c < nc; ++c) {
    const int e0 = clumps_.member_off[c], e1 = clumps_.member_off[c + 1];
    const Mat3 rot_old = clumps_.rot[c];  // of ori[c], kept by place_members
    // Resultants about the centre of mass, in member order. The members' forces include the
    // weights of their mass shares, which sum to the clump's weight; the weight acts at the
    // centre of mass, so a member's lever arm takes its force without its weight (exactly
    // zero torque in free flight, as the clump's own weight gives).
    // (The sums start from the first member, not from zero: a one-sphere clump's force is
    // then its member's, bitwise, signed zeros included.)
    Vec3 f, t;
    for (int e = e0; e < e1; ++e) {
      const int s = clumps_.member[e];
      const Vec3 fs = bodies_.force[s];
      const Vec3 r = rot_old * clumps_.member_local[e];
      const Vec3 ts = bodies_.torque[s] + r.cross(fs - weight(bodies_.mass[s], gravity_));
      if (e == e0) {
        f = fs;
        t = ts;
      } else {
        f += fs;
        t += ts;
      }
    }
    const Vec3& fe = clumps_.ext_force[c];
    const Vec3& te = clumps_.ext_torque[c];
    if (fe.squaredNorm() > 0) f += fe;
    if (te.squaredNorm() > 0) t += te;
    clumps_.force[c] = f;
    clumps_.torque[c] = t;
    if (!f.allFinite() || !t.allFinite()) {
      err = std::min(err, static_cast<long>(c));
      continue;
    }
    const std::uint8_t dofs = clumps_.blocked[c];
    const Real m = clumps_.mass[c];
    const Vec3& inertia = clumps_.inertia[c];
    // Translation: the spheres' leapfrog.
    const Real inv_m = 1.0 / m;
    const Vec3 v_old = clumps_.vel[c];
    Real dissip = 0, work = 0;
    const Vec3 v = energy ? leapfrog_velocity<true>(f, fe, m, inv_m, dofs, DOF_X, v_old, dt, lambda,
                                                    dissip, work)
                          : leapfrog_velocity<false>(f, fe, m, inv_m, dofs, DOF_X, v_old, dt,
                                                     lambda, dissip, work);
    clumps_.vel[c] = v;
    clumps_.pos[c] += v * dt;
    // Rotation.
    const Vec3 w_old = clumps_.angvel[c];
    Vec3 w = w_old;
    Real ke_rot = 0;
    if (inertia[0] == inertia[1] && inertia[1] == inertia[2]) {
      const Real inv_i = 1.0 / inertia[0];
      w = energy ? leapfrog_velocity<true>(t, te, inertia[0], inv_i, dofs, DOF_RX, w_old, dt,
                                           lambda, dissip, work)
                 : leapfrog_velocity<false>(t, te, inertia[0], inv_i, dofs, DOF_RX, w_old, dt,
                                            lambda, dissip, work);
      clumps_.angvel[c] = w;
      clumps_.angmom[c] = inertia[0] * w;
      // (The integration pass turns a block of spheres in a vectorised form whose last bits
      // may differ from this one's: a one-sphere clump's orientation, which no force
      // depends on, equals the sphere's to round-off; everything else is bitwise.)
      rotate_orientation(clumps_.ori[c], w, dt, renormalize);
      if (energy) ke_rot = 0.5 * inertia[0] * (0.5 * (w_old + w)).squaredNorm();
    } else {
      Vec3 tq = t;
      if (lambda > 0) {
        for (int a = 0; a < 3; ++a) {
          const Real p = tq[a] * w_old[a];
          tq[a] *= 1.0 - lambda * (p > 0 ? 1.0 : p < 0 ? -1.0 : 0.0);
        }
      }
      for (int a = 0; a < 3; ++a)
        if (dofs & (DOF_RX << a)) tq[a] = 0;  // fixed below
      Vec3& L = clumps_.angmom[c];
      const Quat q = clumps_.ori[c];
      const Vec3 l_now = L + 0.5 * dt * tq;  // at the start of the step
      // (1 / I once, off the chain of dependent operations; products on it.)
      const Vec3 inv_inertia = inertia.cwiseInverse();
      const Vec3 wb_now = (rot_old.transpose() * l_now).cwiseProduct(inv_inertia);
      Quat q_half = quat_axpy(q, 0.5 * dt, quat_rate(q, wb_now));
      L += dt * tq;
      Vec3 wb_half;
      Mat3 rot_half;
      if (!yade_rotation) {
        // Fincham: the half-step spin in the half step's frame.
        normalize_near_unit(q_half);
        rot_half = q_half.toRotationMatrix();
        wb_half = (rot_half.transpose() * L).cwiseProduct(inv_inertia);
      } else {
        // Yade (2023): in the start-of-step frame, q_half not normalised.
        wb_half = (rot_old.transpose() * L).cwiseProduct(inv_inertia);
      }
      Quat q_new = quat_axpy(q, dt, quat_rate(q_half, wb_half));
      if (!yade_rotation) {
        normalize_near_unit(q_new);
        // The spin at the half step, in the half step's frame (the new frame would tilt it
        // by w dt / 2: an error of first order in the energy).
        w = rot_half * wb_half;
      } else {
        w = q_new * wb_half;  // the end-of-step frame, before normalising (as Yade)
        q_new.normalize();
      }
      clumps_.ori[c] = q_new;
      if (dofs & DOF_ROT) {
        const Mat3 rot_new = q_new.toRotationMatrix();
        // Blocked rotations about global axes keep their spin; L follows the spin.
        for (int a = 0; a < 3; ++a)
          if (dofs & (DOF_RX << a)) w[a] = w_old[a];
        L = rot_new * inertia.cwiseProduct(rot_new.transpose() * w);
      }
      clumps_.angvel[c] = w;
      if (energy) {
        const Vec3 w_now = rot_old * wb_now;
        ke_rot = 0.5 * l_now.dot(w_now);
        if (lambda > 0) dissip += -(tq - t).dot(w_now) * dt;
        work += te.dot(w_now) * dt;
        for (int a = 0; a < 3; ++a)
          if (dofs & (DOF_RX << a)) work += -t[a] * w_old[a] * dt;
      }
    }
    if (energy) {
      clumps_.ke[c] = 0.5 * m * (0.5 * (v_old + v)).squaredNorm() + ke_rot;
      clumps_.damp_dissip[c] += dissip;
      clumps_.ext_work[c] += work;
    }
    if (!clumps_.pos[c].allFinite() || !v.allFinite() || !w.allFinite()) {
      err = std::min(err, static_cast<long>(c));
      continue;
    }
    cpp_dem::place_members(clumps_, bodies_, c);
    for (int e = e0; e < e1; ++e)
      worst = std::max(worst, displacement_since_build(clumps_.member[e]));
  }
  err_clump = err;
  if (err == std::numeric_limits<long>::max() && disp_valid_) max_disp_ = std::max(max_disp_, worst);
}

}  // namespace cpp_dem
