#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "convert.hpp"
#include "cpp_dem/laws/registry.hpp"

namespace cpp_dem::bind {

namespace {

/// Material's docstring: every law's parameters from the field list.
std::string material_docstring() {
  std::string doc =
      "Elastic-frictional material (immutable; SI units).\n\n"
      "Parameters (keywords only; cpp_dem.material_fields(model) lists them)\n"
      "----------\n"
      "model : a law of the registry (cpp_dem.contact_laws()), default 'linear'.\n";
  const auto line = [&](const FieldInfo& f, const std::string& law) {
    doc += std::string(f.name) + " : " + f.doc + "; " + f.unit + "; " + f.range() +
           (f.required() ? "; required" : "; default " + fmt_real(f.fallback)) + law + ".\n";
  };
  for (const FieldInfo& f : kMaterialFields) line(f, "");
  for (const LawInfo& law : kLaws)
    for (int k = 0; k < law.n_fields; ++k)
      line(law.fields[k], std::string(" (the '") + law.name + "' law only)");
  return doc;
}

/// Edit distance of two names (the suggestion for a misspelt keyword).
size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

/// The law named by a Python value given as model= (a str naming a law), or ParameterError.
ContactModel law_of(const py::object& model) {
  if (!py::isinstance<py::str>(model))
    throw ParameterError("model=" + py::repr(model).cast<std::string>() +
                         ": must be the name of a law (cpp_dem.contact_laws())");
  return law_by_name(model.cast<std::string>());
}

/// A material from keywords: model (a law's name), then the parameters of its field list.
Material make_material(const py::dict& kw) {
  py::object model = kw.contains("model") ? py::object(kw["model"]) : py::object(py::str("linear"));
  Material mat = Material::of_law(law_of(model));
  const auto fields = material_fields(mat.model);
  std::vector<bool> given(fields.size(), false);
  for (auto item : kw) {
    const std::string key = py::str(item.first);
    if (key == "model") continue;
    const size_t i = field_index(fields, key);
    if (i == fields.size()) {
      std::string allowed, other;
      size_t best = key.size() / 3 + 2;  // (a suggestion within a third of the name's letters)
      for (const FieldInfo* f : fields) {
        allowed += std::string(allowed.empty() ? "" : ", ") + f->name;
        const size_t d = edit_distance(key, f->name);
        if (d < best) {
          best = d;
          other = std::string(" (did you mean ") + f->name + "?)";
        }
      }
      for (const LawInfo& law : kLaws)
        for (int k = 0; k < law.n_fields; ++k)
          if (key == law.fields[k].name)
            other = std::string(" (a parameter of the '") + law.name + "' law)";
      throw ParameterError(key + "=" + py::repr(item.second).cast<std::string>() +
                           ": not a parameter of a '" + law_info(mat.model).name +
                           "' material; allowed: " + allowed + other);
    }
    const double v = number_arg(item.second, fields[i]->name, fields[i]->unit);
    field_value(mat, *fields[i]) = fields[i]->to_stored(v);
    given[i] = true;
  }
  for (size_t i = 0; i < fields.size(); ++i)
    if (!given[i] && fields[i]->required())
      throw ParameterError(std::string("Material: ") + fields[i]->name + " is required (" +
                           fields[i]->unit + ")");
  mat.validate();
  return mat;
}

py::dict as_dict(const Material& s) {
  py::dict out;
  out["model"] = law_info(s.model).name;
  for (const FieldInfo* f : material_fields(s.model))
    out[f->name] = f->to_python(field_value(s, *f));
  return out;
}

/// A pickled material: (2, law name, {parameter: stored value}); also the 9-tuple of the builds
/// before the field list (law name and the 8 shared parameters, stored values).
Material unpickle_material(const py::tuple& t) {
  if (t.size() == 9) {
    Material mat = Material::of_law(law_by_name(t[0].cast<std::string>()));
    Real* legacy[] = {&mat.density, &mat.young, &mat.poisson, &mat.friction_angle,
                      &mat.damping_normal, &mat.damping_shear, &mat.rolling_stiffness,
                      &mat.rolling_friction};
    for (int k = 0; k < 8; ++k) *legacy[k] = t[k + 1].cast<double>();
    mat.validate();
    return mat;
  }
  if (t.size() != 3 || t[0].cast<int>() != 2)
    throw std::runtime_error("Material: bad pickled state");
  Material mat = Material::of_law(law_by_name(t[1].cast<std::string>()));
  const py::dict stored = t[2].cast<py::dict>();
  const auto fields = material_fields(mat.model);
  for (auto item : stored) {
    const std::string key = py::str(item.first);
    const size_t i = field_index(fields, key);
    if (i == fields.size())
      throw std::runtime_error("Material: pickled parameter '" + key + "' unknown");
    field_value(mat, *fields[i]) = item.second.cast<double>();
  }
  mat.validate();
  return mat;
}

}  // namespace

void bind_material(py::module_& m) {
  // The laws of the registry (laws/law_list.hpp): their ids and names.
  py::enum_<ContactModel> model_enum(m, "ContactModel");
  for (const LawInfo& law : kLaws) model_enum.value(law.name, law.id);
  m.def("contact_laws", [] {
    py::list out;
    for (const LawInfo& law : kLaws) {
      py::dict row;
      row["name"] = law.name;
      row["summary"] = law.summary;
      row["short_kernel"] = law.short_kernel;
      out.append(row);
    }
    return out;
  }, "The contact laws of the registry: name, summary, whether the hot loops have a short kernel.");

  // Material: its keywords, attributes, repr, pickle and replace all come from the field list
  // (material_fields: the shared parameters, then the law's own; laws/fields.hpp).
  static const std::string material_doc = material_docstring();
  py::class_<Material> cls(m, "Material", material_doc.c_str());
  cls.def(py::init([](const py::kwargs& kw) { return make_material(kw); }),
          "Material(*, model='linear', density, young, poisson, friction_angle_deg, ...): "
          "the parameters of cpp_dem.material_fields(model), by keyword.")
      .def_property_readonly("model", [](const Material& s) { return law_info(s.model).name; })
      .def_property_readonly("shear_modulus", &Material::shear_modulus, "Pa")
      .def("as_dict", &as_dict,
           "{'model': name, parameter: value, ...}: every parameter of this material, in the "
           "units of its keyword (material_fields).")
      .def("replace", [](const Material& s, const py::kwargs& changes) {
             py::dict kw;
             const py::object name = py::str(law_info(s.model).name);
             const bool same_law =
                 !changes.contains("model") || py::object(changes["model"]).equal(name);
             for (const FieldInfo* f : material_fields(s.model))
               if (same_law || f->member) kw[f->name] = f->to_python(field_value(s, *f));
             kw["model"] = law_info(s.model).name;
             for (auto item : changes) kw[item.first] = item.second;
             return make_material(kw);
           },
           "A copy with the given parameters changed (checked as Material(...) checks them); "
           "a new model keeps the shared parameters and takes that law's own defaults.")
      // Pickled exactly (stored values: the friction angle in radians), so that a material
      // reaches Dask workers and process pools bitwise.
      .def(py::pickle(
          [](const Material& s) {
            py::dict stored;
            for (const FieldInfo* f : material_fields(s.model))
              stored[f->name] = field_value(s, *f);
            return py::make_tuple(2, std::string(law_info(s.model).name), stored);
          },
          [](const py::tuple& t) { return unpickle_material(t); }))
      .def("__repr__", [](const Material& s) {
        std::string out = std::string("Material(model='") + law_info(s.model).name + "'";
        for (const FieldInfo* f : material_fields(s.model)) {
          const Real v = f->to_python(field_value(s, *f));
          if (f->required() || !(v == f->fallback))
            out += std::string(", ") + f->name + "=" + fmt_real(v);
        }
        return out + ")";
      });
  // One read-only attribute per parameter of any law.
  std::vector<std::string> names;
  const auto add_attribute = [&](const FieldInfo& f) {
    if (std::find(names.begin(), names.end(), f.name) != names.end()) return;
    names.push_back(f.name);
    const std::string key = f.name;
    cls.def_property_readonly(
        f.name,
        [key](const Material& s) -> double {
          for (const FieldInfo* g : material_fields(s.model))
            if (key == g->name) return g->to_python(field_value(s, *g));
          throw py::attribute_error("Material: a '" + std::string(law_info(s.model).name) +
                                    "' material has no parameter '" + key + "'");
        },
        (std::string(f.unit) + "; " + f.doc).c_str());
  };
  for (const FieldInfo& f : kMaterialFields) add_attribute(f);
  for (const LawInfo& law : kLaws)
    for (int k = 0; k < law.n_fields; ++k) add_attribute(law.fields[k]);

  m.def("material_fields", [](const py::object& model) {
          py::list out;
          for (const FieldInfo* f : material_fields(law_of(model))) {
            py::dict row;
            row["name"] = f->name;
            row["unit"] = f->unit;
            row["doc"] = f->doc;
            row["default"] = f->required() ? py::object(py::none()) : py::float_(f->fallback);
            row["allowed"] = f->range();
            row["lo"] = f->lo;
            row["lo_closed"] = f->lo_closed;
            row["hi"] = f->hi;
            row["hi_closed"] = f->hi_closed;
            row["law_owned"] = f->member == nullptr;
            out.append(row);
          }
          return out;
        }, py::arg("model") = py::str("linear"),
        "The parameters of a material of law `model`: name, unit, doc, default (None: "
        "required), allowed (the range as text) and its bounds lo, hi (-inf, inf: none) with "
        "lo_closed, hi_closed, law_owned (the law's own, or shared by every law).");

  py::class_<ContactPhys>(m, "ContactPhys", "Mixed parameters of one contact (read-only).")
      .def_property_readonly("model", [](const ContactPhys& p) {
        return law_info(p.model).name;
      })
      .def_readonly("kn", &ContactPhys::kn, "linear: N/m; Hertz: K in F = K d^1.5, N/m^1.5")
      .def_readonly("ks", &ContactPhys::ks, "linear: N/m; Mindlin: C in k_t = C d^0.5")
      .def_readonly("tan_phi", &ContactPhys::tan_phi)
      .def_readonly("beta_n", &ContactPhys::beta_n)
      .def_readonly("beta_s", &ContactPhys::beta_s)
      .def_readonly("mass_eff", &ContactPhys::mass_eff, "kg")
      .def_readonly("kr", &ContactPhys::kr, "N m/rad")
      .def_readonly("rolling_cap", &ContactPhys::rolling_cap, "m");

  m.def("mix_materials",
        [](const Material& a, const Material& b, Real r1, Real r2, Real m1, Real m2) {
          return mix_materials(a, b, r1, r2, m1, m2);
        },
        py::arg("a"), py::arg("b"), py::arg("r1"),
        py::arg("r2"), py::arg("m1"), py::arg("m2"),
        "Contact parameters of two materials with radii r1, r2 (m) and masses m1, m2 (kg).");
}

}  // namespace cpp_dem::bind
