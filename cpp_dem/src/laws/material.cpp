// Materials: validation and the mixing of two materials into a contact's parameters, through
// the law registry (laws/registry.hpp).
#include "cpp_dem/laws/material.hpp"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>

#include "cpp_dem/laws/beam.hpp"  // BeamParams
#include "cpp_dem/laws/registry.hpp"

namespace cpp_dem {

std::string fmt_real(Real v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

std::string FieldInfo::range() const {
  std::string range;
  const bool has_lo = std::isfinite(lo), has_hi = std::isfinite(hi);
  if (has_lo && has_hi)
    range = std::string("in ") + (lo_closed ? "[" : "(") + fmt_real(lo) + ", " + fmt_real(hi) +
            (hi_closed ? "]" : ")");
  else if (has_lo)
    range = std::string(lo_closed ? ">= " : "> ") + fmt_real(lo);
  else if (has_hi)
    range = std::string(hi_closed ? "<= " : "< ") + fmt_real(hi);
  else
    range = "finite";
  return range;
}

std::string FieldInfo::allowed() const {
  const std::string u = unit;
  return "must be " + range() + (u == "-" ? "" : " (" + u + ")");
}

void FieldInfo::check(Real v) const {
  const bool ok = std::isfinite(v) && (!std::isfinite(lo) || (lo_closed ? v >= lo : v > lo)) &&
                  (!std::isfinite(hi) || (hi_closed ? v <= hi : v < hi));
  if (!ok) throw ParameterError(std::string(name) + "=" + fmt_real(v) + ": " + allowed());
}

std::vector<const FieldInfo*> material_fields(ContactModel m) {
  std::vector<const FieldInfo*> out;
  for (const FieldInfo& f : kMaterialFields) out.push_back(&f);
  const LawInfo& law = law_info(m);
  for (int k = 0; k < law.n_fields; ++k) out.push_back(&law.fields[k]);
  return out;
}

void Material::validate() const {
  // Every field's range (the list's order), then the law's own rules (e.g. the linear law's
  // nu > 0, where nu is the ratio k_s/k_n).
  for (const FieldInfo* f : material_fields(model)) f->check(f->to_python(field_value(*this, *f)));
  with_elastic_part(model, [&](auto part) { decltype(part)::validate(*this); });
}

Material Material::of_law(ContactModel m) {
  Material out;
  out.model = m;
  for (const FieldInfo* f : material_fields(m))
    if (!f->required()) field_value(out, *f) = f->to_stored(f->fallback);
  return out;
}

Material Material::as_law(ContactModel m) const {
  if (m == model) return *this;
  Material out = *this;
  out.model = m;
  const Material fresh = of_law(m);
  for (int k = 0; k < kLawParamSlots; ++k) out.law_params[k] = fresh.law_params[k];
  return out;
}

namespace {

/// tan(angle) (angle in rad), remembered for the last angle this thread asked for, to the
/// bit: the contacts of a packing whose radii grow are mixed again at every step, all with
/// the same friction angle.
Real friction_tan(Real angle) {
  thread_local bool known = false;
  thread_local std::uint64_t last_bits = 0;
  thread_local Real last_tan = 0;
  std::uint64_t bits;
  std::memcpy(&bits, &angle, sizeof bits);
  if (!known || bits != last_bits) {
    last_tan = std::tan(angle);
    last_bits = bits;
    known = true;
  }
  return last_tan;
}

/// mix_materials into p (every field set).
void mix_into(const Material& a, const Material& b, Real r1, Real r2, Real m1, Real m2,
              ContactPhys& p) {
  p = ContactPhys{};
  // A wall passes an infinite radius: R* is then the sphere's radius, and the linear rule
  // (000 eq 4) takes the sphere's radius for both sides, as Yade does.
  const Real r_eff = std::isinf(r2) ? r1 : (std::isinf(r1) ? r2 : r1 * r2 / (r1 + r2));
  if (std::isinf(r1)) r1 = r2;
  if (std::isinf(r2)) r2 = r1;
  // Two materials of different laws meet with the linear law (e.g. Hertz–Mindlin grains
  // against a linear geogrid, as 002 §2.3).
  p.model = a.model == b.model ? a.model : ContactModel::Linear;
  // (a material of another law brings the shared parameters; the law's own are its defaults;
  // a material of the contact's law is read in place, not copied)
  std::optional<Material> a_other, b_other;
  if (a.model != p.model) a_other = a.as_law(p.model);
  if (b.model != p.model) b_other = b.as_law(p.model);
  const Material& a2 = a_other ? *a_other : a;
  const Material& b2 = b_other ? *b_other : b;
  with_elastic_part(p.model, [&](auto part) { decltype(part)::mix(a2, b2, r1, r2, r_eff, p); });
  p.tan_phi = friction_tan(std::min(a.friction_angle, b.friction_angle));
  p.beta_n = 0.5 * (a.damping_normal + b.damping_normal);
  p.beta_s = 0.5 * (a.damping_shear + b.damping_shear);
  if (std::isinf(m1)) p.mass_eff = m2;
  else if (std::isinf(m2)) p.mass_eff = m1;
  else p.mass_eff = m1 * m2 / (m1 + m2);
  const Real beta_r = 0.5 * (a.rolling_stiffness + b.rolling_stiffness);
  const Real eta_r = 0.5 * (a.rolling_friction + b.rolling_friction);
  if (beta_r > 0 && eta_r > 0) {
    // The rolling stiffness scales with the law's reference shear stiffness.
    const Real ks_lin = with_elastic_part(
        p.model, [&](auto part) { return decltype(part)::rolling_reference(a2, b2, r_eff, p); });
    p.kr = beta_r * ks_lin * r_eff * r_eff;
    p.rolling_cap = eta_r * r_eff;
  }
}

}  // namespace

ContactPhys mix_materials(const Material& a, const Material& b, Real r1, Real r2, Real m1,
                          Real m2) {
  ContactPhys p;
  mix_into(a, b, r1, r2, m1, m2, p);
  return p;
}

void PairLaw::validate() const {
  require(kn < 0 || std::isfinite(kn), "kn", kn, "must be finite (N/m)");
  require(ks < 0 || std::isfinite(ks), "ks", ks, "must be finite (N/m)");
  require(!(kn == 0), "kn", kn, "must be > 0 (N/m), or unset");
  require(friction < 0 || std::isfinite(friction), "friction", friction,
          "must be finite (Coulomb coefficient mu), or unset");
  require(damping_normal < 0 || damping_normal <= 1, "damping_normal", damping_normal,
          "must be in [0, 1] (ratio of critical), or unset");
  require(damping_shear < 0 || damping_shear <= 1, "damping_shear", damping_shear,
          "must be in [0, 1] (ratio of critical), or unset");
}

void mix_materials(const Material& a, const Material& b, Real r1, Real r2, Real m1, Real m2,
                   const PairLaw* law, ContactPhys& p) {
  // (Written in place: a result returned and then copied was read back, as 16-byte loads,
  // from the 8-byte stores that had just written it, a stall at each of its fields.)
  if (law && law->model_set)
    mix_into(a.as_law(law->model), b.as_law(law->model), r1, r2, m1, m2, p);
  else
    mix_into(a, b, r1, r2, m1, m2, p);
  if (!law) return;
  if (law->kn >= 0) p.kn = law->kn;
  if (law->ks >= 0) p.ks = law->ks;
  if (law->friction >= 0) p.tan_phi = law->friction;
  if (law->damping_normal >= 0) p.beta_n = law->damping_normal;
  if (law->damping_shear >= 0) p.beta_s = law->damping_shear;
}

ContactPhys mix_materials(const Material& a, const Material& b, Real r1, Real r2, Real m1,
                          Real m2, const PairLaw* law) {
  ContactPhys p;
  mix_materials(a, b, r1, r2, m1, m2, law, p);
  return p;
}

/// Parameters of the geogrid's cohesive beam (grid.hpp); validated here with the other
/// material parameters so that a build without the geogrid (grid_off.cpp) still checks them.
void BeamParams::validate() const {
  require(std::isfinite(young) && young > 0, "young", young, "must be > 0 (Pa)");
  require(std::isfinite(poisson) && poisson > -1 && poisson <= 0.5, "poisson", poisson,
          "must be in (-1, 0.5]");
  require(std::isfinite(radius) && radius > 0, "radius", radius, "must be > 0 (m)");
  require(std::isfinite(normal_cohesion) && normal_cohesion >= 0, "normal_cohesion",
          normal_cohesion, "must be >= 0 (Pa; 0 = unbreakable)");
  require(std::isfinite(shear_cohesion) && shear_cohesion >= 0, "shear_cohesion",
          shear_cohesion, "must be >= 0 (Pa; 0 = unbreakable)");
}

}  // namespace cpp_dem
