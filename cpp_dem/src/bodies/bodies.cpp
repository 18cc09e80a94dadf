// The body API of the scene: materials, spheres, walls, and setters of per-body state.
#include <cmath>
#include <string>

#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
Real sphere_mass(Real density, Real r) { return density * 4.0 / 3.0 * M_PI * r * r * r; }

template <class T>
void require_size(const std::vector<T>& v, size_t n, const char* field) {
  if (v.size() != n)
    throw ParameterError(std::string(field) + ": has " + std::to_string(v.size()) +
                         " rows, the scene has " + std::to_string(n) + " bodies");
}
}  // namespace

Scene::Scene() = default;

namespace {
/// A clump's members move with their clump: a whole-array setter may pass their current
/// values back unchanged, not new ones (that would be undone silently at the next step).
template <class T>
void check_members_unchanged(const Scene& s, const std::vector<T>& now, const std::vector<T>& given,
                             const char* field) {
  if (!s.has_clumps()) return;
  const auto& cl = s.clumps_of_bodies();
  for (size_t b = 0; b < given.size(); ++b)
    if (cl[b] >= 0 && given[b] != now[b])
      throw ParameterError(std::string(field) + "[" + std::to_string(s.id_of(static_cast<int>(b))) +
                           "]: body " + std::to_string(s.id_of(static_cast<int>(b))) +
                           " is a member of clump " + std::to_string(cl[b]) +
                           ", which moves it; set the clump's state (set_clump_state)");
}
}  // namespace

// ---- materials, bodies, walls ---------------------------------------------------------------

int Scene::add_material(const Material& m) {
  m.validate();
  materials_.push_back(m);
  ++phys_version_;
  return static_cast<int>(materials_.size()) - 1;
}

void Scene::set_pair_law(int a, int b, PairLaw law) {
  material(a);
  material(b);
  law.validate();
  if (a > b) std::swap(a, b);
  law.a = a;
  law.b = b;
  const Material &ma = materials_[a], &mb = materials_[b];
  const ContactModel m = law.model_set ? law.model
                         : ma.model == mb.model ? ma.model
                                                : ContactModel::Linear;
  if ((law.kn >= 0 || law.ks >= 0) && m != ContactModel::Linear)
    throw ParameterError("pair law " + std::to_string(a) + "-" + std::to_string(b) +
                         ": kn and ks are the linear law's stiffnesses (N/m); this pair's law is '" +
                         law_info(m).name + "' (give model='linear', or leave kn and ks unset)");
  for (PairLaw& l : pair_laws_)
    if (l.a == a && l.b == b) {
      l = law;
      ++phys_version_;
      return;
    }
  pair_laws_.push_back(law);
  ++phys_version_;
}

const Material& Scene::material(int id) const {
  if (id < 0 || id >= num_materials())
    throw ParameterError("material=" + std::to_string(id) + ": no such material (the scene has " +
                         std::to_string(num_materials()) + ")");
  return materials_[id];
}

int Scene::add_spheres(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                       int material) {
  const Material& mat = this->material(material);
  if (pos.size() != radius.size())
    throw ParameterError("radius: has " + std::to_string(radius.size()) +
                         " values for " + std::to_string(pos.size()) + " centres");
  for (size_t k = 0; k < pos.size(); ++k) {
    require(std::isfinite(radius[k]) && radius[k] > 0, "radius", radius[k], "must be > 0 (m)");
    if (!pos[k].allFinite())
      throw ParameterError("position of sphere " + std::to_string(k) + ": must be finite");
  }
  const int first = num_bodies();
  for (size_t k = 0; k < pos.size(); ++k) {
    const Real r = radius[k];
    const Real m = sphere_mass(mat.density, r);
    push_body(pos[k], r, m, 0.4 * m * r * r, material, BODY_SPHERE);
    // (after the first, whose push tells the per-body arrays: room for the rest at once)
    if (k == 0) reserve_bodies(pos.size() - 1);
  }
  dirty_ = true;
  return first;
}

void Scene::reserve_bodies(std::size_t count) {
  bodies_.reserve_more(count);
  const std::size_t n = static_cast<std::size_t>(num_bodies());
  for (auto* v : {&id_of_slot_, &slot_of_id_})  // (kept once the storage order is not the ids')
    reserve_per_body(*v, n, count);
}

void Scene::push_body(const Vec3& x, Real radius, Real mass, Real inertia, int material,
                      std::uint8_t kind) {
  if (!id_of_slot_.empty()) {
    // A new body is stored at the end, under its own id.
    id_of_slot_.push_back(num_bodies());
    slot_of_id_.push_back(num_bodies());
  }
  bodies_.push(x, radius, mass, inertia, material, kind);
  // (the energy accumulators, once allocated, keep one entry per body)
  if (track_energy_ || !bodies_.ke.empty()) bodies_.size_energy();
  bond_topology_dirty_ = true;  // the bonds' adjacency is per body
}

int Scene::add_wall(int axis, Real position, int sense, int material) {
  if (axis < 0 || axis > 2)
    throw ParameterError("axis=" + std::to_string(axis) + ": must be 0 (x), 1 (y) or 2 (z)");
  if (sense != 1 && sense != -1)
    throw ParameterError("sense=" + std::to_string(sense) +
                         ": must be +1 (spheres on the +axis side) or -1");
  require(std::isfinite(position), "position", position, "must be finite (m)");
  this->material(material);
  if (cell_.on && cell_.periodic[axis])
    throw ParameterError("axis=" + std::to_string(axis) +
                         ": the periodic cell repeats along this axis; walls may only be "
                         "normal to axes that are not periodic");
  Wall w;
  w.axis = axis;
  w.sense = sense;
  w.position = position;
  w.material = material;
  walls_.push_back(w);
  wall_openings_.emplace_back();
  dirty_ = true;
  return num_walls() - 1;
}

void Scene::set_wall_opening(int id, int axis, Real lo, Real hi) {
  const Wall& w = wall(id);
  if (axis == -1) {
    wall_openings_[id] = WallOpening{};
    return;
  }
  if (axis < 0 || axis > 2 || axis == w.axis)
    throw ParameterError("axis=" + std::to_string(axis) + " (opening of wall " +
                         std::to_string(id) + "): must be 0 (x), 1 (y) or 2 (z) and not the "
                         "wall's own axis " + std::to_string(w.axis) + ", or -1 to close it");
  require(std::isfinite(lo), "lo", lo, "must be finite (m)");
  const std::string above = "must be finite and above lo=" + fmt_real(lo) + " (m)";
  require(std::isfinite(hi) && hi > lo, "hi", hi, above.c_str());
  WallOpening o;
  o.axis = axis;
  o.lo = lo;
  o.hi = hi;
  wall_openings_[id] = o;
}

const WallOpening& Scene::wall_opening(int id) const {
  (void)wall(id);  // checks id
  return wall_openings_[id];
}

Wall& Scene::wall(int id) {
  if (id < 0 || id >= num_walls())
    throw ParameterError("wall=" + std::to_string(id) + ": no such wall (the scene has " +
                         std::to_string(num_walls()) + ")");
  return walls_[id];
}
const Wall& Scene::wall(int id) const { return const_cast<Scene*>(this)->wall(id); }

void Scene::set_positions(const std::vector<Vec3>& v) {
  require_size(v, bodies_.pos.size(), "positions");
  for (const auto& x : v)
    if (!x.allFinite()) throw ParameterError("positions: must be finite (m)");
  check_members_unchanged(*this, bodies_.pos, v, "positions");
  bodies_.pos = v;
  dirty_ = true;
}
namespace {
/// ParameterError naming the field and the first body (by slot order of v: its id) whose
/// vector is not finite.
void require_finite(const Scene& s, const std::vector<Vec3>& v, const char* field,
                    const char* unit) {
  for (size_t k = 0; k < v.size(); ++k)
    if (!v[k].allFinite())
      throw ParameterError(std::string(field) + ": body " +
                           std::to_string(s.id_of(static_cast<int>(k))) + " has (" +
                           std::to_string(v[k][0]) + ", " + std::to_string(v[k][1]) + ", " +
                           std::to_string(v[k][2]) + "); must be finite (" + unit + ")");
}
}  // namespace

void Scene::set_velocities(const std::vector<Vec3>& v) {
  require_size(v, bodies_.pos.size(), "velocities");
  require_finite(*this, v, "velocities", "m/s");
  check_members_unchanged(*this, bodies_.vel, v, "velocities");
  bodies_.vel = v;
}
void Scene::set_angular_velocities(const std::vector<Vec3>& v) {
  require_size(v, bodies_.pos.size(), "angular_velocities");
  require_finite(*this, v, "angular_velocities", "rad/s");
  check_members_unchanged(*this, bodies_.angvel, v, "angular_velocities");
  bodies_.angvel = v;
}
void Scene::set_radii(const std::vector<Real>& r) {
  require_size(r, bodies_.pos.size(), "radii");
  for (Real x : r) require(std::isfinite(x) && x > 0, "radius", x, "must be > 0 (m)");
  // A clump scales about its centre of mass by one factor, its members' radius ratio.
  std::vector<Real> clump_factor(clumps_.size(), 1.0);
  for (int c = 0; c < clumps_.size(); ++c) {
    const int e0 = clumps_.member_off[c], e1 = clumps_.member_off[c + 1];
    const int s0 = clumps_.member[e0];
    const Real f = r[s0] / bodies_.radius[s0];
    for (int e = e0 + 1; e < e1; ++e) {
      const int s = clumps_.member[e];
      if (std::abs(r[s] / bodies_.radius[s] - f) > 1e-12 * f)
        throw ParameterError("radius[" + std::to_string(id_of(s)) + "]=" + fmt_real(r[s]) +
                             ": body " + std::to_string(id_of(s)) + " is a member of clump " +
                             std::to_string(c) + ", whose members must all scale by one factor (" +
                             fmt_real(f) + ", from member " + std::to_string(id_of(s0)) + ")");
    }
    clump_factor[c] = f;
  }
  // (The radii at the last build, kept from the first change on: the broad phase's
  // measure of growth, Scene::radius_growth_since_build.)
  if (radius_at_build_.empty())
    radius_at_build_.assign(bodies_.radius.begin(), bodies_.radius.begin() + pos_at_build_.size());
  for (size_t b = 0; b < r.size(); ++b) {
    if (bodies_.clump[b] >= 0) {
      const Real f = clump_factor[bodies_.clump[b]];
      bodies_.radius[b] = r[b];
      bodies_.mass[b] *= f * f * f;
      bodies_.inertia[b] = 0.4 * bodies_.mass[b] * r[b] * r[b];
      continue;
    }
    if (bodies_.kind[b] != BODY_SPHERE) {
      // Grid nodes keep their lumped mass; their radius is the geogrid's R_c.
      if (r[b] != bodies_.radius[b])
        throw ParameterError("radius[" + std::to_string(id_of(b)) + "]=" + std::to_string(r[b]) +
                             ": body " + std::to_string(id_of(b)) +
                             " is a grid node; its radius (the geogrid's R_c) cannot change");
      continue;
    }
    bodies_.radius[b] = r[b];
    bodies_.mass[b] = sphere_mass(materials_[bodies_.material[b]].density, r[b]);
    bodies_.inertia[b] = 0.4 * bodies_.mass[b] * r[b] * r[b];
  }
  for (int c = 0; c < clumps_.size(); ++c) {
    const Real f = clump_factor[c];
    if (f == 1.0) continue;
    const Real f3 = f * f * f;
    clumps_.mass[c] *= f3;
    clumps_.inertia[c] *= f3 * f * f;
    clumps_.stiffness_radius[c] *= f;
    clumps_.angmom[c] *= f3 * f * f;  // the spin is kept
    for (int e = clumps_.member_off[c]; e < clumps_.member_off[c + 1]; ++e) clumps_.member_local[e] *= f;
    place_members(c);
  }
  disp_valid_ = false;  // grown radii count in the broad phase's check
  min_radius_ = -1;
  default_margin_ = -1;
  ++phys_version_;
}
void Scene::set_blocked(int body, std::uint8_t mask) {
  check_body(body);
  if (const int c = bodies_.clump[slot_of(body)]; c >= 0)
    throw ParameterError("body=" + std::to_string(body) + ": is a member of clump " +
                         std::to_string(c) + "; block the clump (set_clump_blocked)");
  if (mask > DOF_ALL)
    throw ParameterError("blocked=" + std::to_string(mask) + ": must be a mask of x y z rx ry rz");
  bodies_.blocked[slot_of(body)] = mask;
  ds_stale_ = ds_on_;  // (its inertia factor follows at the next step's start)
}
void Scene::set_external_forces(const std::vector<Vec3>& f) {
  require_size(f, bodies_.pos.size(), "external_forces");
  require_finite(*this, f, "external_forces", "N");
  bodies_.ext_force = f;
}
void Scene::set_body_velocity(int body, const Vec3& v) {
  check_body(body);
  if (!v.allFinite()) throw ParameterError("velocity of body " + std::to_string(body) +
                                           ": must be finite (m/s)");
  bodies_.vel[slot_of(body)] = v;
}
void Scene::set_body_external_force(int body, const Vec3& f) {
  check_body(body);
  if (!f.allFinite()) throw ParameterError("external force of body " + std::to_string(body) +
                                           ": must be finite (N)");
  if (bodies_.ext_force.empty()) bodies_.ext_force.assign(bodies_.pos.size(), Vec3::Zero());
  bodies_.ext_force[slot_of(body)] = f;
}
void Scene::inject_unchecked(const std::string& field, int body, int axis, Real value) {
  check_body(body);
  if (axis < 0 || axis > 2) throw ParameterError("axis=" + std::to_string(axis) + ": 0, 1 or 2");
  const int b = slot_of(body);
  if (field == "velocities") {
    bodies_.vel[b][axis] = value;
  } else if (field == "angular_velocities") {
    bodies_.angvel[b][axis] = value;
  } else if (field == "external_forces") {
    if (bodies_.ext_force.empty()) bodies_.ext_force.assign(bodies_.pos.size(), Vec3::Zero());
    bodies_.ext_force[b][axis] = value;
  } else if (field == "external_torques") {
    if (bodies_.ext_torque.empty()) bodies_.ext_torque.assign(bodies_.pos.size(), Vec3::Zero());
    bodies_.ext_torque[b][axis] = value;
  } else {
    throw ParameterError("field='" + field + "': velocities, angular_velocities, "
                         "external_forces or external_torques");
  }
}
void Scene::set_external_torques(const std::vector<Vec3>& t) {
  require_size(t, bodies_.pos.size(), "external_torques");
  require_finite(*this, t, "external_torques", "N m");
  bodies_.ext_torque = t;
}
void Scene::set_body_material(int body, int material) {
  check_body(body);
  this->material(material);
  if (const int c = bodies_.clump[slot_of(body)]; c >= 0) {
    // A member keeps its share of the clump's mass: only a material of the same density.
    const int s = slot_of(body);
    const Real rho_old = materials_[bodies_.material[s]].density;
    if (materials_[material].density != rho_old)
      throw ParameterError("material=" + std::to_string(material) + ": body " +
                           std::to_string(body) + " is a member of clump " + std::to_string(c) +
                           ", whose mass is fixed; the new material's density " +
                           fmt_real(materials_[material].density) + " kg/m^3 must equal " +
                           fmt_real(rho_old) + " kg/m^3");
    bodies_.material[s] = material;
    ++phys_version_;
    return;
  }
  body = slot_of(body);
  bodies_.material[body] = material;
  bodies_.mass[body] = sphere_mass(materials_[material].density, bodies_.radius[body]);
  bodies_.inertia[body] = 0.4 * bodies_.mass[body] * bodies_.radius[body] * bodies_.radius[body];
  ++phys_version_;
}
void Scene::set_mass_inertia(int body, Real mass, Real inertia) {
  check_body(body);
  if (const int c = bodies_.clump[slot_of(body)]; c >= 0)
    throw ParameterError("body=" + std::to_string(body) + ": is a member of clump " +
                         std::to_string(c) + "; its mass is a share of the clump's");
  require(std::isfinite(mass) && mass > 0, "mass", mass, "must be > 0 (kg)");
  require(std::isfinite(inertia) && inertia > 0, "inertia", inertia, "must be > 0 (kg m^2)");
  body = slot_of(body);
  bodies_.mass[body] = mass;
  bodies_.inertia[body] = inertia;
  ++phys_version_;
}
void Scene::check_body(int b) const {
  if (b < 0 || b >= num_bodies())
    throw ParameterError("body=" + std::to_string(b) + ": no such body (the scene has " +
                         std::to_string(num_bodies()) + ")");
}

}  // namespace cpp_dem
