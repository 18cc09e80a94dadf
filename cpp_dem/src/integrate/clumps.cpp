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

/// A quaternion as four scalars (w, x, y, z). With V3 and R3 below, the rotation chain's
/// types: see the clump pass for why not Eigen's.
struct Q4 {
  Real w, x, y, z;
};

__attribute__((always_inline)) inline Q4 q4(const Quat& q) { return {q.w(), q.x(), q.y(), q.z()}; }

/// A 3-vector as three scalars (see Q4).
struct V3 {
  Real x, y, z;
  V3 operator*(const V3& o) const { return {x * o.x, y * o.y, z * o.z}; }
};
__attribute__((always_inline)) inline V3 v3(const Vec3& v) { return {v[0], v[1], v[2]}; }
__attribute__((always_inline)) inline Vec3 vec(const V3& v) { return Vec3(v.x, v.y, v.z); }
/// a + h b.
__attribute__((always_inline)) inline V3 axpy(const V3& a, Real h, const V3& b) {
  return {a.x + h * b.x, a.y + h * b.y, a.z + h * b.z};
}

/// q + h dq/dt, where dq/dt = r (0, wb) / 2 is the rate of the orientation r under the
/// body-frame spin wb (rad/s) and h is in s.
__attribute__((always_inline)) inline Q4 advance(const Q4& q, Real h, const Q4& r, const V3& wb) {
  const Real bx = wb.x, by = wb.y, bz = wb.z, k = 0.5 * h;
  return {q.w + k * (-r.x * bx - r.y * by - r.z * bz), q.x + k * (r.w * bx + r.y * bz - r.z * by),
          q.y + k * (r.w * by - r.x * bz + r.z * bx), q.z + k * (r.w * bz + r.x * by - r.y * bx)};
}

/// A rotation matrix as nine scalars: of a unit q (Eigen's toRotationMatrix), or a copy.
struct R3 {
  Real xx, xy, xz, yx, yy, yz, zx, zy, zz;
  explicit R3(const Q4& q) {
    const Real tx = 2 * q.x, ty = 2 * q.y, tz = 2 * q.z;
    const Real twx = tx * q.w, twy = ty * q.w, twz = tz * q.w;
    const Real txx = tx * q.x, txy = ty * q.x, txz = tz * q.x;
    const Real tyy = ty * q.y, tyz = tz * q.y, tzz = tz * q.z;
    xx = 1 - (tyy + tzz), xy = txy - twz, xz = txz + twy;
    yx = txy + twz, yy = 1 - (txx + tzz), yz = tyz - twx;
    zx = txz - twy, zy = tyz + twx, zz = 1 - (txx + tyy);
  }
  explicit R3(const Mat3& m)
      : xx(m(0, 0)), xy(m(0, 1)), xz(m(0, 2)), yx(m(1, 0)), yy(m(1, 1)), yz(m(1, 2)),
        zx(m(2, 0)), zy(m(2, 1)), zz(m(2, 2)) {}
  V3 operator*(const V3& v) const {
    return {xx * v.x + xy * v.y + xz * v.z, yx * v.x + yy * v.y + yz * v.z,
            zx * v.x + zy * v.y + zz * v.z};
  }
  /// R^T v.
  V3 back(const V3& v) const {
    return {xx * v.x + yx * v.y + zx * v.z, xy * v.x + yy * v.y + zy * v.z,
            xz * v.x + yz * v.y + zz * v.z};
  }
};

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
__attribute__((always_inline)) inline void normalize_near_unit(Q4& q) {
  const Real n2 = q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z, e = n2 - 1.0;
  const Real k = std::abs(e) < 1e-6 ? 1.0 - e * (0.5 - 0.375 * e) : 1.0 / std::sqrt(n2);
  q = {q.w * k, q.x * k, q.y * k, q.z * k};
}

/// Yade's first-order local damping of one torque component t about a spin component w:
/// t (1 - lambda sign(t w)).
__attribute__((always_inline)) inline Real damped_torque(Real t, Real w, Real lambda) {
  const Real p = t * w;
  return t * (1.0 - lambda * (p > 0 ? 1.0 : p < 0 ? -1.0 : 0.0));
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
  // The members' largest displacement since the build (displacement_since_build): of those
  // whose radius has not grown, the largest squared distance, rooted once at the end (the
  // square root is monotonic and correctly rounded, so this is the largest of their roots,
  // to the bit); of the others, the distance plus the growth, as it was.
  Real worst = 0, worst_sq = 0;
#pragma omp parallel for schedule(static) reduction(min : err) reduction(max : worst) \
    reduction(max : worst_sq) if (nc > kParallelMin)
  for (int c = 0; c < nc; ++c) {
    const int e0 = clumps_.member_off[c], e1 = clumps_.member_off[c + 1];
    const Mat3& rot_old = clumps_.rot[c];  // of ori[c]; place_members (last) renews it
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
    const Vec3& fe = clumps_.ext_force_of(c);
    const Vec3& te = clumps_.ext_torque_of(c);
    if (fe.squaredNorm() > 0) f += fe;
    if (te.squaredNorm() > 0) t += te;
    clumps_.force[c] = f;
    clumps_.torque[c] = t;
    if (!f.allFinite() || !t.allFinite()) {
      err = std::min(err, static_cast<long>(c));
      continue;
    }
    const std::uint8_t dofs = clumps_.blocked[c];
    // (Density scaling: the inertia times the clump's factor; the members' weights above
    // are the true ones.)
    const Real ds = clumps_.inertia_scale[c];
    const Real m = ds == 1.0 ? clumps_.mass[c] : clumps_.mass[c] * ds;
    const Vec3 inertia = ds == 1.0 ? clumps_.inertia[c] : Vec3(clumps_.inertia[c] * ds);
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
      // The chain of dependent operations below is written on scalars (V3, Q4, R3). Eigen's
      // small vectors and quaternions were built in memory one coefficient at a time and
      // read back as pairs: a failed store-to-load forwarding at each link. On scalars the
      // clump pass takes about 30 % less time (perf, 2000 three-member clumps); the written-out
      // quaternion product rounds differently from Eigen's (2.6e-14 m after 2000 steps).
      V3 tq = v3(t);
      if (lambda > 0) tq = {damped_torque(t[0], w_old[0], lambda),
                            damped_torque(t[1], w_old[1], lambda),
                            damped_torque(t[2], w_old[2], lambda)};
      if (dofs & DOF_ROT)  // fixed below
        tq = {dofs & DOF_RX ? 0.0 : tq.x, dofs & DOF_RY ? 0.0 : tq.y,
              dofs & DOF_RZ ? 0.0 : tq.z};
      const V3 l_old = v3(clumps_.angmom[c]);
      const Q4 q = q4(clumps_.ori[c]);
      const R3 r_old(rot_old);
      const V3 l_now = axpy(l_old, 0.5 * dt, tq);  // at the start of the step
      // (1 / I once, off the chain; products on it.)
      const V3 inv_i = {1.0 / inertia[0], 1.0 / inertia[1], 1.0 / inertia[2]};
      const V3 wb_now = r_old.back(l_now) * inv_i;
      Q4 q_half = advance(q, 0.5 * dt, q, wb_now);
      const V3 l_new = axpy(l_old, dt, tq);
      Quat ori_new;
      if (!yade_rotation) {
        // Fincham: the half-step spin in the half step's frame.
        normalize_near_unit(q_half);
        const R3 r_half(q_half);
        const V3 wb_half = r_half.back(l_new) * inv_i;
        Q4 qn = advance(q, dt, q_half, wb_half);
        normalize_near_unit(qn);
        ori_new = Quat(qn.w, qn.x, qn.y, qn.z);
        // The spin at the half step, in the half step's frame (the new frame would tilt it
        // by w dt / 2: an error of first order in the energy).
        w = vec(r_half * wb_half);
      } else {
        // Yade (2023): the half-step spin in the start-of-step frame, q_half not
        // normalised; the global spin from the end-of-step frame before normalising.
        const V3 wb_half = r_old.back(l_new) * inv_i;
        const Q4 qn = advance(q, dt, q_half, wb_half);
        ori_new = Quat(qn.w, qn.x, qn.y, qn.z);
        w = ori_new * vec(wb_half);
        ori_new.normalize();
      }
      Vec3 L = vec(l_new);
      clumps_.ori[c] = ori_new;
      if (dofs & DOF_ROT) {
        const Mat3 rot_new = ori_new.toRotationMatrix();
        // Blocked rotations about global axes keep their spin; L follows the spin.
        w = Vec3(dofs & DOF_RX ? w_old[0] : w[0], dofs & DOF_RY ? w_old[1] : w[1],
                 dofs & DOF_RZ ? w_old[2] : w[2]);
        L = rot_new * inertia.cwiseProduct(rot_new.transpose() * w);
      }
      clumps_.angmom[c] = L;
      clumps_.angvel[c] = w;
      if (energy) {
        const Vec3 w_now = rot_old * vec(wb_now);
        ke_rot = 0.5 * vec(l_now).dot(w_now);
        if (lambda > 0) dissip += -(vec(tq) - t).dot(w_now) * dt;
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
    // (Each member's displacement since the neighbour lists were built is taken as it is
    // placed, from the position in registers rather than read back from the store.)
    cpp_dem::place_members(clumps_, bodies_, c, [&](int s, const Vec3& x) {
      const Real grown = radius_growth_since_build(s);
      if (grown == 0) worst_sq = std::max(worst_sq, (x - pos_at_build_[s]).squaredNorm());
      else worst = std::max(worst, displacement_since_build(s, x));
    });
  }
  worst = std::max(worst, std::sqrt(worst_sq));
  err_clump = err;
  if (err == std::numeric_limits<long>::max() && disp_valid_) max_disp_ = std::max(max_disp_, worst);
}

}  // namespace cpp_dem
