// The registry of contact laws: one row per law of laws/law_list.hpp, and the one switch that
// turns a law id into its elastic part. The hot loops resolve the law when a contact is
// created (ContactPhys::model, and the short-kernel flag of the contact record) and dispatch
// on the id with this switch, never through a virtual call per contact.
#pragma once

#include <string>

#include "cpp_dem/laws/hertz_mindlin.hpp"
#include "cpp_dem/laws/linear.hpp"
#include "cpp_dem/laws/material.hpp"

namespace cpp_dem {

/// One registry row: what the Python face, the docs and the error messages need to know of a
/// law; the law's maths is its elastic part (a struct of static functions: validate, mix,
/// rolling_reference, normal_force, stiffness, normal_energy).
struct LawInfo {
  ContactModel id;
  const char* name;      ///< name in the Python API and run files
  const char* summary;   ///< one line for docs and reprs
  bool short_kernel;     ///< the hot loops have a short kernel for it (no dashpot, no rolling)
  const FieldInfo* fields;  ///< its own parameters (part::kFields; Material::law_params)
  int n_fields;
};

/// A law's own fields: at most kLawParamSlots, each in the slot of its place in the list, each
/// with a default (a material of another law meets this law with it).
template <class Part>
constexpr bool law_fields_fit() {
  if (Part::kFields.size() > static_cast<std::size_t>(kLawParamSlots)) return false;
  for (std::size_t k = 0; k < Part::kFields.size(); ++k)
    if (Part::kFields[k].slot != static_cast<int>(k) || Part::kFields[k].member ||
        !(Part::kFields[k].fallback == Part::kFields[k].fallback))  // (a default: not NaN)
      return false;
  return true;
}

/// Calls f(Part{}) with the elastic part of law m (the one dispatch on a law id).
template <class F>
inline decltype(auto) with_elastic_part(ContactModel m, F&& f) {
  switch (m) {
#define CPP_DEM_LAW_CASE(id, name, part) \
  case ContactModel::id:                 \
    return f(part{});
    CPP_DEM_CONTACT_LAWS(CPP_DEM_LAW_CASE)
#undef CPP_DEM_LAW_CASE
  }
  throw ParameterError("model=" + std::to_string(static_cast<int>(m)) + ": no such contact law");
}

/// Every law, in the order of laws/law_list.hpp.
inline constexpr LawInfo kLaws[] = {
#define CPP_DEM_LAW_ROW(id, name, part)                                              \
  {ContactModel::id, name, part::kSummary, part::kShortKernel, part::kFields.data(), \
   static_cast<int>(part::kFields.size())},
    CPP_DEM_CONTACT_LAWS(CPP_DEM_LAW_ROW)
#undef CPP_DEM_LAW_ROW
};

#define CPP_DEM_LAW_FIT(id, name, part)                                                 \
  static_assert(law_fields_fit<part>(), name ": its kFields must fill Material::law_params " \
                "slots 0, 1, ... in order, each with a default (raise kLawParamSlots in "  \
                "laws/fields.hpp for more)");
CPP_DEM_CONTACT_LAWS(CPP_DEM_LAW_FIT)
#undef CPP_DEM_LAW_FIT

/// The row of law m.
inline const LawInfo& law_info(ContactModel m) {
  for (const LawInfo& l : kLaws)
    if (l.id == m) return l;
  throw ParameterError("model=" + std::to_string(static_cast<int>(m)) + ": no such contact law");
}

/// The law called `name`; ParameterError naming the known laws otherwise.
inline ContactModel law_by_name(const std::string& name) {
  std::string known;
  for (const LawInfo& l : kLaws) {
    if (name == l.name) return l.id;
    known += std::string(known.empty() ? "'" : ", '") + l.name + "'";
  }
  throw ParameterError("model='" + name + "': must be one of " + known);
}

/// The contact's law has a short kernel and neither dashpots nor rolling resistance: the pair
/// and wall passes run the short kernel (linear_frictional), which is the composed law
/// (apply_law) with those parts off.
inline bool short_kernel_applies(const ContactPhys& p) {
  return law_info(p.model).short_kernel && !(p.beta_n > 0) && !(p.beta_s > 0) && !(p.kr > 0);
}

/// The kernel the pair pass runs for a sphere–sphere contact (PairContact::kernel): the
/// linear short kernel (short_kernel_applies), the Hertz–Mindlin one (hertz_frictional: the
/// law without dashpots or rolling resistance), or the composed law (apply_law). The short
/// kernels do the composed law's operations in its order: the same bits.
/// kHertzDampedKernel: the Hertz–Mindlin law with dashpots (hertz_damped), no rolling.
enum PairKernel : std::uint8_t {
  kComposedKernel = 0,
  kLinearKernel = 1,
  kHertzKernel = 2,
  kHertzDampedKernel = 3
};

inline std::uint8_t pair_kernel(const ContactPhys& p) {
  if (short_kernel_applies(p)) return kLinearKernel;
  if (p.model == ContactModel::HertzMindlin && !(p.kr > 0))
    return !(p.beta_n > 0) && !(p.beta_s > 0) ? kHertzKernel : kHertzDampedKernel;
  return kComposedKernel;
}

}  // namespace cpp_dem
