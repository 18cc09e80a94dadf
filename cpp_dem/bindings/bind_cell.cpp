// Bindings of the periodic cell (bodies/cell.hpp) and its controller. Type conversion only.
#include <pybind11/stl.h>

#include "convert.hpp"
#include "cpp_dem/control/controllers.hpp"

namespace cpp_dem::bind {

namespace {
Mat3 to_mat3(const Array& a, const char* field) {
  if (a.ndim() != 2 || a.shape(0) != 3 || a.shape(1) != 3)
    throw ParameterError(std::string(field) + ": expected a 3 x 3 array");
  Mat3 m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m(r, c) = a.at(r, c);
  return m;
}

py::array_t<double> mat3_array(const Mat3& m) {
  py::array_t<double> out({py::ssize_t(3), py::ssize_t(3)});
  auto w = out.mutable_unchecked<2>();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) w(r, c) = m(r, c);
  return out;
}
}  // namespace

void bind_cell(py::module_& m) {
  py::object scene_cls = py::type::of<Scene>();
  const py::object property = py::module_::import("builtins").attr("property");
  auto method = [&](const char* name, py::cpp_function f) { scene_cls.attr(name) = f; };
  method("set_periodic_cell",
         py::cpp_function(
             [](Scene& s, const Array& h, std::array<bool, 3> periodic) {
               s.set_periodic_cell(to_mat3(h, "cell"), periodic);
             },
             py::name("set_periodic_cell"), py::is_method(scene_cls), py::arg("cell"),
             py::arg("periodic") = std::array<bool, 3>{true, true, true},
             "Makes the scene periodic along the axes marked in `periodic`, with cell vectors "
             "the columns of `cell` (3 x 3, m, det > 0); the cell is cell @ [0,1)^3."));
  scene_cls.attr("is_periodic") = property(
      py::cpp_function([](const Scene& s) { return s.is_periodic(); }), py::none(), py::none(),
      "The scene has a periodic cell.");
  scene_cls.attr("cell_matrix") = property(
      py::cpp_function([](const Scene& s) { return mat3_array(s.cell().h); }), py::none(),
      py::none(), "Cell vectors as columns, m (3 x 3).");
  scene_cls.attr("cell_reference") = property(
      py::cpp_function([](const Scene& s) { return mat3_array(s.cell().h_ref); }), py::none(),
      py::none(), "The cell vectors when the cell was set, m (3 x 3).");
  scene_cls.attr("cell_periodic") = property(
      py::cpp_function([](const Scene& s) { return s.cell().periodic; }), py::none(),
      py::none(), "Which axes repeat (x, y, z).");
  scene_cls.attr("cell_volume") = property(
      py::cpp_function([](const Scene& s) { return s.cell().volume(); }), py::none(),
      py::none(), "Cell volume, m^3.");
  scene_cls.attr("velocity_gradient") = property(
      py::cpp_function([](const Scene& s) { return mat3_array(s.cell().vel_grad); }),
      py::cpp_function([](Scene& s, const Array& l) {
        s.set_velocity_gradient(to_mat3(l, "velocity_gradient"));
      }),
      py::none(), "Imposed velocity gradient L of the periodic cell, 1/s (3 x 3).");
  scene_cls.attr("mean_spin") = property(
      py::cpp_function([](const Scene& s) { return s.cell().mean_spin; }),
      py::cpp_function([](Scene& s, bool on) { s.set_mean_spin(on); }), py::none(),
      "Bodies carry the mean spin axial(skew L) (default True; False as Yade).");
  method("cell_stress",
         py::cpp_function([](const Scene& s) { return mat3_array(s.cell_stress()); },
                          py::name("cell_stress"), py::is_method(scene_cls),
                          "Love–Weber stress of the pair contacts and the bonds over the cell volume, Pa, "
                          "compression positive, not symmetrised (3 x 3)."));
  scene_cls.attr("images") = property(
      py::cpp_function([](const Scene& s) {
        const auto im = s.by_id(s.body_images());
        py::array_t<int> out({static_cast<py::ssize_t>(im.size()), py::ssize_t(3)});
        if (!im.empty()) std::memcpy(out.mutable_data(), im.data(), im.size() * 3 * sizeof(int));
        return out;
      }),
      py::none(), py::none(),
      "Per body: cell vectors it was shifted by when wrapped into the cell (n, 3); the "
      "unwrapped position is pos + cell_matrix @ image.");

  py::class_<CellController, Controller, std::shared_ptr<CellController>>(m, "CellController",
      R"doc(
Mixed stress and strain-rate control of a periodic cell (Yade's PeriTriaxController, PFC's
periodic servo). Each component (r, c) of the velocity gradient L is imposed (set_rate, 1/s,
tension positive) or servo-controlled (set_stress: the cell stress sigma_rc, Pa, compression
positive, reaches the target). The servo's strain correction per call is
gain (target - sigma_rc) / C_rc, C_rc the affine stiffness of the contact network, spread over
`period` steps and capped to +-max_rate (1/s). Bonds in the cell (a sheet of bonded spheres)
count in sigma_rc and C_rc as in Scene.cell_stress.
)doc")
      .def(py::init<Real, Real>(), py::kw_only(), py::arg("gain") = 0.3,
           py::arg("max_rate") = 1.0)
      .def("set_rate", &CellController::set_rate, py::arg("r"), py::arg("c"), py::arg("rate"),
           "Imposes L_rc = rate (1/s).")
      .def("set_stress", &CellController::set_stress, py::arg("r"), py::arg("c"),
           py::arg("stress"), "Servo-controls sigma_rc to `stress` (Pa, compression positive).")
      .def("mode", [](const CellController& c, int r, int q) {
             return c.mode(r, q) == CellController::Mode::Stress ? "stress" : "rate";
           }, py::arg("r"), py::arg("c"))
      .def("goal", &CellController::goal, py::arg("r"), py::arg("c"),
           "The imposed rate (1/s) or the stress target (Pa) of component (r, c).")
      .def_property("gain", &CellController::gain, &CellController::set_gain)
      .def_property("allow_tension", &CellController::allow_tension,
                    &CellController::set_allow_tension,
                    "Tensile normal stress targets allowed (off by default): a cell whose "
                    "bonds hold the tension.")
      .def_property("max_rate", &CellController::max_rate, &CellController::set_max_rate,
                    "Cap on |L_rc| of the stress-controlled components, 1/s.")
      .def_property_readonly("measured_stress",
                             [](const CellController& c) { return mat3_array(c.measured_stress()); },
                             "Cell stress at the last call, Pa (compression positive).")
      .def_property_readonly("stiffness",
                             [](const CellController& c) { return mat3_array(c.stiffness()); },
                             "Affine stiffness C_rc at the last call, Pa.")
      .def_property_readonly("stress_error", &CellController::stress_error,
                             "Largest relative stress error of the stress-controlled "
                             "components at the last call, -.")
      .def("limit_report", [](const CellController& c) {
             py::list out;
             for (int k = 0; k < 9; ++k) {
               const LimitWatch& l = c.limits()[k];
               if (l.count == 0) continue;
               py::dict d;
               d["component"] = py::make_tuple(k / 3, k % 3);
               d["calls"] = l.count;
               d["target_pa"] = l.target;
               d["reached_pa"] = l.reached;
               d["cap_per_s"] = l.cap;
               out.append(d);
             }
             return out;
           },
           "Components that drifted from their target at the rate cap since the last clear: "
           "dicts with component, calls, target_pa, reached_pa, cap_per_s.")
      .def("clear_limit_report", &CellController::clear_limits);
}

}  // namespace cpp_dem::bind
