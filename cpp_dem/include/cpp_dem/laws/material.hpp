// Materials and the per-contact parameters mixed from two materials.
#pragma once

#include <string>
#include <vector>

#include "cpp_dem/core/types.hpp"
#include "cpp_dem/laws/fields.hpp"
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
///
/// Every parameter is a field of the one list (material_fields(model)): the shared ones below
/// (kMaterialFields), and the law's own in law_params (its kFields, laws/<law>.hpp).
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
  /// The law's own parameters, in the order of its kFields (laws/<law>.hpp); a law reads them
  /// as law_params[k]. Slots a law does not declare are zero.
  Real law_params[kLawParamSlots] = {};

  /// Shear modulus G = E / (2 (1 + nu)), Pa.
  Real shear_modulus() const { return young / (2.0 * (1.0 + poisson)); }

  /// Throws ParameterError naming the first bad field, its value and the allowed range.
  void validate() const;

  /// This material under law m: the same shared parameters; the law's own at m's defaults
  /// when m is not this material's law (so that a law never reads another law's slots).
  Material as_law(ContactModel m) const;
  /// A material of law m with every optional parameter at its default (the required ones at
  /// the member initialisers above).
  static Material of_law(ContactModel m);
};

/// The parameters every law shares, in their Python order. Defaults are the Python keywords'
/// (NaN: required); bounds are checked by Material::validate before the law's own rules.
inline const FieldInfo kMaterialFields[] = {
    {"density", "kg/m^3", "mass density", kRequired, 0.0, false, kNoBound, false,
     FieldScale::Plain, &Material::density},
    {"young", "Pa", "Young's modulus E", kRequired, 0.0, false, kNoBound, false, FieldScale::Plain,
     &Material::young},
    {"poisson", "-",
     "Poisson's ratio nu (the linear law: the ratio k_s/k_n of 000 eq 5, in (0, 0.5])",
     kRequired, -1.0, false, 0.5, true, FieldScale::Plain, &Material::poisson},
    {"friction_angle_deg", "deg", "contact friction angle (stored in radians)", kRequired, 0.0,
     true, 90.0, false, FieldScale::Degrees, &Material::friction_angle},
    {"damping_normal", "ratio of critical", "viscous damping of the normal spring", 0.0, 0.0,
     true, 1.0, true, FieldScale::Plain, &Material::damping_normal},
    {"damping_shear", "ratio of critical", "viscous damping of the shear spring", 0.0, 0.0,
     true, 1.0, true, FieldScale::Plain, &Material::damping_shear},
    {"rolling_stiffness", "-", "beta_r: k_r = beta_r k_s R*^2 (0: no rolling resistance)", 0.0,
     0.0, true, kNoBound, false, FieldScale::Plain, &Material::rolling_stiffness},
    {"rolling_friction", "-", "eta_r: |M_r| <= eta_r R* |F_n|", 0.0, 0.0, true, kNoBound, false,
     FieldScale::Plain, &Material::rolling_friction},
};

/// Every parameter of a material of law m: kMaterialFields, then the law's own kFields.
std::vector<const FieldInfo*> material_fields(ContactModel m);

/// The place of the field called `name` in `fields` (fields.size(): none).
inline size_t field_index(const std::vector<const FieldInfo*>& fields, const std::string& name) {
  size_t i = 0;
  while (i < fields.size() && name != fields[i]->name) ++i;
  return i;
}

/// The stored value of field f in material s (a named member, or a law_params slot).
inline Real& field_value(Material& s, const FieldInfo& f) {
  return f.member ? s.*(f.member) : s.law_params[f.slot];
}
inline Real field_value(const Material& s, const FieldInfo& f) {
  return f.member ? s.*(f.member) : s.law_params[f.slot];
}

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
/// The same, written into `out` (whose every field it sets): the pair pass's contacts, mixed
/// again at every step while radii grow, are written in place, not copied.
void mix_materials(const Material& a, const Material& b, Real r1, Real r2, Real m1, Real m2,
                   const PairLaw* law, ContactPhys& out);

}  // namespace cpp_dem
