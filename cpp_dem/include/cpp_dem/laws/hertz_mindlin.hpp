// The Hertz–Mindlin law (002 Table 1): Hertz normal force, no-slip Mindlin tangential
// stiffness, Coulomb cap. Its elastic part for the registry.
#pragma once

#include <array>
#include <cmath>
#include <cstring>

#include "cpp_dem/laws/damping.hpp"
#include "cpp_dem/laws/material.hpp"
#include "cpp_dem/laws/tangential.hpp"

namespace cpp_dem {

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

/// The elastic part of the Hertz–Mindlin law (registry row "hertz_mindlin").
struct HertzMindlinElastic {
  static constexpr bool kShortKernel = false;
  static constexpr const char* kSummary =
      "Hertz normal force, no-slip Mindlin tangential stiffness, Coulomb cap";
  /// Its own parameters beyond the shared ones (material.hpp): none.
  static constexpr std::array<FieldInfo, 0> kFields{};
  static void validate(const Material& m) {
    require(std::isfinite(m.poisson) && m.poisson > -1 && m.poisson <= 0.5, "poisson",
            m.poisson, "must be in (-1, 0.5]");
  }
  /// 1 / E* of two elastic bodies, 1/Pa.
  static Real inverse_e_star(const Material& a, const Material& b) {
    return (1 - a.poisson * a.poisson) / a.young + (1 - b.poisson * b.poisson) / b.young;
  }
  /// The effective moduli of two elastic spheres (reciprocal sums): 1/E* (1/Pa), E* and G*
  /// (Pa).
  struct Moduli {
    Real inverse_e_star, e_star, g_star;
  };
  /// The moduli of materials a and b, remembered per thread for the last (E, nu) of both
  /// asked for, to the bit: the contacts of a packing whose radii grow are mixed again at
  /// every step, nearly all of one pair of materials.
  static Moduli moduli(const Material& a, const Material& b) {
    thread_local bool known = false;
    thread_local Real last_key[4] = {0, 0, 0, 0};
    thread_local Moduli last{0, 0, 0};
    const Real key[4] = {a.young, a.poisson, b.young, b.poisson};
    if (!known || std::memcmp(key, last_key, sizeof key) != 0) {
      const Real inv = inverse_e_star(a, b);
      const Real g_a = a.shear_modulus(), g_b = b.shear_modulus();
      last = {inv, 1.0 / inv, 1.0 / ((2 - a.poisson) / g_a + (2 - b.poisson) / g_b)};
      std::memcpy(last_key, key, sizeof key);
      known = true;
    }
    return last;
  }
  /// p.kn = K = 4/3 E* sqrt(R*) (N/m^1.5) and p.ks = C = 8 G* sqrt(R*) (N/m^1.5).
  static void mix(const Material& a, const Material& b, Real, Real, Real r_eff, ContactPhys& p) {
    const Moduli m = moduli(a, b);
    p.kn = 4.0 / 3.0 * m.e_star * std::sqrt(r_eff);
    p.ks = 8.0 * m.g_star * std::sqrt(r_eff);
  }
  /// k_s depends on the overlap, so the rolling stiffness takes the reference stiffness
  /// E* R* (N/m) and stays a constant of the contact.
  static Real rolling_reference(const Material& a, const Material& b, Real r_eff,
                                const ContactPhys&) {
    return r_eff / moduli(a, b).inverse_e_star;
  }
  static Real normal_force(const ContactPhys& p, Real overlap) {
    return hertz_normal_force(p.kn, overlap);
  }
  /// Tangent stiffnesses at the overlap, N/m.
  static void stiffness(const ContactPhys& p, Real overlap, Real& kn, Real& ks) {
    kn = hertz_normal_stiffness(p.kn, overlap);
    ks = mindlin_shear_stiffness(p.ks, overlap);
  }
  /// Energy of the normal spring, J: int K d^1.5 = 2/5 K d^2.5.
  static Real normal_energy(const ContactPhys& p, Real overlap) {
    return 0.4 * p.kn * overlap * overlap * std::sqrt(overlap);
  }
};

/// The pair pass's short kernel of the Hertz–Mindlin law without dashpots or rolling
/// resistance (frictional_spring's arguments; overlap in m; k_hertz = K and c_mindlin = C,
/// N/m^1.5, as ContactPhys::kn and ::ks): the composed law's lines for it, in its order
/// (the same bits as apply_law), without its geometry record, its state's copy or its
/// dispatch. Returns the normal force F_n (N).
template <class Ops, class V>
ALWAYS_INLINE Real hertz_frictional(V& fs, const V& n_old, const V& n, Real overlap,
                                    const V& rel_vel, const V& angvel_sum, Real k_hertz,
                                    Real c_mindlin, Real tan_phi, Real dt,
                                    Real& dissip_friction) {
  const Real ks = mindlin_shear_stiffness(c_mindlin, overlap);
  const Real fn = hertz_normal_force(k_hertz, overlap);
  frictional_spring<Ops>(fs, n_old, n, fn, rel_vel, angvel_sum, ks, tan_phi, dt,
                         dissip_friction);
  return fn;
}

/// hertz_frictional with the dashpots (002's filling: viscous damping normal and shear):
/// the composed law's lines for the Hertz–Mindlin law without rolling resistance, in its
/// order (the same bits as apply_law), the parameters from p (kn = K, ks = C, tan_phi,
/// beta_n, beta_s, mass_eff). fvs: the shear dashpot's force (N; zero where the contact
/// slips or beta_s = 0), which the contact's force adds: fn n + fs + fvs. Viscous energy (J)
/// is added to dissip_viscous. Returns the total normal force (N).
template <class Ops, class V>
ALWAYS_INLINE Real hertz_damped(V& fs, const V& n_old, const V& n, Real overlap,
                                const V& rel_vel, const V& angvel_sum, const ContactPhys& p,
                                Real dt, Real& dissip_friction, Real& dissip_viscous, V& fvs) {
  const Real kn = hertz_normal_stiffness(p.kn, overlap);
  const Real ks = mindlin_shear_stiffness(p.ks, overlap);
  Real fn = hertz_normal_force(p.kn, overlap);
  const Real vn = Ops::dot(rel_vel, n);
  const V vt = rel_vel - vn * n;
  if (p.beta_n > 0) {
    const Real fv = -viscous_coefficient(p.beta_n, p.mass_eff, kn) * vn;
    fn += fv;
    dissip_viscous += -fv * vn * dt;
  }
  if (Ops::dot(n_old, n_old) > 0) {
    V axis, twist;
    frame_turn<Ops>(n_old, n, angvel_sum, dt, axis, twist);
    turn_into_frame<Ops>(fs, axis, twist, n);
  }
  fs -= (ks * dt) * vt;
  fvs = Ops::zero();
  if (p.beta_s > 0) fvs = -viscous_coefficient(p.beta_s, p.mass_eff, ks) * vt;
  const Real cap = p.tan_phi * (fn > 0 ? fn : 0.0);
  if (cap_spring<Ops>(fs, p.beta_s > 0 ? V(fs + fvs) : fs, cap, ks, dissip_friction)) {
    fvs = Ops::zero();  // slip: the capped total is all in the spring
  } else if (p.beta_s > 0) {
    dissip_viscous += -Ops::dot(fvs, vt) * dt;
  }
  return fn;
}

}  // namespace cpp_dem
