// Bonds between two spheres, as PFC defines them (Itasca, PFC 6 "Linear Contact Bond Model" and
// "Linear Parallel Bond Model"; Potyondy & Cundall 2004, Int J Rock Mech Min Sci 41:1329):
//  - the linear contact underneath (normal k_n and shear k_s in N/m, Coulomb friction mu),
//    active in compression; with an intact contact bond it also carries tension and does not
//    slip, until the normal force reaches the bond's tensile strength or the shear force its
//    shear strength (both forces, N);
//  - the parallel bond beside it: a cemented disc of radius R_bar = lambda_bar min(R_a, R_b),
//    with normal and shear stiffness per area k_bar_n, k_bar_s (Pa/m). Its force and moment
//    grow with the bond's area A = pi R_bar^2 and second moments I = pi R_bar^4 / 4,
//    J = pi R_bar^4 / 2:
//        dF_n = k_bar_n A d(delta_n),   dF_s = -k_bar_s A d(delta_s),
//        dM_t = -k_bar_s J d(theta_t),  dM_b = -k_bar_n I d(theta_b);
//    it breaks in tension when sigma = F_n / A + |M_b| R_bar / I >= sigma_c, or in shear when
//    tau = |F_s| / A + |M_t| R_bar / J >= tau_c (PFC's moment-contribution factor 1).
// A bonded pair is one record for its whole life (the pair pass never sees it): after both
// bonds broke it is the plain frictional linear contact.
#pragma once

#include <cmath>
#include <cstdint>

#include "cpp_dem/laws/tangential.hpp"

namespace cpp_dem {

/// Parameters of a bond between two spheres. SI units; a strength of 0 means unbreakable.
struct BondParams {
  // The linear contact (always present).
  Real kn = 0;                 ///< normal stiffness of the linear contact, N/m (> 0)
  Real ks = 0;                 ///< shear stiffness of the linear contact, N/m (>= 0)
  Real friction = 0;           ///< Coulomb friction coefficient mu of the linear contact, -
  // The contact bond (off when both strengths are negative).
  bool contact_bond = false;   ///< the linear contact starts bonded
  Real cb_tensile = 0;         ///< contact bond's tensile strength, N (0: unbreakable)
  Real cb_shear = 0;           ///< contact bond's shear strength, N (0: unbreakable)
  // The parallel bond (off when pb_kn == 0).
  Real pb_kn = 0;              ///< k_bar_n, normal stiffness per area, Pa/m (0: no parallel bond)
  Real pb_ks = 0;              ///< k_bar_s, shear stiffness per area, Pa/m
  Real pb_radius_factor = 1;   ///< lambda_bar, -: R_bar = lambda_bar min(R_a, R_b)
  Real pb_tensile = 0;         ///< sigma_c, tensile strength, Pa (0: unbreakable)
  Real pb_shear = 0;           ///< tau_c, shear strength, Pa (0: unbreakable)
  /// Throws ParameterError naming the first bad field, its value and the allowed range.
  void validate() const;
};

/// Why a bond part broke (BondBreak::mode).
enum BondBreakMode : int {
  BOND_CB_TENSION = 0,  ///< contact bond, normal force at its tensile strength
  BOND_CB_SHEAR = 1,    ///< contact bond, shear force at its shear strength
  BOND_PB_TENSION = 2,  ///< parallel bond, sigma at sigma_c
  BOND_PB_SHEAR = 3,    ///< parallel bond, tau at tau_c
};

/// A break of one part of a bond: when, which bond, which mode, and the value that reached
/// the strength (N for a contact bond, Pa for a parallel bond).
struct BondBreak {
  long step = 0;
  Real time = 0;   ///< s
  int bond = 0;
  int mode = 0;    ///< BondBreakMode
  Real value = 0;  ///< N (contact bond) or Pa (parallel bond)
};

/// A bonded pair of spheres a, b (slots): parameters, history and the last step's output.
struct Bond {
  int a = 0, b = 0;             ///< body slots (ids in the Python face)
  // Derived parameters (bond_setup).
  Real kn = 0, ks = 0, tan_phi = 0;  ///< linear contact, N/m and -
  Real cb_fn_max = 0, cb_fs_max = 0;  ///< contact bond strengths, N (0: unbreakable)
  Real pb_radius = 0;           ///< R_bar, m
  Real pb_area = 0;             ///< A, m^2
  Real pb_i = 0, pb_j = 0;      ///< I and J, m^4
  Real pb_kn = 0, pb_ks = 0;    ///< Pa/m
  Real pb_sigma_c = 0, pb_tau_c = 0;  ///< Pa (0: unbreakable)
  Real length0 = 0;             ///< centre distance when the bond formed, m
  /// Reference gap, m: the surface gap when the bond formed. The linear contact is active
  /// when the gap is below it (PFC's reference gap), so a pair starts unloaded.
  Real gap0 = 0;
  bool cb_intact = false;       ///< the contact bond holds
  bool pb_intact = false;       ///< the parallel bond holds
  /// Periodic cell: b is seen at its image pos_b + H (cell_shift + image_b - image_a), with
  /// image_a, image_b the bodies' wrap counts (body_store.hpp), so that the bond follows its
  /// spheres through the cell's faces. Zero without a cell. (It fills what was padding: the
  /// record's size and a checkpoint's bytes without a cell are unchanged.)
  std::int16_t cell_shift[3] = {0, 0, 0};
  // History.
  Vec3 normal = Vec3::Zero();   ///< unit a -> b at the last step
  Real fn = 0;                  ///< linear contact's normal force, N, compression positive
  Vec3 fs = Vec3::Zero();       ///< linear contact's shear force on b, N
  Real pb_fn = 0;               ///< parallel bond's normal force, N, tension positive
  Vec3 pb_fs = Vec3::Zero();    ///< parallel bond's shear force on b, N
  Real pb_mt = 0;               ///< parallel bond's twisting moment on b about the normal, N m
  Vec3 pb_mb = Vec3::Zero();    ///< parallel bond's bending moment on b, N m
  Real dissip_friction = 0;     ///< dissipated by the linear contact's slip, J
  int pending_break = -1;       ///< set during a step: a BondBreakMode
  int pad_pending_ = 0;         ///< zero (explicit padding)
  Real pending_value = 0;       ///< the value that reached the strength
  // Output of the last step.
  Vec3 force_b = Vec3::Zero();  ///< total force on b (a gets the opposite), N
  Vec3 torque_a = Vec3::Zero(), torque_b = Vec3::Zero();  ///< N m

  /// Either bond part still holds.
  bool bonded() const { return cb_intact || pb_intact; }
  /// The parallel bond's normal and shear stresses sigma, tau at its rim, Pa.
  Real pb_sigma() const { return pb_fn / pb_area + pb_mb.norm() * pb_radius / pb_i; }
  Real pb_tau() const { return pb_fs.norm() / pb_area + std::abs(pb_mt) * pb_radius / pb_j; }
  /// Its springs acting along and across the normal at the contact point, N/m: the linear
  /// contact's (when it acts: bonded, or in compression) and the intact parallel bond's
  /// (k_bar A).
  void stiffness(Real& k_normal, Real& k_shear) const {
    const bool linear = cb_intact || fn > 0;
    k_normal = (linear ? kn : 0) + (pb_intact ? pb_kn * pb_area : 0);
    k_shear = (linear ? ks : 0) + (pb_intact ? pb_ks * pb_area : 0);
  }
  /// Energy stored in the intact parallel bond alone (released when it breaks), J.
  Real pb_energy() const {
    if (!pb_intact) return 0;
    Real e = 0.5 * pb_fn * pb_fn / (pb_kn * pb_area) + 0.5 * pb_mb.squaredNorm() / (pb_kn * pb_i);
    if (pb_ks > 0)
      e += 0.5 * pb_fs.squaredNorm() / (pb_ks * pb_area) + 0.5 * pb_mt * pb_mt / (pb_ks * pb_j);
    return e;
  }
  /// Energy stored in the linear contact's and the intact parallel bond's springs, J.
  Real elastic_energy() const {
    Real e = pb_energy();
    if (fn != 0) e += 0.5 * fn * fn / kn;
    if (ks > 0) e += 0.5 * fs.squaredNorm() / ks;
    return e;
  }
};

/// Sets bond l's derived parameters from p for spheres of radii ra, rb (m) whose centres are
/// `distance` apart (m): the bond forms at that distance, unloaded.
inline void bond_setup(const BondParams& p, Real ra, Real rb, Real distance, Bond& l) {
  l.kn = p.kn;
  l.ks = p.ks;
  l.tan_phi = p.friction;
  l.cb_intact = p.contact_bond;
  l.cb_fn_max = p.cb_tensile;
  l.cb_fs_max = p.cb_shear;
  l.pb_intact = p.pb_kn > 0;
  l.pb_radius = p.pb_radius_factor * std::min(ra, rb);
  l.pb_area = M_PI * l.pb_radius * l.pb_radius;
  l.pb_i = 0.25 * M_PI * std::pow(l.pb_radius, 4);
  l.pb_j = 0.5 * M_PI * std::pow(l.pb_radius, 4);
  l.pb_kn = p.pb_kn;
  l.pb_ks = p.pb_ks;
  l.pb_sigma_c = p.pb_tensile;
  l.pb_tau_c = p.pb_shear;
  l.length0 = distance;
  l.gap0 = distance - ra - rb;
}

/// The forces and torques of bond l on its spheres from its current state, with the
/// contact point at ca from a's centre and cb from b's (m).
inline void bond_output(Bond& l, const Vec3& ca, const Vec3& cb) {
  const Vec3& n = l.normal;
  Vec3 force = l.fn * n + l.fs;  // on b
  Vec3 moment = Vec3::Zero();    // on b, besides the force's
  if (l.pb_intact) {
    force += -l.pb_fn * n + l.pb_fs;
    moment = l.pb_mb + l.pb_mt * n;
  }
  l.force_b = force;
  l.torque_b = cb.cross(force) + moment;
  l.torque_a = ca.cross(-force) - moment;
}

/// Removes the part of bond l that broke (mode, a BondBreakMode) and sets its outputs again
/// from what is left, for spheres of radii ra, rb at xa, xb (m); returns the elastic energy
/// the break released, J. A broken contact bond leaves the frictional linear contact: no
/// force in tension, the shear force capped by friction.
inline Real bond_release(Bond& l, int mode, Real ra, Real rb, const Vec3& xa, const Vec3& xb) {
  const Real before = l.elastic_energy();
  if (mode == BOND_CB_TENSION || mode == BOND_CB_SHEAR) {
    l.cb_intact = false;
    if (l.fn <= 0) {
      l.fn = 0;
      l.fs.setZero();
    } else {
      Real ignored = 0;  // (the release is counted as a whole below)
      cap_magnitude<NarrowOps>(l.fs, l.tan_phi * l.fn, l.ks, ignored);
    }
  } else {
    l.pb_intact = false;
    l.pb_fn = l.pb_mt = 0;
    l.pb_fs.setZero();
    l.pb_mb.setZero();
  }
  const Real gap = (xb - xa).norm() - ra - rb;
  bond_output(l, (ra + 0.5 * gap) * l.normal, -(rb + 0.5 * gap) * l.normal);
  return before - l.elastic_energy();
}

/// One step of bond l between spheres of radii ra, rb at xa, xb (m), with velocities va, vb
/// (m/s) and spins wa, wb (rad/s), over dt (s). The stored shear forces and the bending
/// moment are carried into the turned frame of the contact; the linear contact acts at the
/// contact point x_c = x_a + (R_a + g/2) n (g the surface gap), in compression, or in
/// tension too while the contact bond holds (relative to the reference gap, Bond::gap0); the
/// parallel bond's springs are incremented.
/// A part that reaches its strength is flagged in pending_break (the scene removes it after
/// the pass, in bond order). Sets the forces and torques on the two spheres; returns the
/// linear contact's overlap beyond the reference gap, gap0 - g (m).
ALWAYS_INLINE Real bond_step(Bond& l, Real ra, Real rb, const Vec3& xa, const Vec3& xb,
                             const Vec3& va, const Vec3& vb, const Vec3& wa, const Vec3& wb,
                             Real dt) {
  const Vec3 d = xb - xa;
  const Real dist = d.norm();
  const Vec3 n = d / dist;
  const Real gap = dist - ra - rb;
  const Real dgap = gap - l.gap0;  // < 0: the linear contact is pressed
  // Keep the stored tangential vectors in the turned frame of the contact.
  if (l.normal.squaredNorm() > 0) {
    Vec3 axis, twist;
    frame_turn<NarrowOps>(l.normal, n, Vec3(wa + wb), dt, axis, twist);
    turn_into_frame<NarrowOps>(l.fs, axis, twist, n);
    if (l.pb_intact) {
      turn_into_frame<NarrowOps>(l.pb_fs, axis, twist, n);
      turn_into_frame<NarrowOps>(l.pb_mb, axis, twist, n);
    }
  }
  l.normal = n;
  // Relative motion of b's contact point against a's.
  const Vec3 ca = (ra + 0.5 * gap) * n, cb = -(rb + 0.5 * gap) * n;
  const Vec3 vrel = (vb + wb.cross(cb)) - (va + wa.cross(ca));
  const Vec3 dus = dt * (vrel - vrel.dot(n) * n);
  const Vec3 wrel = wb - wa;
  const Real dth_t = dt * wrel.dot(n);
  const Vec3 dth_b = dt * wrel - dth_t * n;
  l.pending_break = -1;
  // The linear contact: compression positive.
  if (l.cb_intact || dgap < 0) {
    l.fn = -l.kn * dgap;
    l.fs -= l.ks * dus;
    if (l.cb_intact) {
      if (l.cb_fn_max > 0 && -l.fn >= l.cb_fn_max) {
        l.pending_break = BOND_CB_TENSION;
        l.pending_value = -l.fn;
      } else if (l.cb_fs_max > 0 && l.fs.norm() >= l.cb_fs_max) {
        l.pending_break = BOND_CB_SHEAR;
        l.pending_value = l.fs.norm();
      }
    } else {
      cap_magnitude<NarrowOps>(l.fs, l.tan_phi * l.fn, l.ks, l.dissip_friction);
    }
  } else {
    l.fn = 0;
    l.fs.setZero();
  }
  if (l.pb_intact) {
    l.pb_fn = l.pb_kn * l.pb_area * (dist - l.length0);
    l.pb_fs -= l.pb_ks * l.pb_area * dus;
    l.pb_mt -= l.pb_ks * l.pb_j * dth_t;
    l.pb_mb -= l.pb_kn * l.pb_i * dth_b;
    if (l.pending_break < 0) {
      const Real sigma = l.pb_sigma(), tau = l.pb_tau();
      if (l.pb_sigma_c > 0 && sigma >= l.pb_sigma_c) {
        l.pending_break = BOND_PB_TENSION;
        l.pending_value = sigma;
      } else if (l.pb_tau_c > 0 && tau >= l.pb_tau_c) {
        l.pending_break = BOND_PB_SHEAR;
        l.pending_value = tau;
      }
    }
  }
  bond_output(l, ca, cb);
  return -dgap;
}

}  // namespace cpp_dem
