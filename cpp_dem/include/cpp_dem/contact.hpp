// Contact geometry records and the composed contact law.
//
// Data flow through one contact in one step (shared/DESIGN.md):
//   shape-pair geometry  ->  ContactGeometry  ->  apply_law(phys, state)  ->  LawOutput
// The law never reads global state: everything it needs is in these plain records.
#pragma once

#include "cpp_dem/law.hpp"
#include "cpp_dem/material.hpp"

namespace cpp_dem {

/// Geometry of one contact, filled by a shape-pair function. Side 1 and side 2; the normal
/// points from side 1 to side 2.
struct ContactGeometry {
  Vec3 normal;      ///< unit normal, from side 1 to side 2
  Real overlap;     ///< penetration depth, m (> 0 in contact)
  Vec3 branch1;     ///< contact point minus centre of side 1, m
  Vec3 branch2;     ///< contact point minus centre of side 2, m
  Vec3 rel_vel;     ///< velocity of side 2 minus side 1 at the contact point, m/s
  Vec3 angvel_sum;  ///< omega1 + omega2, rad/s (for the twist of the shear frame)
  Vec3 rel_angvel;  ///< omega2 - omega1, rad/s (for rolling resistance)
};

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

/// Tangent stiffnesses of the contact at its current overlap, N/m.
inline void tangent_stiffness(const ContactPhys& p, Real overlap, Real& kn, Real& ks) {
  if (p.model == ContactModel::Linear) {
    kn = p.kn;
    ks = p.ks;
  } else {
    kn = hertz_normal_stiffness(p.kn, overlap);
    ks = mindlin_shear_stiffness(p.ks, overlap);
  }
}

/// Elastic energy stored in the contact, J (normal + shear + rolling springs).
inline Real contact_elastic_energy(const ContactPhys& p, const ContactState& s) {
  if (s.overlap <= 0) return 0;
  Real kn, ks;
  tangent_stiffness(p, s.overlap, kn, ks);
  Real e = normal_elastic_energy(p.model, p.kn, s.overlap);
  if (ks > 0) e += 0.5 * s.fs.squaredNorm() / ks;
  if (p.kr > 0) e += 0.5 * s.mr.squaredNorm() / p.kr;
  return e;
}

/// The composed law: normal part (linear or Hertz), tangential part (incremental linear or
/// Mindlin) with rotation of the stored shear force with the contact frame, optional viscous
/// damping, Coulomb cap (000 eqs 1–3), optional rolling resistance. dt in s.
inline LawOutput apply_law(const ContactPhys& p, const ContactGeometry& g, Real dt,
                           ContactState& s) {
  const Vec3& n = g.normal;
  Real kn, ks;
  tangent_stiffness(p, g.overlap, kn, ks);
  // Normal elastic force, 000 eq (1) or Hertz.
  const Real fn_el = p.model == ContactModel::Linear ? linear_normal_force(p.kn, g.overlap)
                                                     : hertz_normal_force(p.kn, g.overlap);
  const Real vn = g.rel_vel.dot(n);
  const Vec3 vt = g.rel_vel - vn * n;
  Real fn = fn_el;
  if (p.beta_n > 0) {
    const Real fv = -viscous_coefficient(p.beta_n, p.mass_eff, kn) * vn;
    fn += fv;
    s.dissip_viscous += -fv * vn * dt;
  }
  // Keep the stored shear force in the tangent plane of the rotated contact frame.
  if (s.normal.squaredNorm() > 0) {
    const Vec3 axis = s.normal.cross(n);              // rotation of the normal
    const Vec3 twist = (0.5 * dt * n.dot(g.angvel_sum)) * n;  // spin about the normal
    s.fs -= s.fs.cross(axis);
    s.fs -= s.fs.cross(twist);
    s.fs -= s.fs.dot(n) * n;
    if (p.kr > 0) {
      s.mr -= s.mr.cross(axis);
      s.mr -= s.mr.cross(twist);
      s.mr -= s.mr.dot(n) * n;
    }
  }
  // Incremental shear force, 000 eq (2): dF_s = -k_s u_s_dot dt.
  s.fs -= ks * dt * vt;
  Vec3 ft = s.fs;
  Vec3 fvs = Vec3::Zero();
  if (p.beta_s > 0) fvs = -viscous_coefficient(p.beta_s, p.mass_eff, ks) * vt;
  // Coulomb cap on the total tangential force, 000 eq (3).
  const Real cap = p.tan_phi * (fn > 0 ? fn : 0.0);
  const Vec3 ft_total = ft + fvs;
  if (ft_total.squaredNorm() > cap * cap) {
    const Real norm = ft_total.norm();
    const Vec3 capped = norm > 0 ? Vec3(ft_total * (cap / norm)) : Vec3(Vec3::Zero());
    if (ks > 0) s.dissip_friction += (s.fs - capped).dot(capped) / ks;
    s.fs = capped;
    fvs.setZero();
  } else if (p.beta_s > 0) {
    s.dissip_viscous += -fvs.dot(vt) * dt;
  }
  LawOutput out;
  out.force2 = fn * n + s.fs + fvs;
  out.moment2.setZero();
  if (p.kr > 0) {
    const Vec3 w = g.rel_angvel - g.rel_angvel.dot(n) * n;
    s.mr -= p.kr * dt * w;
    s.dissip_friction += rolling_cap_apply(s.mr, fn > 0 ? fn : 0.0, p.rolling_cap, p.kr);
    out.moment2 = s.mr;
  }
  s.normal = n;
  s.overlap = g.overlap;
  s.fn = fn;
  return out;
}

}  // namespace cpp_dem
