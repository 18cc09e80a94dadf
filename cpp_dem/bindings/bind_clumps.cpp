// Bindings of the clump part of the scene. Type conversion only. Quaternions are (w, x, y, z).
#include <pybind11/stl.h>

#include "convert.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem::bind {

namespace {
Quat to_quat(const Array& a, const char* field) {
  if (a.ndim() != 1 || a.shape(0) != 4)
    throw ParameterError(std::string(field) + ": expected 4 values (w, x, y, z)");
  return Quat(a.at(0), a.at(1), a.at(2), a.at(3));
}
py::array_t<double> quat_array(const std::vector<Quat>& v) {
  py::array_t<double> out({static_cast<py::ssize_t>(v.size()), py::ssize_t(4)});
  auto r = out.mutable_unchecked<2>();
  for (size_t k = 0; k < v.size(); ++k) {
    r(k, 0) = v[k].w(); r(k, 1) = v[k].x(); r(k, 2) = v[k].y(); r(k, 3) = v[k].z();
  }
  return out;
}
}  // namespace

void bind_clumps(py::module_& m) {
  auto cls = py::reinterpret_borrow<py::class_<Scene>>(m.attr("Scene"));
  cls.def("_add_clump",
          [](Scene& s, const Array& local, const Array& radius, int material, double mass,
             const Array& inertia, const Array& com, const Array& ori, double stiffness_radius) {
            return s.add_clump(to_vec3_list(local, "members"), to_real_list(radius, "radii"),
                               material, mass, to_vec3(inertia, "inertia"), to_vec3(com, "position"),
                               to_quat(ori, "orientation"), stiffness_radius);
          },
          py::arg("local"), py::arg("radius"), py::arg("material"), py::arg("mass"),
          py::arg("inertia"), py::arg("com"), py::arg("ori"), py::arg("stiffness_radius") = 0.0)
      .def_property_readonly("clump_stiffness_radii",
                             [](const Scene& s) { return real_array(s.clumps().stiffness_radius); },
                             "Radius each clump's members take for their contact stiffness, m "
                             "(0: their own radii), shape (c,).")
      .def_property_readonly("num_clumps", &Scene::num_clumps)
      .def("clump_members", &Scene::clump_members, py::arg("clump"),
           "Body ids of a clump's member spheres.")
      .def_property_readonly("clump_ids", [](const Scene& s) { return s.by_id(s.clumps_of_bodies()); },
                             "Per body: the index of its clump, -1 for a free body, shape (n,).")
      .def_property_readonly("clump_positions", [](const Scene& s) { return vec3_array(s.clumps().pos); },
                             "Clump centres of mass, m, shape (c, 3).")
      .def_property_readonly("clump_velocities", [](const Scene& s) { return vec3_array(s.clumps().vel); },
                             "Clump velocities (last half step), m/s, shape (c, 3).")
      .def_property_readonly("clump_angular_velocities",
                             [](const Scene& s) { return vec3_array(s.clumps().angvel); },
                             "Clump spins (global frame, last half step), rad/s, shape (c, 3).")
      .def_property_readonly("clump_angular_momenta",
                             [](const Scene& s) { return vec3_array(s.clumps().angmom); },
                             "Clump angular momenta about their centres (global), kg m^2/s, shape (c, 3).")
      .def_property_readonly("clump_orientations", [](const Scene& s) { return quat_array(s.clumps().ori); },
                             "Clump orientations, principal frame -> global, (w, x, y, z), shape (c, 4).")
      .def_property_readonly("clump_forces", [](const Scene& s) { return vec3_array(s.clumps().force); },
                             "Resultant force on each clump in the last step, N, shape (c, 3).")
      .def_property_readonly("clump_torques", [](const Scene& s) { return vec3_array(s.clumps().torque); },
                             "Resultant torque about each centre of mass in the last step, N m, shape (c, 3).")
      .def_property_readonly("clump_masses", [](const Scene& s) { return real_array(s.clumps().mass); },
                             "Clump masses, kg, shape (c,).")
      .def_property_readonly("clump_inertias", [](const Scene& s) { return vec3_array(s.clumps().inertia); },
                             "Principal moments of inertia, kg m^2, shape (c, 3).")
      .def_property_readonly("clump_kinetic_energies", [](const Scene& s) {
        // (zero until the scene tracks energy: the accumulators are allocated then)
        const auto& ke = s.clumps().ke;
        return real_array(ke.empty() ? std::vector<Real>(s.clumps().size(), 0.0) : ke);
      },
                             "Kinetic energy of each clump at the last step (with track_energy), J.")
      .def("set_clump_state",
           [](Scene& s, int c, const Array& pos, const Array& ori, const Array& vel, const Array& w) {
             s.set_clump_state(c, to_vec3(pos, "position"), to_quat(ori, "orientation"),
                               to_vec3(vel, "velocity"), to_vec3(w, "angular_velocity"));
           },
           py::arg("clump"), py::arg("position"), py::arg("orientation"), py::arg("velocity"),
           py::arg("angular_velocity"))
      .def("_set_clump_blocked", &Scene::set_clump_blocked, py::arg("clump"), py::arg("mask"))
      .def_property_readonly("_clump_blocked", [](const Scene& s) { return s.clumps().blocked; })
      .def_property("clump_rotation",
                    [](const Scene& s) { return s.clump_rotation() == ClumpRotation::Yade ? "yade" : "fincham"; },
                    [](Scene& s, const std::string& v) {
                      if (v == "fincham") s.set_clump_rotation(ClumpRotation::Fincham);
                      else if (v == "yade") s.set_clump_rotation(ClumpRotation::Yade);
                      else throw ParameterError("clump_rotation='" + v + "': must be 'fincham' (default, "
                                                "second order) or 'yade' (Yade 2023's first-order variant)");
                    },
                    "Rotation update of clumps: 'fincham' (default) or 'yade' (see docs/clumps.md).")
      .def("set_clump_external",
           [](Scene& s, int c, const Array& f, const Array& t) {
             s.set_clump_external(c, to_vec3(f, "force"), to_vec3(t, "torque"));
           },
           py::arg("clump"), py::arg("force"), py::arg("torque"),
           "Imposed force (N) and torque (N m, about the centre of mass) on a clump.");
}

}  // namespace cpp_dem::bind
