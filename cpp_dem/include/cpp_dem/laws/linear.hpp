// The linear Cundall–Strack law (000 eqs 1–6): its elastic part for the registry, and the
// short kernel that the hot loops run for a linear contact without dashpots or rolling
// resistance.
#pragma once

#include <array>
#include <cmath>

#include "cpp_dem/laws/material.hpp"
#include "cpp_dem/laws/tangential.hpp"

namespace cpp_dem {

/// Normal force magnitude of the linear law, N: F_n = k_n u_n (000 eq 1).
inline Real linear_normal_force(Real kn, Real overlap) { return kn * overlap; }

/// The elastic part of the linear law (registry row "linear").
struct LinearElastic {
  /// The hot loops have a short kernel for it (linear_frictional).
  static constexpr bool kShortKernel = true;
  static constexpr const char* kSummary =
      "linear Cundall–Strack: F_n = k_n u_n, dF_s = -k_s v_s dt, Coulomb cap (000 eqs 1-5)";
  /// Its own parameters beyond the shared ones (material.hpp): none.
  static constexpr std::array<FieldInfo, 0> kFields{};
  /// nu is the ratio k_s/k_n of 000 eq (5) here.
  static void validate(const Material& m) {
    require(std::isfinite(m.poisson) && m.poisson > 0 && m.poisson <= 0.5, "poisson", m.poisson,
            "must be in (0, 0.5] for the linear law, where it is the ratio k_s/k_n of "
            "000 eq (5)");
  }
  /// Normal stiffness, 000 eq (4), and shear stiffness, 000 eq (5): harmonic means of E R and
  /// E R nu (N/m). r1, r2: the radii (m; a wall's is the sphere's).
  static void mix(const Material& a, const Material& b, Real r1, Real r2, Real /*r_eff*/,
                  ContactPhys& p) {
    const Real era = a.young * r1, erb = b.young * r2;
    p.kn = 2.0 * era * erb / (era + erb);
    const Real erna = era * a.poisson, ernb = erb * b.poisson;
    p.ks = 2.0 * erna * ernb / (erna + ernb);
  }
  /// The shear stiffness that scales the rolling stiffness, N/m: k_s.
  static Real rolling_reference(const Material&, const Material&, Real, const ContactPhys& p) {
    return p.ks;
  }
  static Real normal_force(const ContactPhys& p, Real overlap) {
    return linear_normal_force(p.kn, overlap);
  }
  /// Tangent stiffnesses, N/m (constant).
  static void stiffness(const ContactPhys& p, Real, Real& kn, Real& ks) {
    kn = p.kn;
    ks = p.ks;
  }
  /// Energy of the normal spring, J.
  static Real normal_energy(const ContactPhys& p, Real overlap) {
    return 0.5 * p.kn * overlap * overlap;
  }
};

/// The short kernel: the linear law with Coulomb friction and no dashpot or rolling part
/// (frictional_spring's arguments; overlap in m, kn and ks in N/m). Returns the normal force
/// F_n (N).
template <class Ops, class V>
ALWAYS_INLINE Real linear_frictional(V& fs, const V& n_old, const V& n, Real overlap,
                                     const V& rel_vel, const V& angvel_sum, Real kn, Real ks,
                                     Real tan_phi, Real dt, Real& dissip_friction) {
  const Real fn = kn * overlap;  // 000 eq (1)
  frictional_spring<Ops>(fs, n_old, n, fn, rel_vel, angvel_sum, ks, tan_phi, dt,
                         dissip_friction);
  return fn;
}

}  // namespace cpp_dem
