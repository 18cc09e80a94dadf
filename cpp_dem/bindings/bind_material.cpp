#include <cmath>

#include "convert.hpp"
#include "cpp_dem/laws/registry.hpp"

namespace cpp_dem::bind {

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

  py::class_<Material>(m, "Material", R"doc(
Elastic-frictional material (immutable; SI units).

Parameters
----------
model : a law of the registry (cpp_dem.contact_laws()): "linear" (Cundall–Strack, 000 eqs
    1–6) or "hertz_mindlin".
density : mass density, kg/m^3 (> 0).
young : Young's modulus E, Pa (> 0).
poisson : Poisson's ratio nu, -. For the linear law this is k_s/k_n (000 eq 5), in (0, 0.5];
    for Hertz–Mindlin, in (-1, 0.5].
friction_angle_deg : contact friction angle, degrees, in [0, 90).
damping_normal, damping_shear : viscous contact damping, ratio of critical, in [0, 1].
rolling_stiffness : beta_r, -; k_r = beta_r k_s R*^2 (0: no rolling resistance).
rolling_friction : eta_r, -; |M_r| <= eta_r R* |F_n|.
)doc")
      // The arguments as Python objects, so that a string or a bool is refused naming the
      // parameter (not with pybind11's list of signatures).
      .def(py::init([](const py::object& model, const py::object& density,
                       const py::object& young, const py::object& poisson,
                       const py::object& friction_angle_deg, const py::object& damping_normal,
                       const py::object& damping_shear, const py::object& rolling_stiffness,
                       const py::object& rolling_friction) {
             if (!py::isinstance<py::str>(model))
               throw ParameterError("model=" + py::repr(model).cast<std::string>() +
                                    ": must be the name of a law (cpp_dem.contact_laws())");
             Material mat;
             mat.model = law_by_name(model.cast<std::string>());
             mat.density = number_arg(density, "density", "kg/m^3");
             mat.young = number_arg(young, "young", "Pa");
             mat.poisson = number_arg(poisson, "poisson", "-");
             mat.friction_angle =
                 number_arg(friction_angle_deg, "friction_angle_deg", "degrees") * M_PI / 180.0;
             mat.damping_normal = number_arg(damping_normal, "damping_normal", "ratio of critical");
             mat.damping_shear = number_arg(damping_shear, "damping_shear", "ratio of critical");
             mat.rolling_stiffness = number_arg(rolling_stiffness, "rolling_stiffness", "-");
             mat.rolling_friction = number_arg(rolling_friction, "rolling_friction", "-");
             mat.validate();
             return mat;
           }),
           py::kw_only(), py::arg("model") = py::str("linear"), py::arg("density"),
           py::arg("young"), py::arg("poisson"), py::arg("friction_angle_deg"),
           py::arg("damping_normal") = py::float_(0.0), py::arg("damping_shear") = py::float_(0.0),
           py::arg("rolling_stiffness") = py::float_(0.0),
           py::arg("rolling_friction") = py::float_(0.0))
      .def_property_readonly("model", [](const Material& s) {
        return law_info(s.model).name;
      })
      .def_readonly("density", &Material::density, "kg/m^3")
      .def_readonly("young", &Material::young, "Pa")
      .def_readonly("poisson", &Material::poisson, "-")
      .def_property_readonly("friction_angle_deg",
                             [](const Material& s) { return s.friction_angle * 180.0 / M_PI; })
      .def_readonly("damping_normal", &Material::damping_normal)
      .def_readonly("damping_shear", &Material::damping_shear)
      .def_readonly("rolling_stiffness", &Material::rolling_stiffness)
      .def_readonly("rolling_friction", &Material::rolling_friction)
      .def_property_readonly("shear_modulus", &Material::shear_modulus, "Pa")
      // Pickled exactly (the friction angle in radians, as stored), so that a material
      // reaches Dask workers and process pools bitwise.
      .def(py::pickle(
          [](const Material& s) {
            return py::make_tuple(std::string(law_info(s.model).name), s.density, s.young,
                                  s.poisson, s.friction_angle, s.damping_normal,
                                  s.damping_shear, s.rolling_stiffness, s.rolling_friction);
          },
          [](const py::tuple& t) {
            if (t.size() != 9) throw std::runtime_error("Material: bad pickled state");
            Material mat;
            mat.model = law_by_name(t[0].cast<std::string>());
            mat.density = t[1].cast<double>();
            mat.young = t[2].cast<double>();
            mat.poisson = t[3].cast<double>();
            mat.friction_angle = t[4].cast<double>();
            mat.damping_normal = t[5].cast<double>();
            mat.damping_shear = t[6].cast<double>();
            mat.rolling_stiffness = t[7].cast<double>();
            mat.rolling_friction = t[8].cast<double>();
            mat.validate();
            return mat;
          }))
      .def("__repr__", [](const Material& s) {
        return std::string("Material(model='") +
               law_info(s.model).name +
               "', density=" + fmt_real(s.density) + ", young=" + fmt_real(s.young) +
               ", poisson=" + fmt_real(s.poisson) +
               ", friction_angle_deg=" + fmt_real(s.friction_angle * 180.0 / M_PI) + ")";
      });

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
