// Bindings of the geogrid part of the scene. Type conversion only.
#include <pybind11/stl.h>

#include "convert.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem::bind {

namespace {
template <class F>
py::array_t<double> per_link(const Scene& s, F f) {
  std::vector<Real> v;
  v.reserve(s.grid_links().size());
  for (const GridLink& l : s.grid_links()) v.push_back(f(l));
  return real_array(v);
}
template <class F>
py::array_t<double> per_link3(const Scene& s, F f) {
  std::vector<Vec3> v;
  v.reserve(s.grid_links().size());
  for (const GridLink& l : s.grid_links()) v.push_back(f(l));
  return vec3_array(v);
}
}  // namespace

void bind_grid(py::module_& m) {
  py::class_<BeamParams>(m, "BeamParams", R"doc(
Cohesive beam between two grid nodes (000 eqs 7–12). SI units.

young : E of the geogrid, Pa.  poisson : nu, -.  radius : R_c of the cylinder, m.
normal_cohesion : tensile strength sigma_n^max, Pa (0: unbreakable).
shear_cohesion : shear strength, Pa (0: unbreakable).
Stiffnesses: k_n = E pi R^2 / L, k_s = 12 E I / L^3, k_r = E I / L, k_tw = G J / L.
Limits: F_n^max = sigma_n^max pi R^2, F_s^max = tau^max pi R^2 (the link breaks),
M_r^max = 4 sigma_n^max I / R, M_tw^max = 2 sigma_n^max J / R (plastic caps).
)doc")
      .def(py::init([](double young, double poisson, double radius, double normal_cohesion,
                       double shear_cohesion) {
             BeamParams p;
             p.young = young;
             p.poisson = poisson;
             p.radius = radius;
             p.normal_cohesion = normal_cohesion;
             p.shear_cohesion = shear_cohesion;
             p.validate();
             return p;
           }),
           py::kw_only(), py::arg("young"), py::arg("poisson"), py::arg("radius"),
           py::arg("normal_cohesion") = 0.0, py::arg("shear_cohesion") = 0.0)
      .def_readonly("young", &BeamParams::young)
      .def_readonly("poisson", &BeamParams::poisson)
      .def_readonly("radius", &BeamParams::radius)
      .def_readonly("normal_cohesion", &BeamParams::normal_cohesion)
      .def_readonly("shear_cohesion", &BeamParams::shear_cohesion);

  auto cls = py::reinterpret_borrow<py::class_<Scene>>(m.attr("Scene"));
  cls.def("_add_grid_nodes",
          [](Scene& s, const Array& pos, double radius, const Array& mass, const Array& inertia,
             int material) {
            return s.add_grid_nodes(to_vec3_list(pos, "positions"), radius,
                                    to_real_list(mass, "mass"), to_real_list(inertia, "inertia"),
                                    material);
          },
          py::arg("positions"), py::arg("radius"), py::arg("mass"), py::arg("inertia"),
          py::arg("material"))
      .def("add_grid_link", &Scene::add_grid_link, py::arg("a"), py::arg("b"), py::arg("params"),
           py::arg("material"), "Cohesive link + connection cylinder between nodes a and b.")
      .def("add_pfacet", &Scene::add_pfacet, py::arg("n0"), py::arg("n1"), py::arg("n2"),
           py::arg("l01"), py::arg("l12"), py::arg("l20"), py::arg("material"),
           "PFacet on three nodes joined by three existing links.")
      .def("set_mass_inertia", &Scene::set_mass_inertia, py::arg("body"), py::arg("mass"),
           py::arg("inertia"), "Sets a body's mass (kg) and inertia (kg m^2).")
      .def_property("grid_wall_contacts", &Scene::grid_wall_contacts,
                    &Scene::set_grid_wall_contacts,
                    "Grid nodes touch walls (as spheres of radius R_c) when True; default False.")
      .def_property_readonly("num_grid_links", &Scene::num_grid_links)
      .def_property_readonly("num_pfacets", &Scene::num_pfacets)
      .def_property_readonly("body_kinds", [](const Scene& s) {
        const auto k = s.by_id(s.body_kinds());
        return std::vector<int>(k.begin(), k.end());
      }, "0 sphere, 1 grid node, per body.")
      .def_property_readonly("grid_link_nodes", [](const Scene& s) {
        py::array_t<int> out({static_cast<py::ssize_t>(s.num_grid_links()), py::ssize_t(2)});
        auto r = out.mutable_unchecked<2>();
        for (int k = 0; k < s.num_grid_links(); ++k) {
          r(k, 0) = s.grid_links()[k].a;
          r(k, 1) = s.grid_links()[k].b;
        }
        return out;
      }, "Node ids of each link, shape (n_links, 2).")
      .def_property_readonly("pfacet_nodes", [](const Scene& s) {
        py::array_t<int> out({static_cast<py::ssize_t>(s.num_pfacets()), py::ssize_t(3)});
        auto r = out.mutable_unchecked<2>();
        for (int k = 0; k < s.num_pfacets(); ++k)
          for (int i = 0; i < 3; ++i) r(k, i) = s.pfacets()[k].n[i];
        return out;
      }, "Node ids of each PFacet, shape (n_pfacets, 3).")
      .def_property_readonly("grid_link_axial_forces",
                             [](const Scene& s) { return per_link(s, [](const GridLink& l) { return l.broken ? 0.0 : l.fn; }); },
                             "Axial force of each link, N, tension positive (0 once broken).")
      .def_property_readonly("grid_link_shear_forces",
                             [](const Scene& s) { return per_link3(s, [](const GridLink& l) { return l.fs; }); },
                             "Shear force on node b of each link, N, shape (n_links, 3).")
      .def_property_readonly("grid_link_bending_moments",
                             [](const Scene& s) { return per_link3(s, [](const GridLink& l) { return l.mb; }); },
                             "Bending moment on node b, N m, shape (n_links, 3).")
      .def_property_readonly("grid_link_twisting_moments",
                             [](const Scene& s) { return per_link(s, [](const GridLink& l) { return l.mt; }); },
                             "Twisting moment on node b about the link axis, N m.")
      .def_property_readonly("grid_link_radii",
                             [](const Scene& s) { return per_link(s, [](const GridLink& l) { return l.radius; }); },
                             "Cylinder radius R_c of each link, m.")
      .def_property_readonly("grid_link_rest_lengths",
                             [](const Scene& s) { return per_link(s, [](const GridLink& l) { return l.length0; }); },
                             "Initial length of each link, m.")
      .def_property_readonly("grid_link_stiffness",
                             [](const Scene& s) {
                               py::array_t<double> out({static_cast<py::ssize_t>(s.num_grid_links()), py::ssize_t(4)});
                               auto r = out.mutable_unchecked<2>();
                               for (int k = 0; k < s.num_grid_links(); ++k) {
                                 const GridLink& l = s.grid_links()[k];
                                 r(k, 0) = l.kn; r(k, 1) = l.ks; r(k, 2) = l.kr; r(k, 3) = l.ktw;
                               }
                               return out;
                             }, "k_n (N/m), k_s (N/m), k_r (N m/rad), k_tw (N m/rad) per link.")
      .def_property_readonly("grid_link_broken", [](const Scene& s) {
        std::vector<bool> v;
        for (const GridLink& l : s.grid_links()) v.push_back(l.broken);
        return v;
      })
      .def_property_readonly("grid_break_events", [](const Scene& s) {
        py::list out;
        for (const BreakEvent& e : s.break_events()) {
          py::dict d;
          d["step"] = e.step;
          d["time"] = e.time;
          d["link"] = e.link;
          d["reason"] = e.reason == 0 ? "tension" : "shear";
          d["force"] = e.force;
          out.append(d);
        }
        return out;
      }, "Links that broke: step, time (s), link, reason, force (N).")
      .def("grid_contacts", [](const Scene& s) {
        std::vector<int> sphere, kind, prim;
        std::vector<Vec3> force, normal;
        std::vector<Real> overlap;
        for (const GridContact& c : s.grid_contacts()) {
          if (!c.active) continue;
          sphere.push_back(s.id_of(c.sphere));
          kind.push_back(static_cast<int>(c.kind));
          prim.push_back(c.prim);
          force.push_back(c.force);
          normal.push_back(c.state.normal);
          overlap.push_back(c.state.overlap);
        }
        py::dict d;
        d["sphere"] = sphere;
        d["kind"] = kind;
        d["primitive"] = prim;
        d["force"] = vec3_array(force);
        d["normal"] = vec3_array(normal);
        d["overlap"] = real_array(overlap);
        return d;
      }, "Active grain–geogrid contacts: sphere, kind (0 node, 1 connection, 2 pfacet), "
         "primitive index, force on the grain (N), normal, overlap (m).");
}

}  // namespace cpp_dem::bind
