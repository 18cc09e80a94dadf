#include "cpp_dem/control/controllers.hpp"

#include <algorithm>
#include <iterator>
#include <cmath>
#include <string>

namespace cpp_dem {

namespace {
void check_box_walls(const Scene& s, const std::vector<int>& walls, const char* field) {
  if (walls.size() != 6)
    throw ParameterError(std::string(field) + ": expected the 6 walls of a box (x-, x+, y-, "
                         "y+, z-, z+), got " + std::to_string(walls.size()));
  for (int k = 0; k < 6; ++k) {
    const Wall& w = s.wall(walls[k]);
    const int axis = k / 2, sense = (k % 2 == 0) ? 1 : -1;
    if (w.axis != axis || w.sense != sense)
      throw ParameterError(std::string(field) + "[" + std::to_string(k) + "]=wall " +
                           std::to_string(walls[k]) + ": expected the wall of axis " +
                           std::to_string(axis) + " with sense " + std::to_string(sense) +
                           " (order x-, x+, y-, y+, z-, z+, as Scene.add_box)");
  }
}

void check_gain(Real g) {
  require(std::isfinite(g) && g > 0 && g <= 1, "gain", g, "must be in (0, 1]");
}
void check_speed(Real v) {
  require(std::isfinite(v) && v > 0, "max_speed", v, "must be > 0 (m/s)");
}
void check_stress(Real s, const char* field) {
  require(std::isfinite(s) && s >= 0, field, s,
          "must be >= 0 (Pa, compressive positive; walls cannot pull on the spheres)");
}

/// Area of the box wall k (order x-, x+, ...) from the current box size, m^2.
Real box_wall_area(const Vec3& size, int k) {
  const int a = k / 2;
  return size[(a + 1) % 3] * size[(a + 2) % 3];
}
}  // namespace

Real wall_normal_stress(const Wall& w, Real area) {
  // The spheres push the wall against its normal (towards -sense): that is compression.
  return -w.sense * w.force[w.axis] / area;
}

Real wall_contact_stiffness(const Scene& s, int wall, ContactKind kind) {
  Real k = 0;
  s.for_each_contact_of(kind, [&](const ContactRecord& c) {
    if (!c.active || c.other != wall) return;
    Real kn, ks;
    c.stiffness(kn, ks);
    k += kn;
  });
  return k;
}

Real servo_speed(Real sigma_target, Real sigma, Real area, Real stiffness, Real dt, int period,
                 Real gain, Real max_speed) {
  const Real err = sigma_target - sigma;  // > 0: push further in
  Real v;
  if (stiffness > 0) {
    v = gain * err * area / (stiffness * dt * period);
  } else {
    v = err > 0 ? max_speed : 0.0;
  }
  // The cap applies to every branch (Yade's max_vel does not cap all of them).
  return std::clamp(v, -max_speed, max_speed);
}

// ---- StressServo, ServoWall ----------------------------------------------------------------

StressServo::StressServo(Real target, const char* field, Real gain, Real max_speed)
    : target_(target), gain_(gain), max_speed_(max_speed) {
  check_stress(target, field);
  check_gain(gain);
  check_speed(max_speed);
}

void StressServo::set_target(Real target, const char* field) {
  check_stress(target, field);
  target_ = target;
}
void StressServo::set_max_speed(Real v) {
  check_speed(v);
  max_speed_ = v;
}
void StressServo::set_gain(Real g) {
  check_gain(g);
  gain_ = g;
}

Real StressServo::speed(const Scene& scene, Real measured, Real area, Real k) {
  stiffness_ = k;
  const Real v = servo_speed(target_, measured, area, k, scene.dt(), period, gain_, max_speed_);
  limit_.observe(v, max_speed_, measured, target_);
  return v;
}

ServoWall::ServoWall(int wall, Real target_stress, Real area, Real gain, Real max_speed,
                     std::vector<int> box_walls)
    : StressServo(target_stress, "target_stress", gain, max_speed), wall_(wall), area0_(area),
      box_(std::move(box_walls)) {
  if (box_.empty())
    require(std::isfinite(area) && area > 0, "area", area,
            "must be > 0 (m^2), or give box_walls to compute it from the box");
  else if (box_.size() != 6)
    throw ParameterError("box_walls: expected 6 walls (x-, x+, y-, y+, z-, z+), got " +
                         std::to_string(box_.size()));
}

void ServoWall::apply(Scene& scene) {
  Wall& w = scene.wall(wall_);
  if (box_.empty()) {
    area_ = area0_;
  } else {
    const Vec3 size = TriaxialController::box_size(scene, box_);
    int k = -1;
    for (int i = 0; i < 6; ++i)
      if (box_[i] == wall_) k = i;
    if (k < 0) k = 2 * w.axis;  // a wall outside the box: area normal to its axis
    area_ = box_wall_area(size, k);
  }
  sigma_ = wall_normal_stress(w, area_);
  const Real v = speed(scene, sigma_, area_, wall_contact_stiffness(scene, wall_));
  w.velocity.setZero();
  w.velocity[w.axis] = w.sense * v;
}

// ---- CylinderServo ---------------------------------------------------------------------------

CylinderServo::CylinderServo(int cylinder, Real target_pressure, Real gain, Real max_speed)
    : StressServo(target_pressure, "target_pressure", gain, max_speed), cylinder_(cylinder) {}

void CylinderServo::apply(Scene& scene) {
  CylinderWall& w = scene.cylinder_wall(cylinder_);
  if (!w.finite())
    throw ParameterError("CylinderServo: cylindrical wall " + std::to_string(cylinder_) +
                         " is infinite (lo=" + fmt_real(w.lo) + ", hi=" + fmt_real(w.hi) +
                         "): a pressure needs a finite lateral area; give it lo and hi");
  const Real area = w.lateral_area();
  p_ = w.normal_force / area;
  // The speed into the grains (inside: a smaller radius).
  const Real v = speed(scene, p_, area,
                       wall_contact_stiffness(scene, cylinder_, ContactKind::Cylinder));
  w.radial_velocity = w.inside ? -v : v;
}

// ---- MeshServo -------------------------------------------------------------------------------

MeshServo::MeshServo(int mesh, Vec3 direction, Real target_stress, Real area, Real gain,
                     Real max_speed)
    : StressServo(target_stress, "target_stress", gain, max_speed), mesh_(mesh), area_(area) {
  const Real len = direction.norm();
  if (!(std::isfinite(len) && len > 0))
    throw ParameterError("direction=(" + fmt_real(direction[0]) + ", " + fmt_real(direction[1]) +
                         ", " + fmt_real(direction[2]) + "): must be a finite non-zero vector "
                         "(into the grains)");
  direction_ = direction / len;
  require(std::isfinite(area) && area > 0, "area", area, "must be > 0 (m^2)");
}

void MeshServo::apply(Scene& scene) {
  MeshWall& w = scene.mesh_wall(mesh_);
  // The spheres push the mesh back against the direction it goes into them.
  sigma_ = -w.force.dot(direction_) / area_;
  const Real v = speed(scene, sigma_, area_,
                       wall_contact_stiffness(scene, mesh_, ContactKind::Mesh));
  w.velocity = v * direction_;
}

// ---- MembranePressure, PlatenClamp -------------------------------------------------------------

MembranePressure::MembranePressure(std::vector<std::array<int, 3>> triangles, Real pressure_pa)
    : tris_(std::move(triangles)) {
  if (tris_.empty()) throw ParameterError("triangles: empty (a membrane needs at least one)");
  for (size_t t = 0; t < tris_.size(); ++t) {
    const auto& n = tris_[t];
    for (int a = 0; a < 3; ++a) {
      if (n[a] < 0)
        throw ParameterError("triangles[" + std::to_string(t) + "]=(" + std::to_string(n[0]) +
                             ", " + std::to_string(n[1]) + ", " + std::to_string(n[2]) +
                             "): body ids must be >= 0");
      nodes_.push_back(n[a]);
    }
    if (n[0] == n[1] || n[1] == n[2] || n[0] == n[2])
      throw ParameterError("triangles[" + std::to_string(t) + "]=(" + std::to_string(n[0]) +
                           ", " + std::to_string(n[1]) + ", " + std::to_string(n[2]) +
                           "): three different bodies");
  }
  std::sort(nodes_.begin(), nodes_.end());
  nodes_.erase(std::unique(nodes_.begin(), nodes_.end()), nodes_.end());
  // Each corner's place in nodes_, once (apply sums into force_ by it every step).
  at_.reserve(tris_.size());
  for (const auto& n : tris_) {
    std::array<int, 3> k;
    for (int c = 0; c < 3; ++c)
      k[c] = static_cast<int>(std::lower_bound(nodes_.begin(), nodes_.end(), n[c]) -
                              nodes_.begin());
    at_.push_back(k);
  }
  set_pressure(pressure_pa);
}

void MembranePressure::set_pressure(Real p) {
  require(std::isfinite(p), "pressure_pa", p, "must be finite (Pa, compressive positive)");
  pressure_ = p;
}

void MembranePressure::apply(Scene& scene) {
  const auto& pos = scene.positions();
  force_.assign(nodes_.size(), Vec3::Zero());
  area_ = 0;
  area_vec_.setZero();
  if (nodes_.back() >= scene.num_bodies())  // (nodes_ ascending: its last is the largest id)
    for (const auto& n : tris_)
      if (n[0] >= scene.num_bodies() || n[1] >= scene.num_bodies() || n[2] >= scene.num_bodies())
        throw ParameterError("MembranePressure: triangle (" + std::to_string(n[0]) + ", " +
                             std::to_string(n[1]) + ", " + std::to_string(n[2]) +
                             ") names a body the scene does not have (" +
                             std::to_string(scene.num_bodies()) + " bodies)");
  // In triangle order: the same sums on any thread count.
  for (size_t t = 0; t < tris_.size(); ++t) {
    const auto& n = tris_[t];
    const Vec3& x0 = pos[scene.slot_of(n[0])];
    const Vec3 a = 0.5 * (pos[scene.slot_of(n[1])] - x0).cross(pos[scene.slot_of(n[2])] - x0);
    area_ += a.norm();
    area_vec_ += a;
    const Vec3 share = (-pressure_ / 3.0) * a;
    for (int k = 0; k < 3; ++k) force_[at_[t][k]] += share;
  }
  for (size_t k = 0; k < nodes_.size(); ++k) scene.set_body_external_force(nodes_[k], force_[k]);
}

std::vector<Real> PlatenClamp::save_state() const {
  std::vector<Real> st{started_ ? 1.0 : 0.0, wall_start_};
  for (const Vec3& x : start_) st.insert(st.end(), {x[0], x[1], x[2]});
  return st;
}

void PlatenClamp::load_state(const std::vector<Real>& st) {
  const bool on = !st.empty() && st[0] != 0;
  const size_t want = on ? 2 + 3 * bodies_.size() : 2;
  if (st.size() != want)
    throw ParameterError("PlatenClamp: a state of " + std::to_string(st.size()) +
                         " values, this clamp of " + std::to_string(bodies_.size()) +
                         " bodies takes " + std::to_string(want));
  started_ = on;
  wall_start_ = st[1];
  start_.clear();
  if (on)
    for (size_t k = 0; k < bodies_.size(); ++k)
      start_.emplace_back(st[2 + 3 * k], st[3 + 3 * k], st[4 + 3 * k]);
}

PlatenClamp::PlatenClamp(int wall, std::vector<int> bodies) : wall_(wall), bodies_(std::move(bodies)) {
  require(wall >= 0, "wall", wall, "must be a wall id (>= 0)");
  if (bodies_.empty()) throw ParameterError("bodies: empty (the bodies to hold to the wall)");
  for (int b : bodies_) require(b >= 0, "bodies", b, "body ids must be >= 0");
}

void PlatenClamp::apply(Scene& scene) {
  const Wall& w = scene.wall(wall_);
  if (!started_) {
    for (int b : bodies_) {
      if (b >= scene.num_bodies())
        throw ParameterError("PlatenClamp: body " + std::to_string(b) +
                             " does not exist (the scene has " +
                             std::to_string(scene.num_bodies()) + " bodies)");
      const int s = scene.slot_of(b);
      if (scene.clumps_of_bodies()[s] >= 0)
        throw ParameterError("PlatenClamp: body " + std::to_string(b) +
                             " is a member of a clump; hold free bodies (grid nodes)");
      scene.set_blocked(b, static_cast<std::uint8_t>(scene.blocked()[s] | (DOF_X << w.axis)));
      start_.push_back(scene.positions()[s]);
    }
    wall_start_ = w.position;
    started_ = true;
  }
  const int ax = w.axis;
  const Real moved = w.position - wall_start_;
  const Real dt = scene.dt();
  max_offset_ = 0;
  for (size_t k = 0; k < bodies_.size(); ++k) {
    const Real now = scene.positions()[scene.slot_of(bodies_[k])][ax];
    const Real off = start_[k][ax] + moved - now;
    max_offset_ = std::max(max_offset_, std::abs(off));
    Vec3 v = scene.velocities()[scene.slot_of(bodies_[k])];
    v[ax] = w.velocity[ax] + (dt > 0 ? off / dt : 0.0);
    scene.set_body_velocity(bodies_[k], v);
  }
}

// ---- TriaxialController ---------------------------------------------------------------------

TriaxialController::TriaxialController(std::vector<int> walls, Real gain, Real max_speed)
    : walls_(std::move(walls)), gain_(gain), max_speed_(max_speed) {
  if (walls_.size() != 6)
    throw ParameterError("walls: expected the 6 walls of a box (x-, x+, y-, y+, z-, z+), got " +
                         std::to_string(walls_.size()));
  check_gain(gain);
  check_speed(max_speed);
}

Vec3 TriaxialController::box_size(const Scene& s, const std::vector<int>& walls) {
  Vec3 size;
  for (int a = 0; a < 3; ++a) size[a] = s.wall(walls[2 * a + 1]).position - s.wall(walls[2 * a]).position;
  return size;
}

std::array<Real, 6> TriaxialController::wall_stresses(const Scene& s,
                                                      const std::vector<int>& walls) {
  const Vec3 size = box_size(s, walls);
  std::array<Real, 6> out{};
  for (int k = 0; k < 6; ++k) out[k] = wall_normal_stress(s.wall(walls[k]), box_wall_area(size, k));
  return out;
}

Vec3 TriaxialController::axis_stresses(const Scene& s, const std::vector<int>& walls) {
  const auto st = wall_stresses(s, walls);
  return Vec3(0.5 * (st[0] + st[1]), 0.5 * (st[2] + st[3]), 0.5 * (st[4] + st[5]));
}

void TriaxialController::reset_strain(const Scene& s) {
  check_box_walls(s, walls_, "walls");
  l0_ = box_size(s, walls_);
  l0_set_ = true;
}

Vec3 TriaxialController::strains(const Scene& s) const {
  if (!l0_set_) return Vec3::Zero();
  const Vec3 size = box_size(s, walls_);
  return Vec3((l0_[0] - size[0]) / l0_[0], (l0_[1] - size[1]) / l0_[1], (l0_[2] - size[2]) / l0_[2]);
}

void TriaxialController::set_stress(int axis, Real sigma) {
  if (axis < 0 || axis > 2)
    throw ParameterError("axis=" + std::to_string(axis) + ": must be 0 (x), 1 (y) or 2 (z)");
  check_stress(sigma, "stress");
  mode_[axis] = Mode::Stress;
  goal_[axis] = sigma;
}

void TriaxialController::set_strain_rate(int axis, Real rate) {
  if (axis < 0 || axis > 2)
    throw ParameterError("axis=" + std::to_string(axis) + ": must be 0 (x), 1 (y) or 2 (z)");
  require(std::isfinite(rate), "strain_rate", rate, "must be finite (1/s)");
  mode_[axis] = Mode::StrainRate;
  goal_[axis] = rate;
}

TriaxialController::Mode TriaxialController::mode(int axis) const {
  if (axis < 0 || axis > 2)
    throw ParameterError("axis=" + std::to_string(axis) + ": must be 0 (x), 1 (y) or 2 (z)");
  return mode_[axis];
}
Real TriaxialController::goal(int axis) const {
  mode(axis);
  return goal_[axis];
}
void TriaxialController::set_max_speed(Real v) {
  check_speed(v);
  max_speed_ = v;
}
void TriaxialController::set_gain(Real g) {
  check_gain(g);
  gain_ = g;
}

void TriaxialController::apply(Scene& scene) {
  if (!l0_set_) reset_strain(scene);
  const Vec3 size = box_size(scene, walls_);
  const Real cap = effective_max_speed();
  // The walls are watched for drift at their cap while the box is loaded (an axis under
  // strain-rate control); a stress-only stage (a preparation) settles as it may.
  const bool loading = mode_[0] == Mode::StrainRate || mode_[1] == Mode::StrainRate ||
                       mode_[2] == Mode::StrainRate;
  std::array<Real, 6> v{};  // along each wall's inward normal, m/s
  std::array<Real, 6> sigma{};
  for (int k = 0; k < 6; ++k) {
    const int a = k / 2;
    if (mode_[a] == Mode::StrainRate) {
      v[k] = 0.5 * goal_[a] * l0_[a];
    } else if (!symmetric_) {
      const Real area = box_wall_area(size, k);
      sigma[k] = wall_normal_stress(scene.wall(walls_[k]), area);
      v[k] = servo_speed(goal_[a], sigma[k], area, wall_contact_stiffness(scene, walls_[k]),
                         scene.dt(), period, gain_, cap);
    } else if (k % 2 == 1) {
      // both walls of the axis at one speed, from the axis's mean stress and their mean
      // contact stiffness (the mean stress changes by k_mean v / area)
      const Real area = box_wall_area(size, k);
      const Real s0 = wall_normal_stress(scene.wall(walls_[k - 1]), area);
      const Real s1 = wall_normal_stress(scene.wall(walls_[k]), area);
      const Real kmean = 0.5 * (wall_contact_stiffness(scene, walls_[k - 1]) +
                                wall_contact_stiffness(scene, walls_[k]));
      sigma[k - 1] = sigma[k] = 0.5 * (s0 + s1);
      v[k - 1] = v[k] = servo_speed(goal_[a], sigma[k], area, kmean, scene.dt(), period,
                                    gain_, cap);
    }
  }
  for (int k = 0; k < 6; ++k) {
    const int a = k / 2;
    if (mode_[a] == Mode::Stress && loading) limit_[k].observe(v[k], cap, sigma[k], goal_[a]);
    Wall& w = scene.wall(walls_[k]);
    w.velocity.setZero();
    w.velocity[w.axis] = w.sense * v[k];
  }
}

Real TriaxialController::effective_max_speed() const {
  Real cap = max_speed_;
  for (int a = 0; a < 3; ++a)
    if (mode_[a] == Mode::StrainRate) cap = std::max(cap, std::abs(goal_[a]) * l0_.maxCoeff());
  return cap;
}

std::vector<Real> TriaxialController::save_state() const {
  std::vector<Real> s;
  for (int a = 0; a < 3; ++a) {
    s.push_back(static_cast<Real>(mode_[a]));
    s.push_back(goal_[a]);
    s.push_back(l0_[a]);
  }
  s.push_back(l0_set_ ? 1.0 : 0.0);
  s.push_back(gain_);
  s.push_back(max_speed_);
  s.push_back(symmetric_ ? 1.0 : 0.0);
  return s;
}

void TriaxialController::load_state(const std::vector<Real>& s) {
  // (12 values: a checkpoint written before the axis-mean servo, which is then off)
  if (s.size() != 12 && s.size() != 13)
    throw ParameterError("TriaxialController state: expected 12 or 13 values, got " +
                         std::to_string(s.size()));
  for (int a = 0; a < 3; ++a) {
    mode_[a] = static_cast<Mode>(static_cast<int>(s[3 * a]));
    goal_[a] = s[3 * a + 1];
    l0_[a] = s[3 * a + 2];
  }
  l0_set_ = s[9] != 0;
  gain_ = s[10];
  max_speed_ = s[11];
  symmetric_ = s.size() == 13 && s[12] != 0;
}

// ---- which controller moves which wall -------------------------------------------------------

std::vector<int> controlled_walls(const Controller& c) {
  if (const auto* s = dynamic_cast<const ServoWall*>(&c)) return {s->wall()};
  if (const auto* s = dynamic_cast<const CylinderServo*>(&c)) return {-1 - s->cylinder()};
  if (const auto* s = dynamic_cast<const MeshServo*>(&c)) return {kMeshWallCode - s->mesh()};
  if (const auto* t = dynamic_cast<const TriaxialController*>(&c)) return t->walls();
  return {};
}

namespace {
std::string controller_name(const Controller& c) {
  if (dynamic_cast<const ServoWall*>(&c)) return "ServoWall";
  if (dynamic_cast<const CylinderServo*>(&c)) return "CylinderServo";
  if (dynamic_cast<const MeshServo*>(&c)) return "MeshServo";
  if (dynamic_cast<const TriaxialController*>(&c)) return "TriaxialController";
  if (dynamic_cast<const RadiusGrowth*>(&c)) return "RadiusGrowth";
  if (dynamic_cast<const CellController*>(&c)) return "CellController";
  if (dynamic_cast<const MembranePressure*>(&c)) return "MembranePressure";
  if (dynamic_cast<const PlatenClamp*>(&c)) return "PlatenClamp";
  return "Controller";
}
}  // namespace

namespace {
/// Whether both controllers move a wall; the first such wall's name ("wall 3", "cylindrical
/// wall 0": controlled_walls gives a cylinder k as -1 - k) in `name`.
bool shared_wall(const Controller& a, const Controller& b, std::string& name) {
  const std::vector<int> wa = controlled_walls(a);
  for (int w : controlled_walls(b))
    if (std::find(wa.begin(), wa.end(), w) != wa.end()) {
      name = w >= 0                ? "wall " + std::to_string(w)
             : w > kMeshWallCode ? "cylindrical wall " + std::to_string(-1 - w)
                                 : "mesh wall " + std::to_string(kMeshWallCode - w);
      return true;
    }
  return false;
}
}  // namespace

namespace {
/// The bodies a controller sets a force or a velocity of (a membrane's nodes, a clamp's
/// bodies), ascending, and what it sets.
std::vector<int> controlled_bodies(const Controller& c, const char*& what) {
  if (const auto* m = dynamic_cast<const MembranePressure*>(&c)) {
    what = "external force";
    return m->nodes();
  }
  if (const auto* k = dynamic_cast<const PlatenClamp*>(&c)) {
    what = "velocity";
    std::vector<int> b = k->bodies();
    std::sort(b.begin(), b.end());
    return b;
  }
  return {};
}

/// Whether both controllers set the same thing of one body (two membranes' forces, two
/// clamps' velocities); the first such body's description in `name`.
bool shared_body(const Controller& a, const Controller& b, std::string& name) {
  const char* wa = "";
  const char* wb = "";
  const std::vector<int> ba = controlled_bodies(a, wa), bb = controlled_bodies(b, wb);
  if (ba.empty() || bb.empty() || std::string(wa) != wb) return false;
  std::vector<int> both;
  std::set_intersection(ba.begin(), ba.end(), bb.begin(), bb.end(), std::back_inserter(both));
  if (both.empty()) return false;
  name = "the " + std::string(wa) + " of body " + std::to_string(both.front());
  return true;
}
}  // namespace

void check_new_controller(const Scene& s, const Controller& c) {
  for (int i = 0; i < s.num_controllers(); ++i) {
    const auto other = s.controller(i);
    if (other.get() == &c)
      throw ParameterError("controller: this " + controller_name(c) +
                           " is controller " + std::to_string(i) +
                           " of the scene already (it would run twice per step)");
    if (!c.enabled || !other->enabled) continue;
    std::string w;
    if (shared_wall(c, *other, w))
      throw ParameterError(
          "controller (" + controller_name(c) + "): " + w +
          " is moved by controller " + std::to_string(i) + " (" + controller_name(*other) +
          ") already; two controllers would set its velocity in turn. Disable one "
          "(controller.enabled = False) or remove them (scene.clear_controllers())");
    if (shared_body(c, *other, w))
      throw ParameterError(
          "controller (" + controller_name(c) + "): " + w + " is set by controller " +
          std::to_string(i) + " (" + controller_name(*other) + ") already; the later would "
          "replace the earlier's every step. Give each body to one controller, disable one "
          "(controller.enabled = False) or remove them (scene.clear_controllers())");
  }
}

void check_enabled_controllers(const Scene& s) {
  for (int i = 0; i < s.num_controllers(); ++i) {
    const auto a = s.controller(i);
    if (!a->enabled) continue;
    for (int j = i + 1; j < s.num_controllers(); ++j) {
      const auto b = s.controller(j);
      if (!b->enabled) continue;
      // two enabled controllers on one wall, or on one body's force or velocity
      const auto refuse = [&](const std::string& verb, const std::string& what,
                              const std::string& why) {
        throw ParameterError(
            "controllers " + std::to_string(i) + " (" + controller_name(*a) + ") and " +
            std::to_string(j) + " (" + controller_name(*b) + ") are both enabled and both " +
            verb + " " + what + "; " + why + ". "
            "Disable one (controller.enabled = False) before running");
      };
      std::string w;
      if (shared_wall(*a, *b, w)) refuse("move", w, "they would set its velocity in turn");
      if (shared_body(*a, *b, w))
        refuse("set", w, "the later would replace the earlier's every step");
    }
  }
}

// ---- RadiusGrowth ---------------------------------------------------------------------------

RadiusGrowth::RadiusGrowth(std::vector<int> walls, std::vector<int> bodies, Real target_stress,
                           Real gain, Real max_strain)
    : walls_(std::move(walls)), bodies_(std::move(bodies)), target_(target_stress), gain_(gain),
      max_strain_(max_strain) {
  if (walls_.size() != 6 && !walls_.empty())
    throw ParameterError("walls: expected the 6 walls of a box (x-, x+, y-, y+, z-, z+), or "
                         "none in a periodic cell; got " + std::to_string(walls_.size()));
  require(std::isfinite(target_stress) && target_stress > 0, "target_stress", target_stress,
          "must be > 0 (Pa, compressive positive)");
  check_gain(gain);
  require(std::isfinite(max_strain) && max_strain > 0 && max_strain <= 0.1, "max_strain",
          max_strain, "must be in (0, 0.1] (radius strain per call)");
}

void RadiusGrowth::set_target_stress(Real sigma) {
  require(std::isfinite(sigma) && sigma > 0, "target_stress", sigma,
          "must be > 0 (Pa, compressive positive)");
  target_ = sigma;
}

void RadiusGrowth::apply(Scene& scene) {
  const auto& r = scene.radii();
  const auto& kind = scene.body_kinds();
  if (grown_only_) {
    grows_.assign(r.size(), 0);
    if (bodies_.empty()) {
      for (size_t b = 0; b < r.size(); ++b) grows_[b] = kind[b] == 0;
    } else {
      for (int b : bodies_)
        if (b >= 0 && b < static_cast<int>(r.size())) grows_[scene.slot_of(b)] = 1;
    }
  }
  // A contact counts unless grown_only and neither side grows (a wall contact: its sphere).
  const auto counts = [&](const ContactRecord& c) {
    return !grown_only_ || (c.body1 >= 0 && grows_[c.body1]) || grows_[c.body2];
  };
  Real volume;
  if (walls_.empty()) {
    if (!scene.is_periodic())
      throw ParameterError("RadiusGrowth: no walls given and the scene has no periodic cell");
    volume = scene.cell().volume();
    if (!grown_only_) {
      sigma_ = scene.cell_stress().trace() / 3.0;
    } else {
      // The grains' mean normal stress, the trace of (1/V) sum f l^T over their pair
      // contacts (no bonds) over 3: summed as Scene::cell_stress sums, so that with every
      // sphere growing and no bonds it is the cell's, bitwise.
      const auto& x = scene.positions();
      Mat3 fl = Mat3::Zero();
      scene.for_each_contact_of(ContactKind::Pair, [&](const ContactRecord& c) {
        if (c.active && counts(c))
          fl += c.force2 * (x[c.body2] + c.shift2 - x[c.body1]).transpose();
      });
      sigma_ = (fl / volume).trace() / 3.0;
    }
  } else {
    const auto st = TriaxialController::wall_stresses(scene, walls_);
    Real mean = 0;
    for (Real x : st) mean += x;
    sigma_ = mean / 6.0;
    const Vec3 size = TriaxialController::box_size(scene, walls_);
    volume = size[0] * size[1] * size[2];
  }
  // Stress increase per unit radius strain from the current contacts, Pa.
  Real s = 0;
  scene.for_each_contact_of(ContactKind::Pair, [&](const ContactRecord& c) {
    if (!c.active || !counts(c)) return;
    Real kn, ks;
    c.stiffness(kn, ks);
    const Real l = r[c.body1] + r[c.body2];
    s += kn * l * l;
  });
  scene.for_each_contact_of(ContactKind::Wall, [&](const ContactRecord& c) {
    if (!c.active || !counts(c)) return;
    Real kn, ks;
    c.stiffness(kn, ks);
    s += kn * r[c.body2] * r[c.body2];
  });
  s /= volume;
  Real m = s > 0 ? 1.0 + gain_ * (target_ - sigma_) / s : 1.0 + max_strain_;
  m = std::clamp(m, 1.0 - max_strain_, 1.0 + max_strain_);
  last_ = m;
  if (m == 1.0) return;
  total_ *= m;
  radii_ = r;
  if (bodies_.empty()) {
    for (size_t b = 0; b < radii_.size(); ++b)
      if (kind[b] == 0) radii_[b] *= m;
  } else {
    for (int b : bodies_) {
      const bool known = b >= 0 && b < static_cast<int>(radii_.size());
      radii_.at(known ? scene.slot_of(b) : b) *= m;  // ids -> storage order
    }
  }
  scene.set_radii(radii_);
}

std::vector<Real> RadiusGrowth::save_state() const {
  std::vector<Real> s{target_, gain_, max_strain_, sigma_, total_, last_};
  if (grown_only_) s.push_back(1.0);  // (without it: the six values of the older format)
  return s;
}

void RadiusGrowth::load_state(const std::vector<Real>& s) {
  if (s.size() != 6 && s.size() != 7)
    throw ParameterError("RadiusGrowth state: expected 6 or 7 values, got " +
                         std::to_string(s.size()));
  target_ = s[0];
  gain_ = s[1];
  max_strain_ = s[2];
  sigma_ = s[3];
  total_ = s[4];
  last_ = s[5];
  grown_only_ = s.size() == 7 && s[6] != 0;
}

// ---- periodic cell ----------------------------------------------------------------------

CellController::CellController(Real gain, Real max_rate) : gain_(gain), max_rate_(max_rate) {
  check_gain(gain);
  set_max_rate(max_rate);
}

void CellController::check_index(int r, int c) const {
  if (r < 0 || r > 2 || c < 0 || c > 2)
    throw ParameterError("component=(" + std::to_string(r) + ", " + std::to_string(c) +
                         "): row and column must be 0, 1 or 2 (x, y, z)");
}

void CellController::set_rate(int r, int c, Real rate) {
  check_index(r, c);
  require(std::isfinite(rate), "rate", rate, "must be finite (1/s)");
  mode_[3 * r + c] = Mode::Rate;
  goal_[3 * r + c] = rate;
}

void CellController::set_stress(int r, int c, Real sigma) {
  check_index(r, c);
  require(std::isfinite(sigma), "stress", sigma, "must be finite (Pa, compression positive)");
  if (r == c && sigma < 0 && !allow_tension_)
    throw ParameterError(
        "stress (" + std::to_string(r) + ", " + std::to_string(c) + ")=" + fmt_real(sigma) +
        " Pa: a tensile normal stress; a periodic cell of cohesionless grains cannot hold "
        "tension (the servo would stretch it without end): give a normal stress >= 0 (Pa, "
        "compression positive), or set allow_tension for a cell whose bonds hold it");
  if (r != c && mode_[3 * c + r] == Mode::Stress)
    throw ParameterError("stress (" + std::to_string(r) + ", " + std::to_string(c) +
                         "): component (" + std::to_string(c) + ", " + std::to_string(r) +
                         ") is stress-controlled already; both act on the same shear stress "
                         "(set one of them to a rate)");
  mode_[3 * r + c] = Mode::Stress;
  goal_[3 * r + c] = sigma;
}

void CellController::set_gain(Real g) {
  check_gain(g);
  gain_ = g;
}

void CellController::set_max_rate(Real v) {
  require(std::isfinite(v) && v > 0, "max_rate", v, "must be > 0 (1/s)");
  max_rate_ = v;
}

void CellController::apply(Scene& scene) {
  if (!scene.is_periodic())
    throw ParameterError("CellController: the scene has no periodic cell (set_periodic_cell)");
  const PeriodicCell& cell = scene.cell();
  const Real volume = cell.volume();
  // The cell stress (as Scene::cell_stress) and the affine stiffness of each component, Pa,
  // in one walk of the contacts.
  sigma_.setZero();
  stiff_.setZero();
  const auto& x = scene.positions();
  // One spring of force f on branch l (from side 1 to side 2), normal n, stiffnesses kn, ks.
  const auto add = [&](const Vec3& f, const Vec3& l, const Vec3& n, Real kn, Real ks) {
    sigma_ += f * l.transpose();
    for (int r = 0; r < 3; ++r) {
      const Real krr = kn * n[r] * n[r] + ks * (1 - n[r] * n[r]);
      for (int q = 0; q < 3; ++q) stiff_(r, q) += krr * l[q] * l[q];
    }
  };
  scene.for_each_contact_of(ContactKind::Pair, [&](const ContactRecord& c) {
    if (!c.active) return;
    Real kn, ks;
    c.stiffness(kn, ks);
    add(c.force2, x[c.body2] + c.shift2 - x[c.body1], c.state->normal, kn, ks);
  });
  // Bonds, as in Scene::cell_stress (b at the image the bond sees), with their springs.
  for (const Bond& b : scene.bonds()) {
    Real kn, ks;
    b.stiffness(kn, ks);
    add(b.force_b, x[b.b] + scene.bond_shift(b) - x[b.a], b.normal, kn, ks);
  }
  sigma_ /= volume;
  stiff_ /= volume;
  Mat3 l;
  const Real span = scene.dt() * period;
  error_ = 0;
  for (int r = 0; r < 3; ++r)
    for (int q = 0; q < 3; ++q) {
      const int k = 3 * r + q;
      if (!cell.periodic[r] || !cell.periodic[q]) {
        l(r, q) = 0;
        continue;
      }
      if (mode_[k] == Mode::Rate) {
        l(r, q) = goal_[k];
        continue;
      }
      // sigma_rq (compression positive) falls as L_rq extends: d sigma = -C d eps.
      const Real s = r == q ? sigma_(r, q) : 0.5 * (sigma_(r, q) + sigma_(q, r));
      const Real miss = goal_[k] - s;
      error_ = std::max(error_, std::abs(miss) / std::max(std::abs(goal_[k]), 1.0));
      Real rate;
      if (stiff_(r, q) > 0) rate = -gain_ * miss / (stiff_(r, q) * span);
      else rate = miss > 0 ? -max_rate_ : miss < 0 ? max_rate_ : 0.0;
      rate = std::clamp(rate, -max_rate_, max_rate_);
      limit_[k].observe(rate, max_rate_, s, goal_[k]);
      l(r, q) = rate;
    }
  scene.set_velocity_gradient(l);
}

}  // namespace cpp_dem
