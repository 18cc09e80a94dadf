// Bindings of bonds between spheres (laws/bond.hpp). Type conversion only.
#include <pybind11/stl.h>

#include "convert.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem::bind {

namespace {
const char* const kModeNames[] = {"contact_tension", "contact_shear", "parallel_tension",
                                  "parallel_shear"};
}  // namespace

void bind_bonds(py::module_& m) {
  py::class_<BondParams>(m, "BondParams", R"doc(
A bond between two spheres as PFC defines it (linear contact bond and linear parallel bond;
Potyondy & Cundall 2004). SI units; a strength of 0 means unbreakable.

Linear contact (always): kn, ks (N/m), friction (Coulomb mu, -). It acts when the surface gap
is below the gap at bonding (the reference gap).
Contact bond (contact_bond=True): the linear contact carries tension and does not slip until
its normal force reaches cb_tensile (N) or its shear force cb_shear (N).
Parallel bond (pb_kn > 0): a disc of radius R_bar = pb_radius_factor * min(R_a, R_b) with
normal and shear stiffness per area pb_kn, pb_ks (Pa/m): axial k = pb_kn A, shear k = pb_ks A,
twisting k = pb_ks J, bending k = pb_kn I (A = pi R_bar^2, I = pi R_bar^4/4, J = 2 I).
It breaks when sigma = F_n/A + |M_b| R_bar/I >= pb_tensile (Pa) or
tau = |F_s|/A + |M_t| R_bar/J >= pb_shear (Pa).
)doc")
      .def(py::init([](double kn, double ks, double friction, bool contact_bond,
                       double cb_tensile, double cb_shear, double pb_kn, double pb_ks,
                       double pb_radius_factor, double pb_tensile, double pb_shear) {
             BondParams p;
             p.kn = kn;
             p.ks = ks;
             p.friction = friction;
             p.contact_bond = contact_bond;
             p.cb_tensile = cb_tensile;
             p.cb_shear = cb_shear;
             p.pb_kn = pb_kn;
             p.pb_ks = pb_ks;
             p.pb_radius_factor = pb_radius_factor;
             p.pb_tensile = pb_tensile;
             p.pb_shear = pb_shear;
             p.validate();
             return p;
           }),
           py::kw_only(), py::arg("kn"), py::arg("ks") = 0.0, py::arg("friction") = 0.0,
           py::arg("contact_bond") = false, py::arg("cb_tensile") = 0.0,
           py::arg("cb_shear") = 0.0, py::arg("pb_kn") = 0.0, py::arg("pb_ks") = 0.0,
           py::arg("pb_radius_factor") = 1.0, py::arg("pb_tensile") = 0.0,
           py::arg("pb_shear") = 0.0)
      .def_readonly("kn", &BondParams::kn)
      .def_readonly("ks", &BondParams::ks)
      .def_readonly("friction", &BondParams::friction)
      .def_readonly("contact_bond", &BondParams::contact_bond)
      .def_readonly("cb_tensile", &BondParams::cb_tensile)
      .def_readonly("cb_shear", &BondParams::cb_shear)
      .def_readonly("pb_kn", &BondParams::pb_kn)
      .def_readonly("pb_ks", &BondParams::pb_ks)
      .def_readonly("pb_radius_factor", &BondParams::pb_radius_factor)
      .def_readonly("pb_tensile", &BondParams::pb_tensile)
      .def_readonly("pb_shear", &BondParams::pb_shear);

  auto cls = py::reinterpret_borrow<py::class_<Scene>>(m.attr("Scene"));
  cls.def("add_bond", &Scene::add_bond, py::arg("a"), py::arg("b"), py::arg("params"),
          "Bonds spheres a and b (ids), unloaded at their present distance; returns the "
          "bond's index.")
      .def_property_readonly("num_bonds", &Scene::num_bonds)
      .def_property_readonly("bond_spheres", [](const Scene& s) {
        py::array_t<int> out({static_cast<py::ssize_t>(s.num_bonds()), py::ssize_t(2)});
        auto r = out.mutable_unchecked<2>();
        for (int k = 0; k < s.num_bonds(); ++k) {
          r(k, 0) = s.id_of(s.bonds()[k].a);
          r(k, 1) = s.id_of(s.bonds()[k].b);
        }
        return out;
      }, "Sphere ids (a, b) of each bond, shape (n_bonds, 2).")
      .def("bond_state", [](const Scene& s) {
        const auto& bs = s.bonds();
        const size_t n = bs.size();
        std::vector<Real> fn(n), pb_fn(n), pb_mt(n), sigma(n), tau(n), rbar(n), gap0(n);
        std::vector<Real> k_normal(n), k_shear(n), k_bend(n), k_twist(n), friction(n);
        std::vector<Vec3> fs(n), pb_fs(n), pb_mb(n), force(n), normal(n);
        std::vector<bool> cb(n), pb(n);
        for (size_t k = 0; k < n; ++k) {
          const Bond& l = bs[k];
          fn[k] = l.fn;
          fs[k] = l.fs;
          pb_fn[k] = l.pb_fn;
          pb_fs[k] = l.pb_fs;
          pb_mt[k] = l.pb_mt;
          pb_mb[k] = l.pb_mb;
          sigma[k] = l.pb_intact ? l.pb_sigma() : 0.0;
          tau[k] = l.pb_intact ? l.pb_tau() : 0.0;
          rbar[k] = l.pb_radius;
          gap0[k] = l.gap0;
          force[k] = l.force_b;
          normal[k] = l.normal;
          cb[k] = l.cb_intact;
          pb[k] = l.pb_intact;
          l.stiffness(k_normal[k], k_shear[k]);
          k_bend[k] = l.pb_intact ? l.pb_kn * l.pb_i : 0.0;
          k_twist[k] = l.pb_intact ? l.pb_ks * l.pb_j : 0.0;
          friction[k] = l.tan_phi;
        }
        py::dict d;
        d["contact_bond"] = cb;
        d["parallel_bond"] = pb;
        d["normal_force"] = real_array(fn);
        d["shear_force"] = vec3_array(fs);
        d["pb_normal_force"] = real_array(pb_fn);
        d["pb_shear_force"] = vec3_array(pb_fs);
        d["pb_twisting_moment"] = real_array(pb_mt);
        d["pb_bending_moment"] = vec3_array(pb_mb);
        d["pb_sigma"] = real_array(sigma);
        d["pb_tau"] = real_array(tau);
        d["pb_radius"] = real_array(rbar);
        d["reference_gap"] = real_array(gap0);
        d["force"] = vec3_array(force);
        d["normal"] = vec3_array(normal);
        d["normal_stiffness"] = real_array(k_normal);
        d["shear_stiffness"] = real_array(k_shear);
        d["bending_stiffness"] = real_array(k_bend);
        d["twisting_stiffness"] = real_array(k_twist);
        d["friction"] = real_array(friction);
        return d;
      }, R"doc(Every bond's state, arrays in bond order:
contact_bond, parallel_bond: the parts that still hold (bool);
normal_force: the linear contact's normal force, N, compression positive; shear_force (n, 3):
its shear force on b, N; pb_normal_force: the parallel bond's, N, tension positive;
pb_shear_force (n, 3), N; pb_twisting_moment (about the normal), N m; pb_bending_moment (n, 3),
N m, all on b; pb_sigma, pb_tau: the parallel bond's rim stresses, Pa (0 once broken);
pb_radius: R_bar, m; reference_gap, m; force (n, 3): the bond's total force on b, N (a gets
the opposite); normal (n, 3): unit a -> b; normal_stiffness, shear_stiffness: the springs
acting now along and across the normal at the contact point, N/m (the linear contact's, when
bonded or pressed, plus the intact parallel bond's k_bar A); bending_stiffness,
twisting_stiffness: the intact parallel bond's k_bar_n I and k_bar_s J, N m/rad (0 once
broken); friction: the linear contact's Coulomb mu, -.)doc")
      .def_property_readonly("bond_breaks", [](const Scene& s) {
        py::list out;
        for (const BondBreak& e : s.bond_breaks()) {
          py::dict d;
          d["step"] = e.step;
          d["time"] = e.time;
          d["bond"] = e.bond;
          d["mode"] = kModeNames[e.mode];
          d["value"] = e.value;
          out.append(d);
        }
        return out;
      }, "Bond parts that broke, in order: step, time (s), bond, mode ('contact_tension', "
         "'contact_shear', 'parallel_tension', 'parallel_shear'), value (N for a contact "
         "bond, Pa for a parallel bond).");
}

}  // namespace cpp_dem::bind
