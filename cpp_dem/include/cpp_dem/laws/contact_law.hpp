// The composed contact law: elastic part (from the registry) + dashpots + tangential spring in
// the turning frame with the Coulomb cap + rolling resistance, on the plain records
// ContactGeometry (this step) and ContactState (the contact's history).
//
// Data flow through one contact in one step (shared/DESIGN.md):
//   shape-pair geometry  ->  ContactGeometry  ->  apply_law(phys, state)  ->  LawOutput
// The law never reads global state: everything it needs is in these plain records.
#pragma once

#include "cpp_dem/geometry/contact_geometry.hpp"
#include "cpp_dem/laws/damping.hpp"
#include "cpp_dem/laws/registry.hpp"
#include "cpp_dem/laws/rolling.hpp"
#include "cpp_dem/laws/tangential.hpp"

namespace cpp_dem {

/// History a contact carries from step to step.
struct ContactState {
  Vec3 fs = Vec3::Zero();       ///< elastic shear force on side 2, N
  Vec3 mr = Vec3::Zero();       ///< rolling moment on side 2, N m
  Vec3 normal = Vec3::Zero();   ///< normal at the previous step (zero: new contact)
  Real overlap = 0;             ///< overlap at the last evaluation, m
  Real fn = 0;                  ///< total normal force (elastic + viscous) on side 2, N
  Real dissip_friction = 0;     ///< cumulative Coulomb + rolling slip dissipation, J
  Real dissip_viscous = 0;      ///< cumulative viscous dissipation, J

  /// The contact opened: forget the springs' history (dissipation totals are kept).
  void clear_history() {
    fs.setZero();
    mr.setZero();
    normal.setZero();
    overlap = 0;
    fn = 0;
  }
};

/// What the law returns: the force and extra moment on side 2 (side 1 gets the opposite).
struct LawOutput {
  Vec3 force2;    ///< total contact force on side 2, N
  Vec3 moment2;   ///< moment on side 2 not due to force2 (rolling resistance), N m
};

/// Tangent stiffnesses of the contact at its current overlap, N/m (time step, servos).
inline void tangent_stiffness(const ContactPhys& p, Real overlap, Real& kn, Real& ks) {
  with_elastic_part(p.model, [&](auto part) { decltype(part)::stiffness(p, overlap, kn, ks); });
}

/// Elastic energy stored in the contact, J (normal + shear + rolling springs).
inline Real contact_elastic_energy(const ContactPhys& p, const ContactState& s) {
  if (s.overlap <= 0) return 0;
  Real kn, ks;
  tangent_stiffness(p, s.overlap, kn, ks);
  Real e = with_elastic_part(
      p.model, [&](auto part) { return decltype(part)::normal_energy(p, s.overlap); });
  if (ks > 0) e += 0.5 * s.fs.squaredNorm() / ks;
  if (p.kr > 0) e += 0.5 * s.mr.squaredNorm() / p.kr;
  return e;
}

/// The composed law with elastic part `Elastic`: normal force (000 eq 1 or Hertz), optional
/// normal dashpot, the stored shear force turned with the contact frame and incremented
/// (000 eq 2), optional shear dashpot, Coulomb cap on the total (000 eq 3), optional rolling
/// resistance. dt in s.
template <class Elastic>
inline LawOutput apply_composed_law(const ContactPhys& p, const ContactGeometry& g, Real dt,
                                    ContactState& s) {
  const Vec3& n = g.normal;
  Real kn, ks;
  Elastic::stiffness(p, g.overlap, kn, ks);
  const Real fn_el = Elastic::normal_force(p, g.overlap);
  const Real vn = g.rel_vel.dot(n);
  const Vec3 vt = g.rel_vel - vn * n;
  Real fn = fn_el;
  if (p.beta_n > 0) {
    const Real fv = -viscous_coefficient(p.beta_n, p.mass_eff, kn) * vn;
    fn += fv;
    s.dissip_viscous += -fv * vn * dt;
  }
  if (s.normal.squaredNorm() > 0) {
    Vec3 axis, twist;
    frame_turn<NarrowOps>(s.normal, n, g.angvel_sum, dt, axis, twist);
    turn_into_frame<NarrowOps>(s.fs, axis, twist, n);
    if (p.kr > 0) turn_into_frame<NarrowOps>(s.mr, axis, twist, n);
  }
  s.fs -= ks * dt * vt;
  Vec3 fvs = Vec3::Zero();
  if (p.beta_s > 0) fvs = -viscous_coefficient(p.beta_s, p.mass_eff, ks) * vt;
  const Real cap = p.tan_phi * (fn > 0 ? fn : 0.0);
  if (cap_spring<NarrowOps>(s.fs, p.beta_s > 0 ? Vec3(s.fs + fvs) : s.fs, cap, ks,
                            s.dissip_friction)) {
    fvs.setZero();  // slip: the capped total is all in the spring
  } else if (p.beta_s > 0) {
    s.dissip_viscous += -fvs.dot(vt) * dt;
  }
  LawOutput out;
  out.force2 = fn * n + s.fs + fvs;
  out.moment2.setZero();
  if (p.kr > 0) {
    rolling_resistance(s.mr, g.rel_angvel, n, p.kr, p.rolling_cap, fn, dt, s.dissip_friction);
    out.moment2 = s.mr;
  }
  s.normal = n;
  s.overlap = g.overlap;
  s.fn = fn;
  return out;
}

/// The composed law of the contact's registry row (apply_composed_law).
inline LawOutput apply_law(const ContactPhys& p, const ContactGeometry& g, Real dt,
                           ContactState& s) {
  return with_elastic_part(p.model, [&](auto part) {
    return apply_composed_law<decltype(part)>(p, g, dt, s);
  });
}

}  // namespace cpp_dem
