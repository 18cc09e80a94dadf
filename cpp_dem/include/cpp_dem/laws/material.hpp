// Materials and the per-contact parameters mixed from two materials.
#pragma once

#include "cpp_dem/core/types.hpp"
#include "cpp_dem/laws/law_list.hpp"

namespace cpp_dem {

/// An elastic-frictional material. All values SI.
///
/// The law of a contact is composed of parts chosen from the two materials when the contact
/// is created: the normal/tangential model, optional viscous damping (normal, shear) and
/// optional rolling resistance. Mixing rules:
///  - linear: k_n and k_s by the harmonic means of E R and E R nu (000 eqs 4–5),
///  - Hertz–Mindlin: effective E* and G* (reciprocal sums), R* = R1 R2 / (R1 + R2),
///  - friction: the smaller of the two friction angles (as Yade's FrictPhys),
///  - damping ratios and rolling parameters: arithmetic means,
///  - two materials with different models meet with the linear model (e.g. Hertz–Mindlin
///    grains against a linear geogrid, as 002 §2.3).
struct Material {
  ContactModel model = ContactModel::Linear;  ///< the law's elastic part (laws/law_list.hpp)
  std::uint8_t pad_[7] = {};      ///< zero (explicit padding: checkpoints are byte-identical)
  Real density = 2650.0;          ///< mass density, kg/m^3
  Real young = 1e7;               ///< Young's modulus E, Pa
  /// Poisson's ratio nu, -. For the linear law this is the ratio k_s / k_n entering 000 eq (5)
  /// and must then be in (0, 0.5]; for Hertz–Mindlin it is the elastic Poisson's ratio.
  Real poisson = 0.3;
  Real friction_angle = 0.5;      ///< contact friction angle phi, rad, in [0, pi/2)
  Real damping_normal = 0.0;      ///< viscous damping, ratio of critical, normal, in [0, 1]
  Real damping_shear = 0.0;       ///< viscous damping, ratio of critical, shear, in [0, 1]
  /// Rolling stiffness coefficient beta_r, -: k_r = beta_r k_s R*^2 (Iwashita–Oda). 0 = off.
  Real rolling_stiffness = 0.0;
  /// Rolling friction coefficient eta_r, -: |M_r| <= eta_r R* |F_n|. 0 = off.
  Real rolling_friction = 0.0;

  /// Shear modulus G = E / (2 (1 + nu)), Pa.
  Real shear_modulus() const { return young / (2.0 * (1.0 + poisson)); }

  /// Throws ParameterError naming the first bad field, its value and the allowed range.
  void validate() const;
};

/// Per-contact parameters, computed once when the contact becomes active
/// (and again when radii change). Plain values; the law kernels read only these.
struct ContactPhys {
  ContactModel model = ContactModel::Linear;
  std::uint8_t pad_[7] = {};  ///< zero (explicit padding: checkpoints are byte-identical)
  Real kn = 0;          ///< linear: normal stiffness N/m; Hertz: K in F = K delta^1.5, N/m^1.5
  Real ks = 0;          ///< linear: shear stiffness N/m; Mindlin: C in k_t = C delta^0.5, N/m^1.5
  Real tan_phi = 0;     ///< Coulomb friction coefficient, -
  Real beta_n = 0;      ///< viscous damping ratio, normal, -
  Real beta_s = 0;      ///< viscous damping ratio, shear, -
  Real mass_eff = 0;    ///< effective mass m1 m2 / (m1 + m2), kg (body mass against a wall)
  Real kr = 0;          ///< rolling stiffness, N m / rad
  Real rolling_cap = 0; ///< eta_r R*, m (|M_r| <= rolling_cap |F_n|)
};

/// The law of one pair of materials, over the mixing rules (Scene::set_pair_law): 002 gives
/// its grains Hertz–Mindlin with mu = 0.8 among themselves, and a linear contact with its own
/// k_n, k_s and mu = 0.5 against the geogrid. A field left unset (model_set false, or a
/// negative value) keeps what the mixing rules give.
struct PairLaw {
  int a = 0, b = 0;            ///< the two materials (a <= b)
  bool model_set = false;
  ContactModel model = ContactModel::Linear;  ///< the law's elastic part (if model_set)
  std::uint8_t pad_[6] = {};   ///< zero (explicit padding: checkpoints are byte-identical)
  Real kn = -1;                ///< linear law: normal stiffness, N/m
  Real ks = -1;                ///< linear law: shear stiffness, N/m
  Real friction = -1;          ///< Coulomb friction coefficient mu, -
  Real damping_normal = -1;    ///< viscous damping, ratio of critical, normal, [0, 1]
  Real damping_shear = -1;     ///< viscous damping, ratio of critical, shear, [0, 1]
  /// Throws ParameterError naming the first bad field.
  void validate() const;
};

/// Mixes two materials for a contact with radii r1, r2 (m) and masses m1, m2 (kg). A wall
/// passes infinity for both: R* is then the sphere's radius, and the linear rule (000 eq 4)
/// uses the sphere's radius on both sides, as Yade does.
ContactPhys mix_materials(const Material& a, const Material& b, Real r1, Real r2, Real m1,
                          Real m2);

/// mix_materials with the pair law `law` over it (nullptr: none).
ContactPhys mix_materials(const Material& a, const Material& b, Real r1, Real r2, Real m1,
                          Real m2, const PairLaw* law);

}  // namespace cpp_dem
