#include <pybind11/stl.h>

#include <cmath>
#include <limits>

#include "convert.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem::bind {

namespace {
py::dict energies_dict(const Energies& e) {
  py::dict d;
  d["kinetic"] = e.kinetic;
  d["elastic"] = e.elastic;
  d["gravity_potential"] = e.gravity_potential;
  d["friction"] = e.friction;
  d["viscous"] = e.viscous;
  d["local_damping"] = e.local_damping;
  d["plastic"] = e.plastic;
  d["wall_work"] = e.wall_work;
  d["external_work"] = e.external_work;
  d["cell_work"] = e.cell_work;
  d["balance_error"] = e.balance_error;
  d["balance_error_relative"] = e.balance_error_relative;
  return d;
}

/// Active contacts as arrays: ids (k,2) (wall contacts: body, -1-wall), force on the second
/// body / on the sphere (k,3) N, normal (k,3), branch (k,3) m (pairs: from i's centre to j's,
/// or j's periodic image; walls: zero), overlap (k,) m, normal force (k,) N, elastic shear
/// force on the second body (k,3) N, tangent stiffnesses kn, ks (k,) N/m, tan_phi (k,) -.
/// Scene::run without the GIL, asking Python about pending signals about every 0.1 s when on
/// the main thread (the only one where Python runs signal handlers): a handler's exception
/// (KeyboardInterrupt for Ctrl-C) stops the run after the step in progress, with step_count
/// and time those of the steps done, and is raised here.
void run_interruptible(Scene& s, long steps) {
  static const unsigned long main_thread =
      py::module_::import("threading").attr("main_thread")().attr("ident").cast<unsigned long>();
  bool raised = false;
  std::function<bool()> ask;
  if (PyThread_get_thread_ident() == main_thread)
    ask = [&raised] {
      py::gil_scoped_acquire gil;
      raised = PyErr_CheckSignals() != 0;  // the exception stays set in this thread's state
      return raised;
    };
  {
    py::gil_scoped_release nogil;
    s.run(steps, ask);
  }
  if (raised) throw py::error_already_set();
}

/// A velocity argument (3 values, m/s) that must be finite, `of` naming what it moves.
Vec3 finite_velocity(const Array& v, const std::string& of) {
  const Vec3 vel = to_vec3(v, "velocity");
  if (!vel.allFinite())
    throw ParameterError("velocity=(" + fmt_real(vel[0]) + ", " + fmt_real(vel[1]) + ", " +
                         fmt_real(vel[2]) + ") of " + of + ": must be finite (m/s)");
  return vel;
}

py::dict contacts_dict(const Scene& s) {
  std::vector<int> ids;
  std::vector<Vec3> force, normal, branch, fs;
  std::vector<Real> overlap, fn, kn, ks, tan_phi;
  s.for_each_contact([&](const ContactRecord& c) {
    // grid: Scene.grid_contacts(); cylinders and meshes: their walls' records
    if (!c.active || (c.kind != ContactKind::Pair && c.kind != ContactKind::Wall)) return;
    ids.push_back(s.id_of(c.kind == ContactKind::Pair ? c.body1 : c.body2));
    ids.push_back(c.kind == ContactKind::Pair ? s.id_of(c.body2) : -1 - c.other);
    force.push_back(c.force2);
    // Pair: x_j (its periodic image) - x_i; wall: zero (see measure.love_weber_stress).
    branch.push_back(c.kind == ContactKind::Pair
                         ? Vec3(s.positions()[c.body2] + c.shift2 - s.positions()[c.body1])
                         : Vec3::Zero());
    normal.push_back(c.state->normal);
    fs.push_back(c.state->fs);
    Real k_n, k_s;
    c.stiffness(k_n, k_s);
    kn.push_back(k_n);
    ks.push_back(k_s);
    tan_phi.push_back(c.phys->tan_phi);
    overlap.push_back(c.state->overlap);
    fn.push_back(c.state->fn);
  });
  py::array_t<int> id_arr({static_cast<py::ssize_t>(fn.size()), py::ssize_t(2)});
  if (!ids.empty()) std::memcpy(id_arr.mutable_data(), ids.data(), ids.size() * sizeof(int));
  py::dict d;
  d["ids"] = id_arr;
  d["force"] = vec3_array(force);
  d["normal"] = vec3_array(normal);
  d["branch"] = vec3_array(branch);
  d["shear_force"] = vec3_array(fs);
  d["kn"] = real_array(kn);
  d["ks"] = real_array(ks);
  d["tan_phi"] = real_array(tan_phi);
  d["overlap"] = real_array(overlap);
  d["normal_force"] = real_array(fn);
  return d;
}
}  // namespace

void bind_scene(py::module_& m) {
  py::class_<Scene>(m, "Scene", "DEM scene (compiled part; see cpp_dem.Scene).")
      .def(py::init<>())
      .def("add_material",
           [](Scene& s, const py::object& material) {
             if (!py::isinstance<Material>(material))
               throw ParameterError(
                   "material=" + py::repr(material).cast<std::string>() +
                   ": must be a Material (cpp_dem.linear_material(...), "
                   "cpp_dem.hertz_mindlin_material(...) or cpp_dem.Material(...))");
             return s.add_material(material.cast<const Material&>());
           },
           py::arg("material"), "Adds a material; returns its index.")
      .def("material", &Scene::material, py::arg("index"), py::return_value_policy::copy)
      .def_property_readonly("num_materials", &Scene::num_materials)
      .def("set_pair_law",
           [](Scene& s, int a, int b, std::optional<std::string> model,
              std::optional<double> kn, std::optional<double> ks, std::optional<double> friction,
              std::optional<double> damping_normal, std::optional<double> damping_shear) {
             PairLaw l;
             if (model) {
               l.model_set = true;
               l.model = law_by_name(*model);
             }
             const auto set = [](std::optional<double> v, const char* field, Real& out) {
               if (!v) return;
               if (!(*v >= 0)) require(false, field, *v, "must be >= 0, or None (unset)");
               out = *v;
             };
             set(kn, "kn", l.kn);
             set(ks, "ks", l.ks);
             set(friction, "friction", l.friction);
             set(damping_normal, "damping_normal", l.damping_normal);
             set(damping_shear, "damping_shear", l.damping_shear);
             s.set_pair_law(a, b, l);
           },
           py::arg("a"), py::arg("b"), py::kw_only(), py::arg("model") = py::none(),
           py::arg("kn") = py::none(), py::arg("ks") = py::none(),
           py::arg("friction") = py::none(), py::arg("damping_normal") = py::none(),
           py::arg("damping_shear") = py::none(),
           R"doc(Gives materials a and b their own law over the mixing rules (None keeps the
mixed value): model (a law of the registry), kn and ks (the linear law's stiffnesses, N/m),
friction (Coulomb coefficient mu, -), damping_normal and damping_shear (ratios of critical).
Replaces an earlier law of the pair; contacts take it at their next step.)doc")
      .def_property_readonly("pair_laws", [](const Scene& s) {
        py::list out;
        for (const PairLaw& l : s.pair_laws()) {
          py::dict d;
          d["a"] = l.a;
          d["b"] = l.b;
          d["model"] = l.model_set ? py::object(py::str(law_info(l.model).name)) : py::object(py::none());
          const auto opt = [](Real v) { return v >= 0 ? py::object(py::float_(v)) : py::object(py::none()); };
          d["kn"] = opt(l.kn);
          d["ks"] = opt(l.ks);
          d["friction"] = opt(l.friction);
          d["damping_normal"] = opt(l.damping_normal);
          d["damping_shear"] = opt(l.damping_shear);
          out.append(d);
        }
        return out;
      }, "The pair laws set (set_pair_law), one dict per pair of materials.")
      .def("_add_spheres",
           [](Scene& s, const Array& centers, const Array& radii, int material) {
             return s.add_spheres(to_vec3_list(centers, "centers"), to_real_list(radii, "radii"),
                                  material);
           },
           py::arg("centers"), py::arg("radii"), py::arg("material"))
      .def_property_readonly("num_bodies", &Scene::num_bodies)
      .def("add_wall", &Scene::add_wall, py::kw_only(), py::arg("axis"), py::arg("position"),
           py::arg("sense"), py::arg("material"),
           "Adds an axis-aligned one-sided wall: axis 0/1/2 (x/y/z), position along the axis (m), "
           "sense +1 if spheres are on its +axis side, -1 otherwise. Returns its index.")
      .def_property_readonly("num_walls", &Scene::num_walls)
      .def("add_cylinder_wall",
           [](Scene& s, const Array& centre, const Array& axis, double radius, bool inside,
              int material, double lo, double hi) {
             return s.add_cylinder_wall(to_vec3(centre, "centre"), to_vec3(axis, "axis"), radius,
                                        inside, material, lo, hi);
           },
           py::kw_only(), py::arg("centre"), py::arg("axis"), py::arg("radius"),
           py::arg("inside"), py::arg("material"),
           py::arg("lo") = -std::numeric_limits<double>::infinity(),
           py::arg("hi") = std::numeric_limits<double>::infinity(),
           "Adds a cylindrical wall: its axis through centre (m) along axis (any non-zero "
           "vector), radius (m), spheres inside it (inside=True: a triaxial cell's rigid side) "
           "or outside it (a pile), its lateral surface from lo to hi (m along the axis from "
           "centre; the default: infinite). The ends are open: a sphere beyond an end meets its "
           "rim circle. Not in a periodic cell. Returns its index.")
      .def_property_readonly("num_cylinder_walls", &Scene::num_cylinder_walls)
      .def("cylinder_wall",
           [](const Scene& s, int id) {
             const CylinderWall& w = s.cylinder_wall(id);
             py::dict d;
             d["centre"] = real_array({w.centre[0], w.centre[1], w.centre[2]});
             d["axis"] = real_array({w.axis[0], w.axis[1], w.axis[2]});
             d["radius"] = w.radius;
             d["inside"] = w.inside != 0;
             d["lo"] = w.lo;
             d["hi"] = w.hi;
             d["material"] = w.material;
             d["velocity"] = real_array({w.velocity[0], w.velocity[1], w.velocity[2]});
             d["radial_velocity"] = w.radial_velocity;
             d["force"] = real_array({w.force[0], w.force[1], w.force[2]});
             d["normal_force"] = w.normal_force;
             d["pressure_pa"] = w.finite() ? w.normal_force / w.lateral_area()
                                           : std::numeric_limits<double>::quiet_NaN();
             d["work"] = w.work;
             return d;
           },
           py::arg("cylinder"),
           "A cylindrical wall as a dict: centre (m), axis (unit), radius (m), inside, lo, hi "
           "(m), material, velocity (m/s), radial_velocity (m/s), force (N, the spheres' on "
           "it, last step), normal_force (N, the sum of its contacts' normal forces, "
           "compressive positive), pressure_pa (normal_force over the lateral area 2 pi R "
           "(hi - lo); NaN when infinite) and work (J, done by it on the spheres).")
      .def("set_cylinder_velocity",
           [](Scene& s, int id, const Array& v) {
             s.cylinder_wall(id).velocity =
                 finite_velocity(v, "cylindrical wall " + std::to_string(id));
           },
           py::arg("cylinder"), py::arg("velocity"),
           "Imposed velocity of the whole cylindrical wall (3 values), m/s.")
      .def("set_cylinder_radial_velocity",
           [](Scene& s, int id, double v) {
             require(std::isfinite(v), "radial_velocity", v, "must be finite (m/s)");
             s.cylinder_wall(id).radial_velocity = v;
           },
           py::arg("cylinder"), py::arg("radial_velocity"),
           "Imposed rate of the cylinder's radius, m/s (> 0 widens it).")
      .def("_add_mesh_wall",
           [](Scene& s, const Array& vertices, const py::array_t<int, py::array::c_style |
                                                                       py::array::forcecast>& tris,
              int material) {
             if (tris.ndim() != 2 || tris.shape(1) != 3)
               throw ParameterError("triangles: expected an (n, 3) array of vertex indices");
             std::vector<std::array<int, 3>> t(static_cast<size_t>(tris.shape(0)));
             for (py::ssize_t k = 0; k < tris.shape(0); ++k)
               t[k] = {tris.at(k, 0), tris.at(k, 1), tris.at(k, 2)};
             return s.add_mesh_wall(to_vec3_list(vertices, "vertices"), t, material);
           },
           py::arg("vertices"), py::arg("triangles"), py::arg("material"))
      .def_property_readonly("num_mesh_walls", &Scene::num_mesh_walls)
      .def_property_readonly("mesh_dropped_contacts", &Scene::mesh_dropped_contacts,
                             "Sphere–mesh contacts beyond three at one sphere and mesh in one "
                             "step, left out (the deepest kept), since the scene was made.")
      .def("mesh_wall",
           [](const Scene& s, int id) {
             const MeshWall& w = s.mesh_wall(id);
             py::dict d;
             d["vertices"] = vec3_array(s.mesh_vertices(id));
             d["num_triangles"] = w.ntri;
             py::array_t<int> tris({static_cast<py::ssize_t>(w.ntri), py::ssize_t(3)});
             for (int t = 0; t < w.ntri; ++t)
               for (int i = 0; i < 3; ++i) tris.mutable_at(t, i) = s.mesh_triangles()[w.tri_off + t][i];
             d["triangles"] = tris;
             d["material"] = w.material;
             d["velocity"] = real_array({w.velocity[0], w.velocity[1], w.velocity[2]});
             d["ref"] = real_array({w.ref[0], w.ref[1], w.ref[2]});
             d["force"] = real_array({w.force[0], w.force[1], w.force[2]});
             d["moment"] = real_array({w.moment[0], w.moment[1], w.moment[2]});
             d["work"] = w.work;
             return d;
           },
           py::arg("mesh"),
           "A mesh wall as a dict: vertices (current, m), triangles ((m, 3) indices into "
           "them), num_triangles, material, velocity "
           "(m/s), ref (m, the point its moment is about: its vertices' mean, moving with it), "
           "force (N) and moment (N m, about ref) of the spheres on it at the last step, work "
           "(J, done by it on the spheres).")
      .def("set_mesh_velocity",
           [](Scene& s, int id, const Array& v) {
             s.mesh_wall(id).velocity = finite_velocity(v, "mesh wall " + std::to_string(id));
           },
           py::arg("mesh"), py::arg("velocity"),
           "Imposed velocity of the whole mesh wall (3 values), m/s.")
      .def("set_cylinder_radius", &Scene::set_cylinder_radius, py::arg("cylinder"),
           py::arg("radius"), "Sets the cylinder's radius, m.")
      .def("set_wall_opening", &Scene::set_wall_opening, py::arg("wall"), py::kw_only(),
           py::arg("axis"), py::arg("lo") = 0.0, py::arg("hi") = 0.0,
           "Opens the wall for bodies whose centre lies in (lo, hi) (m) along axis 0/1/2 (not "
           "the wall's own axis): they pass it without contact, as through a pull-out box's "
           "slot. axis=-1 closes it.")
      .def("wall_opening",
           [](const Scene& s, int id) {
             const WallOpening& o = s.wall_opening(id);
             return py::make_tuple(o.axis, o.lo, o.hi);
           },
           py::arg("wall"), "(axis, lo, hi) of the wall's opening, m; axis -1: closed.")
      .def("set_wall_velocity",
           [](Scene& s, int id, const Array& v) {
             s.wall(id).velocity = finite_velocity(v, "wall " + std::to_string(id));
           },
           py::arg("wall"), py::arg("velocity"), "Imposed wall velocity (3 values), m/s.")
      .def("_inject_unchecked", &Scene::inject_unchecked, py::arg("field"), py::arg("body"),
           py::arg("axis"), py::arg("value"),
           "Writes one component of a body's velocity, spin, external force or torque without "
           "the setters' checks (tests of the blow-up detector).")
      .def("set_wall_position",
           [](Scene& s, int id, double x) {
             require(std::isfinite(x), "position", x, "must be finite (m)");
             Wall& w = s.wall(id);
             w.moved_since_build += std::abs(x - w.position);
             w.position = x;
           },
           py::arg("wall"), py::arg("position"), "Moves the wall plane to position (m).")
      .def_property_readonly("wall_positions", [](const Scene& s) {
        std::vector<Real> v;
        for (int i = 0; i < s.num_walls(); ++i) v.push_back(s.wall(i).position);
        return real_array(v);
      }, "Wall plane coordinates, m, shape (n_walls,).")
      .def_property_readonly("wall_forces", [](const Scene& s) {
        std::vector<Vec3> v;
        for (int i = 0; i < s.num_walls(); ++i) v.push_back(s.wall(i).force);
        return vec3_array(v);
      }, "Force exerted by the spheres on each wall at the last step, N, shape (n_walls, 3).")
      .def_property_readonly("wall_velocities", [](const Scene& s) {
        std::vector<Vec3> v;
        for (int i = 0; i < s.num_walls(); ++i) v.push_back(s.wall(i).velocity);
        return vec3_array(v);
      }, "Imposed wall velocities, m/s, shape (n_walls, 3).")
      .def_property_readonly("wall_axes", [](const Scene& s) {
        std::vector<int> v;
        for (int i = 0; i < s.num_walls(); ++i) v.push_back(s.wall(i).axis);
        return v;
      })
      .def_property_readonly("wall_senses", [](const Scene& s) {
        std::vector<int> v;
        for (int i = 0; i < s.num_walls(); ++i) v.push_back(s.wall(i).sense);
        return v;
      })
      .def_property("positions", [](const Scene& s) { return vec3_array(s.by_id(s.positions())); },
                    [](Scene& s, const Array& a) { s.set_positions(s.by_slot(to_vec3_list(a, "positions"))); },
                    "Body centres, m, shape (n, 3).")
      .def_property("velocities", [](const Scene& s) { return vec3_array(s.by_id(s.velocities())); },
                    [](Scene& s, const Array& a) { s.set_velocities(s.by_slot(to_vec3_list(a, "velocities"))); },
                    "Body velocities, m/s, shape (n, 3) (leapfrog: at the last half step).")
      .def_property("angular_velocities",
                    [](const Scene& s) { return vec3_array(s.by_id(s.angular_velocities())); },
                    [](Scene& s, const Array& a) {
                      s.set_angular_velocities(s.by_slot(to_vec3_list(a, "angular_velocities")));
                    },
                    "Angular velocities, rad/s, shape (n, 3).")
      .def_property_readonly("forces", [](const Scene& s) { return vec3_array(s.by_id(s.forces())); },
                             "Resultant force on each body at the last step (contacts, gravity, "
                             "external), N, shape (n, 3).")
      .def_property_readonly("torques", [](const Scene& s) { return vec3_array(s.by_id(s.torques())); },
                             "Resultant torque, N m, shape (n, 3).")
      .def_property("radii", [](const Scene& s) { return real_array(s.by_id(s.radii())); },
                    [](Scene& s, const Array& a) { s.set_radii(s.by_slot(to_real_list(a, "radii"))); },
                    "Radii, m, shape (n,). Setting them rescales masses and inertias.")
      .def_property_readonly("masses", [](const Scene& s) { return real_array(s.by_id(s.masses())); },
                             "Masses, kg, shape (n,).")
      .def_property_readonly("inertias", [](const Scene& s) { return real_array(s.by_id(s.inertias())); },
                             "Moments of inertia, kg m^2, shape (n,).")
      .def_property_readonly("orientations", [](const Scene& s) {
        py::array_t<double> out({static_cast<py::ssize_t>(s.num_bodies()), py::ssize_t(4)});
        auto r = out.mutable_unchecked<2>();
        for (int b = 0; b < s.num_bodies(); ++b) {
          const Quat& q = s.orientations()[s.slot_of(b)];
          r(b, 0) = q.w(); r(b, 1) = q.x(); r(b, 2) = q.y(); r(b, 3) = q.z();
        }
        return out;
      }, "Orientation quaternions (w, x, y, z), shape (n, 4).")
      .def_property_readonly("material_ids", [](const Scene& s) { return s.by_id(s.body_materials()); })
      .def_property("external_forces", [](const Scene& s) { return vec3_array(s.by_id(s.external_forces())); },
                    [](Scene& s, const Array& a) {
                      s.set_external_forces(s.by_slot(to_vec3_list(a, "external_forces")));
                    },
                    "Constant external force on each body, N, shape (n, 3).")
      .def_property("external_torques", [](const Scene& s) { return vec3_array(s.by_id(s.external_torques())); },
                    [](Scene& s, const Array& a) {
                      s.set_external_torques(s.by_slot(to_vec3_list(a, "external_torques")));
                    },
                    "Constant external torque on each body, N m, shape (n, 3).")
      .def("_set_blocked", &Scene::set_blocked, py::arg("body"), py::arg("mask"))
      .def_property_readonly("_blocked", [](const Scene& s) {
        const auto b = s.by_id(s.blocked());
        return std::vector<int>(b.begin(), b.end());
      })
      .def("set_body_material", &Scene::set_body_material, py::arg("body"), py::arg("material"))
      .def_property("spatial_sort", &Scene::spatial_sort, &Scene::set_spatial_sort,
                    "Store the spheres in spatial order at the first broad-phase build (default "
                    "True; ids and every array seen from Python are unchanged).")
      .def_property_readonly("identity_order", &Scene::identity_order,
                             "True while the bodies are stored in id order.")
      .def_property("dt", &Scene::dt, &Scene::set_dt, "Time step, s.")
      .def_property("gravity", [](const Scene& s) {
        return std::vector<double>{s.gravity()[0], s.gravity()[1], s.gravity()[2]};
      }, [](Scene& s, const Array& g) { s.set_gravity(to_vec3(g, "gravity")); },
                    "Gravitational acceleration, m/s^2 (3 values).")
      .def_property("local_damping", &Scene::local_damping, &Scene::set_local_damping,
                    "Cundall local non-viscous damping coefficient, -, in [0, 1).")
      .def_property("verlet_margin", &Scene::verlet_margin, &Scene::set_verlet_margin,
                    "Broad-phase Verlet margin, m, >= 0 (0: 0.2 x the mean radius, the default).")
      .def_property("max_step_ratio", &Scene::max_step_ratio, &Scene::set_max_step_ratio,
                    "Largest move of a body in one step, in radii (default 1); beyond it the "
                    "step raises BlowUpError (tunnelling).")
      .def_property("max_overlap_ratio", &Scene::max_overlap_ratio, &Scene::set_max_overlap_ratio,
                    "Overlap / smaller radius above which a step raises BlowUpError (default 0.5).")
      .def_property(
          "shear_kinematics",
          [](const Scene& s) {
            return s.shear_kinematics() == ShearKinematics::Yade ? "yade" : "contact_point";
          },
          [](Scene& s, const std::string& v) {
            if (v == "contact_point") s.set_shear_kinematics(ShearKinematics::ContactPoint);
            else if (v == "yade") s.set_shear_kinematics(ShearKinematics::Yade);
            else
              throw ParameterError("shear_kinematics='" + v + "': must be 'contact_point' "
                                   "(default) or 'yade' (Yade's avoidGranularRatcheting)");
          },
          "Relative velocity at a sphere-sphere contact that grows the shear spring. "
          "'contact_point' (default): the bodies' velocities at the contact point, "
          "v_j - v_i - (l_j w_j + l_i w_i) x n with branch lengths l = r - overlap/2. "
          "'yade': Yade's ScGeom with avoidGranularRatcheting, alpha (v_j - v_i) - "
          "(r_j w_j + r_i w_i) x n with alpha = (r_i + r_j) / (r_i + r_j - overlap), for "
          "comparisons with Yade (see docs/core.md). Sphere-sphere contacts only (clump members "
          "included; not walls, the geogrid or bonds); kept in checkpoints.")
      .def_property("track_energy", &Scene::track_energy, &Scene::set_track_energy,
                    "Energy bookkeeping on/off (turning it on restarts the balance).")
      .def("set_auto_timestep", &Scene::set_auto_timestep, py::arg("safety") = 0.8,
           py::arg("period") = 100,
           "Every `period` steps set dt = safety x critical_dt() (period 0 switches it off).")
      .def("set_density_scaling", &Scene::set_density_scaling, py::arg("target_dt"),
           py::arg("safety") = 0.5, py::arg("period") = 1,
           "Density scaling for quasi-static stages: dt = target_dt (s), and every `period` "
           "steps each free body and clump takes the inertia factor s = max(1, (target_dt / "
           "(safety x its own critical step))^2), its critical step from its active contacts, "
           "bonds and links (updated just before the bodies move; a factor falls at most by "
           "half per update; a body that never touched keeps 1). Weight and gravity stay the "
           "true ones; "
           "velocities are kept when a factor changes. While on, the automatic time step is "
           "not applied and critical_dt() takes the scaled inertia. Kept in checkpoints. See "
           "cpp_dem.protocols.quasi_static and docs/quasi_static.md.")
      .def("clear_density_scaling", &Scene::clear_density_scaling,
           "Switches density scaling off: every inertia factor back to 1 (dt is kept).")
      .def_property_readonly("density_scaling", &Scene::density_scaling,
                             "Whether density scaling is on.")
      .def_property_readonly("density_scaling_target_dt", &Scene::density_scaling_target_dt,
                             "Density scaling's target time step, s.")
      .def_property_readonly("density_scaling_safety", &Scene::density_scaling_safety,
                             "Density scaling's safety factor, -.")
      .def_property_readonly("density_scaling_period", &Scene::density_scaling_period,
                             "Steps between updates of the inertia factors.")
      .def("density_scaling_stats", [](const Scene& s) {
             const Scene::DensityScalingStats st = s.density_scaling_stats();
             py::dict d;
             d["max_factor"] = st.max_factor;
             d["mean_factor"] = st.mean_factor;
             d["scaled_share"] = st.scaled_share;
             d["scaled"] = st.scaled;
             d["movable"] = st.movable;
             d["inertial_number"] = st.inertial_number;
             return d;
           },
           "What density scaling does now: max_factor and mean_factor (mass-weighted) of the "
           "inertia factors, -; scaled_share, the share of free bodies and clumps with a "
           "factor above 1 (scaled of movable); inertial_number, the sample's with the scaled "
           "inertia, sqrt(sum rho_c |dv_c|^2 / sum |f_c| / d_c^2) over the active pair "
           "contacts (dv_c the centres' relative velocity, f_c the force, d_c the sum of the "
           "radii, rho_c the bodies' density times their factor), -.")
      .def("inertia_scale", &Scene::inertia_scale, py::arg("body"),
           "The density-scaling inertia factor of a body (its clump's for a member), -.")
      .def_property_readonly("timestep_safety", &Scene::timestep_safety)
      .def_property_readonly("timestep_period", &Scene::timestep_period)
      .def_property("dt_check_period", &Scene::dt_check_period, &Scene::set_dt_check_period,
                    "Without the automatic time step: every this many steps (0 = off) a dt "
                    "above critical_dt() stops the run with BlowUpError.")
      .def("_run", &run_interruptible, py::arg("steps"),
           "Runs `steps` steps in C++ without the GIL; a signal (Ctrl-C) raises its exception "
           "(KeyboardInterrupt) within about 0.1 s, after the step in progress.")
      .def_property_readonly("step_count", &Scene::step_count)
      .def_property_readonly("time", &Scene::time, "Simulated time, s.")
      .def("critical_dt", &Scene::critical_dt,
           "Critical time-step estimate, s: min over bodies and axes of sqrt(2 m / K) from the "
           "current contact stiffnesses; the p-wave estimate before contacts exist; inf when every "
           "body is fully blocked.")
      .def("critical_dt_body", [](const Scene& s, bool contact_seen) {
             int body = -1;
             const Real dt = s.critical_dt_body(&body, contact_seen);
             return py::make_tuple(dt, body);
           }, py::arg("contact_seen") = false,
           "(critical_dt(), the id of the body that sets it, -1 when no contact or link "
           "exists): which body limits the time step. With contact_seen, the estimate of a "
           "packing in contact even when nothing touches yet (every grain's stiffness floor; "
           "not with density scaling on).")
      .def("pwave_dt", &Scene::pwave_dt, "p-wave time step min R sqrt(rho / E), s.")
      .def("energies", [](const Scene& s) { return energies_dict(s.energies()); },
           "Energy terms, J, and the balance error (needs track_energy).")
      .def("reset_energy", &Scene::reset_energy)
      .def("unbalanced_force", &Scene::unbalanced_force,
           "Mean resultant force on free bodies / mean contact force, - (NaN without contacts).")
      .def("memory_by_field", [](const Scene& s) {
        py::dict d;
        for (const auto& [name, bytes] : s.memory_by_field()) d[py::str(name)] = bytes;
        return d;
      }, "Bytes allocated by each of the core's arrays (capacity x element size), by field "
         "name: the scene's own memory, not the allocator's or Python's.")
      .def("collider_stats", [](const Scene& s) {
        const ColliderStats c = s.collider_stats();
        py::dict d;
        d["builds"] = c.builds;
        d["pair_candidates"] = c.pair_candidates;
        d["pair_records"] = c.pair_records;
        d["wall_candidates"] = c.wall_candidates;
        d["grid_candidates"] = c.grid_candidates;
        return d;
      })
      .def("_pair_batched", &Scene::pair_batched,
           "The pair contacts the last pair pass ran eight at a time (tests; docs/core.md).")
      .def("contacts", &contacts_dict, "Active contacts as arrays (see docs).")
      .def_property_readonly("num_active_contacts", &Scene::num_active_contacts);
}

}  // namespace cpp_dem::bind
