// Bindings of the sample controllers (controllers.hpp). Type conversion only.
#include <pybind11/stl.h>

#include <array>

#include "convert.hpp"
#include "cpp_dem/control/controllers.hpp"

namespace cpp_dem::bind {

namespace {
py::array_t<double> vec3_np(const Vec3& v) { return vec3_array({v}).attr("reshape")(3); }
}  // namespace

namespace {
/// A LimitWatch as the dict of limit_report(): wall, axis (when given), calls, target_pa,
/// reached_pa, cap_m_per_s.
py::dict limit_dict(const LimitWatch& l, int wall, const std::string& axis) {
  py::dict d;
  if (!axis.empty()) d["axis"] = axis;
  d["wall"] = wall;
  d["calls"] = l.count;
  d["target_pa"] = l.target;
  d["reached_pa"] = l.reached;
  d["cap_m_per_s"] = l.cap;
  return d;
}

/// The watch of a StressServo (ServoWall, CylinderServo) on its Python class: limit_report,
/// clear_limit_report, target_report, clear_target_report. Its reports name its wall by `key`
/// ("wall"; a cylinder's also by "cylinder", with "wall" its index too).
template <class S, class Cls>
void def_servo_watch(Cls& cls, const char* key, int (S::*id)() const, Real (S::*target)() const) {
  const std::string k = key;
  cls.def("limit_report", [k, id](const S& c) {
        py::list out;
        if (c.limit().count > 0) {
          py::dict d = limit_dict(c.limit(), (c.*id)(), "");
          d[k.c_str()] = (c.*id)();
          out.append(d);
        }
        return out;
      }, ("Calls since the last clear at the speed cap while drifting from the target stress "
          "(off by more than 5 % and growing): a list with one dict (" + k + ", calls, "
          "target_pa, reached_pa, cap_m_per_s), or empty.").c_str())
      .def("clear_limit_report", &S::clear_limit)
      .def("target_report", [k, id, target](const S& c) {
        py::list out;
        const LimitWatch& l = c.limit();
        if (l.unmet()) {
          py::dict d;
          d["wall"] = (c.*id)();
          d[k.c_str()] = (c.*id)();
          d["target_pa"] = (c.*target)();
          d["reached_pa"] = l.last_sigma;
          d["calls"] = l.run_calls;
          d["calls_at_cap"] = l.run_cap_calls;
          d["cap_m_per_s"] = l.last_cap;
          out.append(d);
        }
        return out;
      }, ("The target not reached: when the stress has not been within 5 % of the current "
          "target at any call since it was set, and the target was not reported yet, a list "
          "with one dict (" + k + ", target_pa, reached_pa: the stress at the last call, calls "
          "and calls_at_cap since the last clear_target_report, cap_m_per_s); else empty.").c_str())
      .def("clear_target_report", &S::clear_target_watch, py::arg("reported") = false,
           "Starts the count of calls over; reported=True: the unmet target was reported "
           "(it is not reported again until a new target is set).");
}
}  // namespace

void bind_controllers(py::module_& m) {
  py::class_<Controller, std::shared_ptr<Controller>>(m, "Controller",
      "Base of the controllers the step loop runs every `period` steps (before the forces).")
      .def_readwrite("period", &Controller::period, "Steps between calls, >= 1.")
      .def_readwrite("enabled", &Controller::enabled);

  // Scene.add_controller lives here (the Controller type is bound in this file).
  py::object scene_cls = py::type::of<Scene>();
  scene_cls.attr("add_controller") = py::cpp_function(
      [](Scene& s, std::shared_ptr<Controller> c) {
        if (c) check_new_controller(s, *c);
        return s.add_controller(std::move(c));
      },
      py::name("add_controller"), py::is_method(scene_cls), py::arg("controller"),
      "Adds a controller (run every controller.period steps, before the forces, in the order "
      "added); returns its index. The scene keeps it alive. Refused (ParameterError) when it "
      "is in the scene already, or when it and another enabled controller move one wall.");
  scene_cls.attr("_check_controllers") = py::cpp_function(
      [](const Scene& s) { check_enabled_controllers(s); }, py::name("_check_controllers"),
      py::is_method(scene_cls),
      "ParameterError when two enabled controllers move the same wall (before a run).");
  scene_cls.attr("controller") = py::cpp_function(
      [](const Scene& s, int i) { return s.controller(i); }, py::name("controller"),
      py::is_method(scene_cls), py::arg("index"), "The controller added as number `index`.");
  scene_cls.attr("clear_controllers") = py::cpp_function(
      [](Scene& s) { s.clear_controllers(); }, py::name("clear_controllers"),
      py::is_method(scene_cls), "Removes every controller (e.g. a preparation's).");
  scene_cls.attr("num_controllers") = py::cpp_function(
      [](const Scene& s) { return s.num_controllers(); }, py::name("num_controllers"),
      py::is_method(scene_cls), "Number of controllers.");

  m.def("servo_speed", &servo_speed, py::arg("sigma_target"), py::arg("sigma"), py::arg("area"),
        py::arg("stiffness"), py::arg("dt"), py::arg("period"), py::arg("gain"),
        py::arg("max_speed"),
        "Servo wall speed along the inward normal, m/s: gain (sigma_target - sigma) area / "
        "(stiffness dt period), capped to +-max_speed (stresses Pa, area m^2, stiffness N/m).");

  py::class_<ServoWall, Controller, std::shared_ptr<ServoWall>> servo_wall(m, "ServoWall", R"doc(
One wall driven to a target normal stress (Pa, compressive positive) by its velocity.

Each call sets the wall velocity along its inward normal to
gain (sigma_target - sigma) A / (k dt period), k the summed normal stiffness of the wall's
contacts (N/m), capped to +-max_speed (m/s). A is `area` (m^2), or the current box face area
when `box_walls` (the six walls of Scene.add_box) are given.
)doc");
  servo_wall.def(py::init<int, Real, Real, Real, Real, std::vector<int>>(), py::kw_only(),
           py::arg("wall"), py::arg("target_stress"), py::arg("area") = 0.0,
           py::arg("gain") = 0.5, py::arg("max_speed"), py::arg("box_walls") = std::vector<int>{})
      .def_property("target_stress", &ServoWall::target_stress, &ServoWall::set_target_stress,
                    "Target normal stress, Pa (compressive positive).")
      .def_property("max_speed", &ServoWall::max_speed, &ServoWall::set_max_speed,
                    "Velocity cap, m/s.")
      .def_property("gain", &ServoWall::gain, &ServoWall::set_gain, "Gain alpha in (0, 1].")
      .def_property_readonly("wall", &ServoWall::wall)
      .def_property_readonly("area", &ServoWall::area, "Area at the last call, m^2.")
      .def_property_readonly("measured_stress", &ServoWall::measured_stress,
                             "Stress at the last call, Pa.")
      .def_property_readonly("stiffness", &ServoWall::stiffness,
                             "Summed contact normal stiffness at the last call, N/m.");
  def_servo_watch<ServoWall>(servo_wall, "wall", &ServoWall::wall, &ServoWall::target_stress);

  py::class_<CylinderServo, Controller, std::shared_ptr<CylinderServo>> cylinder_servo(
      m, "CylinderServo", R"doc(
A cylindrical wall (Scene.add_cylinder_wall, finite) driven to a target mean normal pressure on
its lateral surface (Pa, compressive positive) by the rate of its radius.

Each call sets the wall's radial velocity to gain (p_target - p) A / (k dt period) in the
direction that presses the grains harder when p is below the target (inside: narrowing;
outside: widening), capped to +-max_speed (m/s). p is the wall's normal force over its lateral
area A = 2 pi R (hi - lo), k the summed normal stiffness of its contacts (N/m).
)doc");
  cylinder_servo.def(py::init<int, Real, Real, Real>(), py::kw_only(), py::arg("cylinder"),
           py::arg("target_pressure"), py::arg("gain") = 0.5, py::arg("max_speed"))
      .def_property("target_pressure", &CylinderServo::target_pressure,
                    &CylinderServo::set_target_pressure, "Target pressure, Pa (compressive positive).")
      .def_property("max_speed", &CylinderServo::max_speed, &CylinderServo::set_max_speed,
                    "Cap of the radial speed, m/s.")
      .def_property("gain", &CylinderServo::gain, &CylinderServo::set_gain, "Gain alpha in (0, 1].")
      .def_property_readonly("cylinder", &CylinderServo::cylinder)
      .def_property_readonly("measured_pressure", &CylinderServo::measured_pressure,
                             "Pressure at the last call, Pa.")
      .def_property_readonly("stiffness", &CylinderServo::stiffness,
                             "Summed contact normal stiffness at the last call, N/m.");
  def_servo_watch<CylinderServo>(cylinder_servo, "cylinder", &CylinderServo::cylinder,
                                 &CylinderServo::target_pressure);

  py::class_<MeshServo, Controller, std::shared_ptr<MeshServo>> mesh_servo(m, "MeshServo", R"doc(
A mesh wall (Scene.add_mesh_wall) driven as a whole along `direction` (into the grains) to a
target normal stress (Pa, compressive positive) on `area` (m^2): a loading plate, a footing.

Each call sets the mesh's velocity to v direction, v = gain (sigma_target - sigma) A /
(k dt period) capped to +-max_speed (m/s); sigma is the spheres' push on the mesh against
`direction` over A, k the summed normal stiffness of its contacts (N/m).
)doc");
  mesh_servo.def(py::init([](int mesh, const Array& direction, Real target, Real area, Real gain,
                             Real max_speed) {
                   return std::make_shared<MeshServo>(mesh, to_vec3(direction, "direction"),
                                                      target, area, gain, max_speed);
                 }),
                 py::kw_only(), py::arg("mesh"), py::arg("direction"), py::arg("target_stress"),
                 py::arg("area"), py::arg("gain") = 0.5, py::arg("max_speed"))
      .def_property("target_stress", &MeshServo::target_stress, &MeshServo::set_target_stress,
                    "Target normal stress, Pa (compressive positive).")
      .def_property("max_speed", &MeshServo::max_speed, &MeshServo::set_max_speed,
                    "Velocity cap, m/s.")
      .def_property("gain", &MeshServo::gain, &MeshServo::set_gain, "Gain alpha in (0, 1].")
      .def_property_readonly("mesh", &MeshServo::mesh)
      .def_property_readonly("area", &MeshServo::area, "The area, m^2.")
      .def_property_readonly("measured_stress", &MeshServo::measured_stress,
                             "Stress at the last call, Pa.")
      .def_property_readonly("stiffness", &MeshServo::stiffness,
                             "Summed contact normal stiffness at the last call, N/m.");
  def_servo_watch<MeshServo>(mesh_servo, "mesh", &MeshServo::mesh, &MeshServo::target_stress);

  py::class_<TriaxialController, Controller, std::shared_ptr<TriaxialController>> tc(
      m, "TriaxialController", R"doc(
Per-axis control of a box of six walls (order x-, x+, y-, y+, z-, z+): stress control (both
walls of the axis servo to a normal stress, Pa, compressive positive, with the face area
recomputed from the current box) or strain-rate control (both walls move inwards at
rate L0 / 2, rate in 1/s, compression positive). Strains are engineering (L0 - L) / L0,
compression positive, from the box size when the controller first ran (or reset_strain).
)doc");
  tc.def(py::init<std::vector<int>, Real, Real>(), py::kw_only(), py::arg("walls"),
         py::arg("gain") = 0.5, py::arg("max_speed"))
      .def("set_stress", &TriaxialController::set_stress, py::arg("axis"), py::arg("stress"))
      .def("set_strain_rate", &TriaxialController::set_strain_rate, py::arg("axis"),
           py::arg("rate"))
      .def("mode", [](const TriaxialController& c, int a) {
        return c.mode(a) == TriaxialController::Mode::Stress ? "stress" : "strain_rate";
      }, py::arg("axis"))
      .def("goal", &TriaxialController::goal, py::arg("axis"),
           "Target stress (Pa) or strain rate (1/s) of the axis.")
      .def_property("max_speed", &TriaxialController::max_speed,
                    &TriaxialController::set_max_speed, "Velocity cap of the servo, m/s.")
      .def_property("gain", &TriaxialController::gain, &TriaxialController::set_gain)
      .def_property("symmetric", &TriaxialController::symmetric,
                    &TriaxialController::set_symmetric,
                    "Axis-mean servo (default False: each wall on its own stress): both walls "
                    "of a stress-controlled axis move inwards at one speed, from the axis's "
                    "mean stress and their mean contact stiffness, so the box cannot "
                    "translate. Use it under gravity: on their own stresses the bottom wall "
                    "(carrying the weight too) backs off while the top one pushes, and at "
                    "the speed cap the box only translates.")
      .def_property_readonly("effective_max_speed", &TriaxialController::effective_max_speed,
                             "Cap of the stress-controlled walls now, m/s: max_speed, raised "
                             "while an axis is strain-rate controlled to |rate| x the longest "
                             "reference length.")
      .def("limit_report", [](const TriaxialController& c) {
        py::list out;
        for (int k = 0; k < 6; ++k)
          if (c.limit(k).count > 0)
            out.append(limit_dict(c.limit(k), c.walls()[k], std::string(1, "xyz"[k / 2])));
        return out;
      }, "Per stress-controlled wall, calls since the last clear at the speed cap while "
         "drifting from the target (off by more than 5 % and growing): dicts (axis, wall, "
         "calls, target_pa, reached_pa, cap_m_per_s).")
      .def("clear_limit_report", &TriaxialController::clear_limits)
      .def_property_readonly("walls", &TriaxialController::walls)
      .def("strains", [](const TriaxialController& c, const Scene& s) {
        return vec3_np(c.strains(s));
      }, py::arg("scene"), "Engineering strains per axis, -, compression positive.")
      .def_property_readonly("reference_lengths", [](const TriaxialController& c) {
        return vec3_np(c.reference_lengths());
      }, "Box size at zero strain, m.")
      .def("reset_strain", &TriaxialController::reset_strain, py::arg("scene"))
      .def_static("box_size", [](const Scene& s, const std::vector<int>& w) {
        return vec3_np(TriaxialController::box_size(s, w));
      }, py::arg("scene"), py::arg("walls"), "Box dimensions from the six walls, m.")
      .def_static("wall_stresses", [](const Scene& s, const std::vector<int>& w) {
        auto st = TriaxialController::wall_stresses(s, w);
        return real_array(std::vector<Real>(st.begin(), st.end()));
      }, py::arg("scene"), py::arg("walls"),
         "Normal stresses of the six walls, Pa (compressive positive), current areas.")
      .def_static("axis_stresses", [](const Scene& s, const std::vector<int>& w) {
        return vec3_np(TriaxialController::axis_stresses(s, w));
      }, py::arg("scene"), py::arg("walls"), "Per-axis mean wall stress, Pa.");

  py::class_<MembranePressure, Controller, std::shared_ptr<MembranePressure>>(
      m, "MembranePressure", R"doc(
A confining pressure on a surface of triangles between bodies: a flexible membrane of PFacets
(cpp_dem.build.membrane.cylindrical_membrane makes one and this controller with it).

Every call (period 1: every step, before the contact forces) sets the external force of each
node to the sum of a third of -p A_f over its triangles, A_f = (x1 - x0) x (x2 - x0) / 2 the
triangle's area vector from the nodes' current positions (outward for nodes listed
anticlockwise seen from outside) and p = `pressure_pa` (Pa, compressive positive: it pushes the
surface inwards). The load follows each triangle's area and normal as the surface deforms. It
owns its nodes' external forces: a force set on them otherwise is replaced at the next call.
)doc")
      .def(py::init([](const std::vector<std::array<int, 3>>& triangles, Real pressure_pa) {
             return std::make_shared<MembranePressure>(triangles, pressure_pa);
           }),
           py::kw_only(), py::arg("triangles"), py::arg("pressure_pa"))
      .def_property("pressure_pa", &MembranePressure::pressure, &MembranePressure::set_pressure,
                    "The pressure, Pa (compressive positive).")
      .def_property_readonly("triangles", &MembranePressure::triangles,
                             "Node body ids, three per triangle.")
      .def_property_readonly("nodes", &MembranePressure::nodes, "The nodes it loads (ids).")
      .def_property_readonly("area", &MembranePressure::area,
                             "Sum of the triangles' areas at the last call, m^2.")
      .def_property_readonly("area_vector", [](const MembranePressure& c) {
             const Vec3& a = c.area_vector();
             return std::vector<Real>{a[0], a[1], a[2]};
           },
                             "Sum of the triangles' area vectors at the last call, m^2.");

  py::class_<PlatenClamp, Controller, std::shared_ptr<PlatenClamp>>(m, "PlatenClamp", R"doc(
Bodies held to a planar wall, as a membrane's end ring is sealed to its platen.

Every call gives each body the wall's velocity along the wall's axis, corrected by its offset
from where the wall has carried it since the first call over one step, and holds it still
across the axis; the bodies' translations are blocked at the first call. Add it after the
wall's servo, so that it follows the velocity the servo sets in the same step (added before,
it follows one step late and the correction takes up the difference).
)doc")
      .def(py::init<int, std::vector<int>>(), py::kw_only(), py::arg("wall"), py::arg("bodies"))
      .def_property_readonly("wall", &PlatenClamp::wall)
      .def_property_readonly("bodies", &PlatenClamp::bodies)
      .def_property_readonly("max_offset", &PlatenClamp::max_offset,
                             "Largest offset along the axis from where the wall carried a body, "
                             "at the last call, m.");

  py::class_<RadiusGrowth, Controller, std::shared_ptr<RadiusGrowth>>(m, "RadiusGrowth", R"doc(
Radius growth under stress control (001 §4.3.1; the expansion of REFD, 000 §2.3): each call
multiplies the radii by m = 1 + gain (sigma_t - sigma) / S, sigma the mean stress of the six
box walls (Pa), S = (1/V) sum_c k_n l_c^2 (Pa) from the current contacts; m is capped to
[1 - max_strain, 1 + max_strain]. Masses follow the radii. grown_only (off by default):
sigma and S count only the contacts touching a growing sphere and no bonds (in a periodic
cell sigma is then those grains' mean normal stress; with walls only S changes), so a
sheet of bonded spheres among the grains does not offset the target.
)doc")
      .def(py::init([](std::vector<int> walls, std::vector<int> bodies, Real target,
                       Real gain, Real max_strain, bool grown_only) {
             auto g = std::make_shared<RadiusGrowth>(std::move(walls), std::move(bodies),
                                                     target, gain, max_strain);
             g->set_grown_only(grown_only);
             return g;
           }),
           py::kw_only(), py::arg("walls"), py::arg("bodies") = std::vector<int>{},
           py::arg("target_stress"), py::arg("gain") = 0.5, py::arg("max_strain") = 1e-3,
           py::arg("grown_only") = false)
      .def_property("grown_only", &RadiusGrowth::grown_only, &RadiusGrowth::set_grown_only,
                    "Count only the contacts touching a growing sphere, and no bonds.")
      .def_property("target_stress", &RadiusGrowth::target_stress,
                    &RadiusGrowth::set_target_stress, "Target mean wall stress, Pa.")
      .def_property_readonly("measured_stress", &RadiusGrowth::measured_stress,
                             "Mean wall stress at the last call, Pa.")
      .def_property_readonly("total_factor", &RadiusGrowth::total_factor,
                             "Product of the multipliers applied so far, -.")
      .def_property_readonly("last_factor", &RadiusGrowth::last_factor);
}

}  // namespace cpp_dem::bind
