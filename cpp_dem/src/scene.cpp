// The scene: its parameters, its controllers, and the order of a step. The passes of a step
// are in src/broadphase/, src/passes/ and src/integrate/; the body API in src/bodies/.
#include "cpp_dem/scene.hpp"

#include "cpp_dem/geometry/sphere_wall.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>

namespace cpp_dem {

// ---- parameters -----------------------------------------------------------------------------

void Scene::set_dt(Real dt) {
  require(std::isfinite(dt) && dt > 0, "dt", dt, "must be > 0 (s)");
  dt_ = dt;
}
void Scene::set_gravity(const Vec3& g) {
  if (!g.allFinite()) throw ParameterError("gravity: must be finite (m/s^2)");
  gravity_ = g;
}
void Scene::set_local_damping(Real d) {
  require(std::isfinite(d) && d >= 0 && d < 1, "local_damping", d, "must be in [0, 1)");
  local_damping_ = d;
}
void Scene::set_verlet_margin(Real m) {
  require(std::isfinite(m) && m >= 0, "verlet_margin", m,
          "must be >= 0 (m); 0 selects the default, 0.2 x the mean radius");
  margin_ = m;
  dirty_ = true;
}
void Scene::set_max_overlap_ratio(Real r) {
  require(std::isfinite(r) && r > 0 && r <= 2, "max_overlap_ratio", r, "must be in (0, 2]");
  max_overlap_ratio_ = r;
}
void Scene::set_max_step_ratio(Real r) {
  require(std::isfinite(r) && r > 0 && r <= 2, "max_step_ratio", r,
          "must be in (0, 2] (largest move of a body in one step, in radii)");
  max_step_ratio_ = r;
}
void Scene::set_track_energy(bool on) {
  if (on && !track_energy_) {
    track_energy_ = true;
    bodies_.size_energy();  // (allocated when first tracked: BodyStore's energy accumulators)
    clumps_.size_energy();
    reset_energy();
  }
  track_energy_ = on;
}
void Scene::set_auto_timestep(Real safety, int period) {
  require(std::isfinite(safety) && safety > 0 && safety <= 1, "timestep_safety", safety,
          "must be in (0, 1]: above 1 the step exceeds the critical estimate and leapfrog can "
          "go unstable");
  if (period < 0)
    throw ParameterError("timestep_period=" + std::to_string(period) + ": must be >= 0 (0 = off)");
  ts_safety_ = safety;
  ts_period_ = period;
  if (ds_on_) return;  // density scaling keeps dt at its target
  // Period 0: dt is set once, now, and not updated during the run (the dt check still
  // watches it); a positive period also sets it now and then every `period` steps.
  const Real est = critical_dt();
  if (std::isfinite(est)) set_dt(safety * est);
}

void Scene::set_density_scaling(Real target_dt, Real safety, int period) {
  require(std::isfinite(target_dt) && target_dt > 0, "target_dt", target_dt, "must be > 0 (s)");
  require(std::isfinite(safety) && safety > 0 && safety <= 1, "safety", safety,
          "must be in (0, 1]: each body's scaled critical step is target_dt / safety");
  if (period < 1)
    throw ParameterError("period=" + std::to_string(period) +
                         ": must be >= 1 (steps between updates of the inertia factors)");
  ds_on_ = true;
  ds_target_dt_ = target_dt;
  ds_safety_ = safety;
  ds_period_ = period;
  dt_ = target_dt;
  update_density_scaling();
}

void Scene::clear_density_scaling() {
  ds_on_ = false;
  ds_stale_ = false;
  for (int c = 0; c < clumps_.size(); ++c) set_clump_scale(c, 1.0);
  std::vector<Real>().swap(bodies_.inertia_scale);  // (every factor 1: none kept)
}

void Scene::set_clump_scale(int c, Real s) {
  Real& old = clumps_.inertia_scale[c];
  if (s == old) return;
  // The spin is kept: L = R I R^T w grows with the factor; so does the kinetic energy, and
  // the energy balance books the change as external work.
  clumps_.angmom[c] *= s / old;
  if (track_energy_) clumps_.ext_work[c] += clumps_.ke[c] * (s / old - 1);
  old = s;
}

void Scene::set_dt_check_period(int period) {
  if (period < 0)
    throw ParameterError("dt_check_period=" + std::to_string(period) + ": must be >= 0 (0 = off)");
  dt_check_period_ = period;
}

void Scene::raise_overlap(long k, bool wall) const {
  std::ostringstream os;
  os.precision(4);
  // Before the first step nothing has moved: the overlap was in the input.
  const char* why = step_ == 0
                        ? "); the initial configuration overlaps this much: move the bodies "
                          "apart or relax the overlaps first (cpp_dem.prep.relax_overlaps)"
                        : "); the time step may be too large or the contact too soft";
  int body = -1;
  if (wall) {
    const WallContact& c = wall_contacts_[k];
    const Wall& w = walls_[c.wall];
    Real s = wall_distance(w, bodies_.pos[c.body]);
    Vec3 d;
    const bool edge = opening_edge(w, wall_openings_[c.wall], bodies_.pos[c.body], d);
    if (edge) s = d.norm();  // (against an edge of the wall's opening)
    os << "blow-up at step " << step_ << ": body " << id_of(c.body) << " overlaps wall " << c.wall
       << (edge ? " (an edge of its opening)" : "") << " by "
       << (bodies_.radius[c.body] - s) / bodies_.radius[c.body]
       << " of its radius (max_overlap_ratio=" << max_overlap_ratio_ << why;
    body = c.body;
  } else {
    // (k: the candidate pair)
    const int ci = pair_first_body(k), cj = cand_second(k);
    const Real ov = bodies_.radius[ci] + bodies_.radius[cj] -
                    (bodies_.pos[cj] + pair_shift(k) - bodies_.pos[ci]).norm();
    os << "blow-up at step " << step_ << ": bodies " << id_of(ci) << " and " << id_of(cj)
       << " overlap by " << ov / std::min(bodies_.radius[ci], bodies_.radius[cj])
       << " of the smaller radius (max_overlap_ratio=" << max_overlap_ratio_ << why;
    if (!std::isfinite(ov)) os << " (non-finite position)";
    body = bodies_.radius[cj] < bodies_.radius[ci] ? cj : ci;
  }
  if (step_ > 0) os << blow_up_hint(body);
  throw BlowUpError(os.str());
}

int Scene::add_controller(std::shared_ptr<Controller> c) {
  if (!c) throw ParameterError("controller: must not be None");
  if (c->period < 1)
    throw ParameterError("period=" + std::to_string(c->period) + ": must be >= 1 step");
  controllers_.push_back(std::move(c));
  return static_cast<int>(controllers_.size()) - 1;
}

std::shared_ptr<Controller> Scene::controller(int id) const {
  if (id < 0 || id >= num_controllers())
    throw ParameterError("controller=" + std::to_string(id) + ": no such controller");
  return controllers_[id];
}

namespace {
/// The first non-finite of a body's force, torque, velocity, spin and position, named with
/// its value (for the blow-up messages).
std::string non_finite_quantity(const Vec3& f, const Vec3& t, const Vec3& v, const Vec3& w,
                                const Vec3& x) {
  std::ostringstream os;
  if (!f.allFinite()) os << "force " << f.transpose();
  else if (!t.allFinite()) os << "torque " << t.transpose();
  else if (!v.allFinite()) os << "velocity " << v.transpose();
  else if (!w.allFinite()) os << "angular velocity " << w.transpose();
  else os << "position " << x.transpose();
  return os.str();
}
}  // namespace

void Scene::note_formed_contact(const ContactPhys& p, int b1, int b2) const {
  // The mass that the contact's spring moves: a clump member's clump; a fully blocked body
  // (or clump) moves none.
  const auto free_mass = [this](int b) {
    if (b < 0) return std::numeric_limits<Real>::infinity();
    const int c = bodies_.clump[b];
    if (c >= 0)
      return (clumps_.blocked[c] & DOF_ALL) == DOF_ALL ? std::numeric_limits<Real>::infinity()
                                                        : clumps_.mass[c];
    return (bodies_.blocked[b] & DOF_ALL) == DOF_ALL ? std::numeric_limits<Real>::infinity()
                                                      : bodies_.mass[b];
  };
  const Real m1 = free_mass(b1), m2 = free_mass(b2);
  const int b = m2 <= m1 ? b2 : b1;
  const Real m = std::min(m1, m2);
  if (b < 0 || !(m < std::numeric_limits<Real>::infinity())) return;
  // The law's stiffness as the contact forms (the linear law's k_n; a Hertz contact's is
  // ~0 at first, and the grains' stiffness floor in check_dt bounds it).
  Real kn, ks;
  tangent_stiffness(p, 0, kn, ks);
  const Real q = std::isfinite(kn) && kn > 0 ? kn / m : 0;
  if (q <= formed_.stiffness_per_mass.load(std::memory_order_relaxed)) return;
  std::lock_guard<std::mutex> hold(formed_.lock);
  if (q <= formed_.stiffness_per_mass.load(std::memory_order_relaxed)) return;
  formed_.body = id_of(b);
  formed_.stiffness_per_mass.store(q, std::memory_order_relaxed);
}

void Scene::check_dt() {
  // The contacts active now (critical_dt_body), and those that formed and perhaps opened
  // again since the last check: bouncing grains may have no contact at the moment of the
  // check. Such a contact gives every grain its stiffness floor (as any active contact does)
  // and its own single-contact estimate sqrt(2 m / k_n), m the lighter free body's mass.
  // With density scaling the factors follow the contacts themselves (each update takes the
  // contacts of its step before the bodies move), so a contact that formed and opened again
  // needs no check of its own: only the active ones are checked, with the scaled inertia.
  const Real q = ds_on_ ? -1 : formed_.stiffness_per_mass.load(std::memory_order_relaxed);
  const int q_body = formed_.body;
  const long since = formed_.since;
  formed_.stiffness_per_mass.store(-1, std::memory_order_relaxed);
  formed_.body = -1;
  formed_.since = step_;
  int body = -1;
  Real est = critical_dt_body(&body, q >= 0);
  bool formed = false;
  if (q > 0) {
    const Real est_formed = std::sqrt(2 / q);
    if (est_formed < est) {
      est = est_formed;
      body = q_body;
      formed = true;
    }
  }
  if (body < 0 || !(dt_ > est * (1 + 1e-12))) return;
  std::ostringstream os;
  os.precision(4);
  os << "blow-up at step " << step_ << ": the time step dt=" << dt_
     << " s exceeds the critical estimate " << est << " s (set by body " << body;
  if (formed) os << ", in a contact that formed after step " << since;
  os << ") " << dt_ / est << " x; leapfrog may be unstable and results would be wrong: ";
  if (ds_on_)
    os << "density scaling is on and its factors did not catch up; lower its target_dt or "
          "safety, or update them more often (period)";
  else
    os << "lower dt or use set_auto_timestep(safety <= 1)";
  throw BlowUpError(os.str());
}

std::string Scene::blow_up_hint(int b) const {
  std::ostringstream os;
  os.precision(3);
  int body = -1;
  const Real est = critical_dt_body(&body, true);
  if (std::isfinite(est) && est > 0) {
    os << "; dt=" << dt_ << " s is " << dt_ / est << " x the critical estimate " << est << " s";
    if (dt_ > est) os << " (lower dt or use set_auto_timestep(safety <= 1))";
  }
  if (b >= 0 && b < num_bodies() && bodies_.kind[b] == BODY_SPHERE) {
    // How deep the grain's own weight alone would press one contact of the linear law's
    // stiffness E R, in radii: well below 1e-3 for sand-like moduli (E 1e7-1e10 Pa).
    const int mi = bodies_.material[b];
    const Material& m = materials_[mi];
    const Real r = bodies_.radius[b], k = m.young * r;
    const Real sink = bodies_.mass[b] * gravity_.norm() / k / r;
    if (sink > 0.01)
      os << "; material " << mi << " is very soft for these grains: its young=" << m.young
         << " Pa gives a contact stiffness E R = " << k << " N/m, and a grain's own weight alone "
         << "would press one contact " << sink << " of its radius deep (sand-like grains: "
         << "young 1e7-1e10 Pa); raise young";
  }
  return os.str();
}

void Scene::step() {
  if (ds_stale_) update_density_scaling();  // (clears it)
  if (!ds_on_ && ts_period_ > 0 && step_ % ts_period_ == 0 && step_ > 0) {
    const Real est = critical_dt();
    if (std::isfinite(est)) dt_ = ts_safety_ * est;  // nothing free: keep dt
  }
  if ((ds_on_ || ts_period_ == 0) && dt_check_period_ > 0 && step_ > 0 &&
      step_ % dt_check_period_ == 0)
    check_dt();
  for (const auto& c : controllers_)
    if (c->enabled && step_ % c->period == 0) c->apply(*this);
  check_boundary_steps();
  if (need_rebuild()) rebuild();
  disp_valid_ = false;  // until this step's integration measures them again
  if (cell_.on) refresh_image_offsets();
  long err_pair, err_wall, err_body;
  compute_pair_forces(err_pair);
  if (err_pair != std::numeric_limits<long>::max()) raise_overlap(err_pair, false);
  compute_wall_forces(err_wall);
  if (err_wall != std::numeric_limits<long>::max()) raise_overlap(err_wall, true);
  if (!cylinder_walls_.empty()) {
    long err_cyl;
    compute_cylinder_forces(err_cyl);
    if (err_cyl != std::numeric_limits<long>::max()) raise_cylinder_overlap(err_cyl);
  }
  if (!mesh_walls_.empty()) {
    long err_mesh;
    compute_mesh_forces(err_mesh);
    if (err_mesh != std::numeric_limits<long>::max()) raise_mesh_overlap(err_mesh);
  }
  if constexpr (kGeogridBuilt) {
    if (has_grid()) {
      long err_grid;
      compute_grid_contacts(err_grid);
      if (err_grid != std::numeric_limits<long>::max()) {
        const GridContact& c = grid_contacts_[err_grid];
        std::ostringstream os;
        os.precision(4);
        os << "blow-up at step " << step_ << ": sphere " << id_of(c.sphere)
           << " overlaps the geogrid ("
           << (c.kind == GridPrimitive::Node         ? "node "
               : c.kind == GridPrimitive::Connection ? "connection "
                                                     : "pfacet ")
           << c.prim << ") by " << c.geom.overlap / bodies_.radius[c.sphere]
           << " of the grain radius (max_overlap_ratio=" << max_overlap_ratio_
           << "); the time step may be too large or the contact too soft"
           << blow_up_hint(c.sphere);
        throw BlowUpError(os.str());
      }
      compute_links();
    }
  }
  if (has_bonds()) {
    long err_bond;
    compute_bonds(err_bond);
    if (err_bond != std::numeric_limits<long>::max()) raise_bond_overlap(err_bond);
  }
  // Wall forces and work, summed in contact order.
  for (Wall& w : walls_) w.force.setZero();
  for (const WallContact& c : wall_contacts_)
    if (c.active) walls_[c.wall].force -= c.force;
  if (track_energy_ && !energy_reference_set_) set_energy_reference();
  // The mean field's work on the contacts in this step: it moves j relative to i by L l dt
  // against the force f on j, -dt sum_c f_c . (L l_c).
  if (cell_.on && track_energy_)
    cell_.work -= dt_ * (pair_stress_sum().cwiseProduct(cell_.vel_grad)).sum();
  // Density scaling: the factors from the contacts of this step's forces, before they move
  // the bodies (a contact that formed in this step counts at once).
  if (ds_on_ && step_ % ds_period_ == 0) update_density_scaling();
  reduce_and_integrate(err_body);
  if (err_body != std::numeric_limits<long>::max()) {
    const int b = static_cast<int>(err_body);
    std::ostringstream os;
    os << "blow-up at step " << step_ << ": body " << id_of(b) << " has a non-finite "
       << non_finite_quantity(bodies_.force[b], bodies_.torque[b], bodies_.vel[b],
                              bodies_.angvel[b], bodies_.pos[b]);
    throw BlowUpError(os.str());
  }
  if (has_clumps()) {
    long err_clump;
    integrate_clumps(err_clump);
    if (err_clump != std::numeric_limits<long>::max()) {
      const int c = static_cast<int>(err_clump);
      std::ostringstream os;
      os << "blow-up at step " << step_ << ": clump " << c << " (members from body "
         << id_of(clumps_.member[clumps_.member_off[c]]) << ") has a non-finite "
         << non_finite_quantity(clumps_.force[c], clumps_.torque[c], clumps_.vel[c],
                                clumps_.angvel[c], clumps_.pos[c]);
      throw BlowUpError(os.str());
    }
  }
  if (cell_.on) advance_cell();  // (the bodies took the mean field in the integration)
  check_tunnelling();
  for (Wall& w : walls_) {
    // Work done by the wall on the spheres: -(force on wall) . v dt.
    w.work += -w.force.dot(w.velocity) * dt_;
    const Real dx = w.velocity[w.axis] * dt_;
    w.position += dx;
    w.moved_since_build += std::abs(dx);
  }
  if (!cylinder_walls_.empty()) move_cylinder_walls();
  if (!mesh_walls_.empty()) move_mesh_walls();
  ++step_;
  time_ += dt_;
}

Real Scene::grain_min_radius() {
  if (min_radius_ < 0) {
    Real grains = std::numeric_limits<Real>::infinity(), all = grains;
    max_radius_ = 0;
    for (int b = 0; b < num_bodies(); ++b) {
      all = std::min(all, bodies_.radius[b]);
      max_radius_ = std::max(max_radius_, bodies_.radius[b]);
      if (bodies_.kind[b] == BODY_SPHERE) grains = std::min(grains, bodies_.radius[b]);
    }
    min_radius_ = std::isfinite(grains) ? grains : all;
  }
  return min_radius_;
}

void Scene::check_boundary_steps() {
  // What a boundary moves towards the bodies in one step, against what a grain may move
  // (check_tunnelling): a plane wall along its inward normal, a cylinder by its translation
  // across its axis and its radius's change towards the bodies, a mesh by its translation, a
  // periodic cell by the mean field's change of a contact's branch (2 r_max |L| dt, |L| the
  // Frobenius norm of the velocity gradient; the step map is singular at |L| dt = 2).
  if (num_bodies() == 0) return;
  const bool moving_cell = cell_.on && !cell_.vel_grad.isZero(0);
  const Real limit = max_step_ratio_ * grain_min_radius();
  const auto g = [](Real x) {
    std::ostringstream os;
    os.precision(4);
    os << x;
    return os.str();
  };
  const auto fail = [&](const std::string& what, Real moved, const std::string& how) {
    std::ostringstream os;
    os.precision(4);
    os << "blow-up at step " << step_ << ": " << what << " would move " << moved
       << " m towards the bodies in one step (" << how << ", dt " << dt_
       << " s), more than max_step_ratio=" << max_step_ratio_ << " of the smallest grain's "
       << "radius " << grain_min_radius() << " m: it can pass through a grain without touching "
       << "it (tunnelling); lower its speed (a servo's max_speed, a strain rate) or the time step";
    throw BlowUpError(os.str());
  };
  for (size_t k = 0; k < walls_.size(); ++k) {
    const Wall& w = walls_[k];
    const Real in = w.sense * w.velocity[w.axis] * dt_;  // (> 0: towards its inner side)
    if (in > limit)
      fail("wall " + std::to_string(k) + " (" + (w.sense > 0 ? "+" : "-") + "xyz"[w.axis] +
               ")", in, "velocity " + g(w.velocity[w.axis]) + " m/s along its axis");
  }
  for (size_t k = 0; k < cylinder_walls_.size(); ++k) {
    const CylinderWall& w = cylinder_walls_[k];
    const Vec3 across = w.velocity - w.velocity.dot(w.axis) * w.axis;
    const Real in = across.norm() * dt_ +
                    std::max(Real(0), (w.inside ? -1 : 1) * w.radial_velocity * dt_);
    if (in > limit)
      fail("cylindrical wall " + std::to_string(k), in,
           "speed across its axis " + g(across.norm()) + " m/s, radial velocity " +
               g(w.radial_velocity) + " m/s");
  }
  for (size_t k = 0; k < mesh_walls_.size(); ++k) {
    const Real in = mesh_walls_[k].velocity.norm() * dt_;
    if (in > limit)
      fail("mesh wall " + std::to_string(k), in,
           "speed " + g(mesh_walls_[k].velocity.norm()) + " m/s");
  }
  if (moving_cell) {
    const Real rmax = max_radius_;  // (with grain_min_radius above)
    const Real strain = cell_.vel_grad.norm() * dt_;
    if (strain > 1 || 2 * rmax * strain > limit) {
      std::ostringstream os;
      os.precision(4);
      os << "blow-up at step " << step_ << ": the periodic cell's velocity_gradient strains it "
         << "by |L| dt = " << strain << " in one step (|L| = " << cell_.vel_grad.norm()
         << " 1/s, the Frobenius norm; dt " << dt_ << " s): a contact's branch of 2 r_max = "
         << 2 * rmax << " m would change by " << 2 * rmax * strain << " m, more than "
         << "max_step_ratio=" << max_step_ratio_ << " of the smallest grain's radius "
         << grain_min_radius() << " m (tunnelling), or |L| dt above 1 (the step map is "
         << "singular at 2); lower the strain rate (a cell servo's max_rate) or the time step";
      throw BlowUpError(os.str());
    }
  }
}

void Scene::check_tunnelling() {
  // A grain may move its radius times max_step_ratio per step. A geogrid node is a member of
  // radius R_c, and what it must not cross is a grain: the band of deep overlaps along its
  // path through a grain of radius r is r + 2 R_c long, so it may move (R_c + r_min) times
  // max_step_ratio, r_min the smallest grain radius.
  grain_min_radius();
  // Leapfrog moved each body by v dt, and no body moved farther in this step than since the
  // last build (max_disp_): below max_step_ratio x the smallest grain radius nothing tunnels.
  if (disp_valid_ && max_disp_ <= max_step_ratio_ * min_radius_) return;
  const int n = num_bodies();
  const Real dt2 = dt_ * dt_;
  for (int b = 0; b < n; ++b) {
    const Real allowed = bodies_.kind[b] == BODY_SPHERE ? bodies_.radius[b]
                                                        : bodies_.radius[b] + min_radius_;
    const Real reach = max_step_ratio_ * allowed;
    if (bodies_.vel[b].squaredNorm() * dt2 <= reach * reach) continue;  // NaN was caught before
    // Where the move ended in too deep an overlap, that is the more telling message (the
    // next step's overlap check would give it).
    const auto& x = bodies_.pos;
    const auto& r = bodies_.radius;
    const int nrows = static_cast<int>(pair_ioff_.size()) - 1;
    for (int i = 0; i < nrows; ++i) {
      for (int k = pair_ioff_[i]; k < pair_ioff_[i + 1]; ++k) {
        const int j = cand_second(k);
        if (i != b && j != b) continue;
        const Real ov = r[i] + r[j] - (x[j] + pair_shift(k) - x[i]).norm();
        if (!(ov <= max_overlap_ratio_ * std::min(r[i], r[j]))) raise_overlap(k, false);
      }
    }
    for (size_t k = 0; k < wall_contacts_.size(); ++k) {
      const WallContact& c = wall_contacts_[k];
      if (c.body != b) continue;
      const Real ov = r[b] - wall_distance(walls_[c.wall], x[b]);
      if (ov < r[b] && !(ov <= max_overlap_ratio_ * r[b])) raise_overlap(k, true);
    }
    const Real step_len = bodies_.vel[b].norm() * dt_;
    std::ostringstream os;
    os.precision(4);
    os << "blow-up at step " << step_ << ": body " << id_of(b) << " moved " << step_len
       << " m in one step (speed " << bodies_.vel[b].norm() << " m/s, velocity ("
       << bodies_.vel[b][0] << ", " << bodies_.vel[b][1] << ", " << bodies_.vel[b][2] << ") m/s, dt " << dt_
       << " s), more than max_step_ratio=" << max_step_ratio_ << " of "
       << (bodies_.kind[b] == BODY_SPHERE ? "its radius " : "its radius plus the smallest grain's ")
       << allowed << " m: it can pass through a wall, a grain or a geogrid member without touching it "
          "(tunnelling); the time step may be too large, or an imposed velocity or force too big"
       << blow_up_hint(b);
    throw BlowUpError(os.str());
  }
}

long Scene::run(long n, const std::function<bool()>& interrupted) {
  if (n < 0) throw ParameterError("n=" + std::to_string(n) + ": must be >= 0 steps");
  if (num_bodies() > 0 && margin_ <= 0 && default_margin() <= 0)
    throw ParameterError("verlet_margin: could not derive a default");
  if (!interrupted) {
    for (long k = 0; k < n; ++k) step();
    return n;
  }
  // Steps in batches whose length follows the cost of a step, so that the clock is read
  // about every millisecond (not every step: a step of a few grains costs less than a read),
  // and `interrupted` is asked about every 0.1 s of wall time.
  using Clock = std::chrono::steady_clock;
  constexpr double kRead = 1e-3, kAsk = 0.1;  // s
  Clock::time_point last_read = Clock::now(), last_ask = last_read;
  long batch = 1;
  for (long k = 0; k < n;) {
    const long m = std::min(batch, n - k);
    for (long j = 0; j < m; ++j) step();
    k += m;
    const Clock::time_point now = Clock::now();
    const double took = std::chrono::duration<double>(now - last_read).count();
    last_read = now;
    if (took < 0.5 * kRead && batch < (1L << 30)) batch *= 2;
    else if (took > 2 * kRead && batch > 1) batch /= 2;
    if (std::chrono::duration<double>(now - last_ask).count() >= kAsk) {
      last_ask = now;
      if (k < n && interrupted()) return k;
    }
  }
  return n;
}

int Scene::num_active_contacts() const {
  // Sphere–sphere and sphere–wall contacts (grain–geogrid contacts: grid_contacts()).
  int n = 0;
  for_each_contact([&n](const ContactRecord& c) { n += c.active && c.kind != ContactKind::Grid; });
  return n;
}

}  // namespace cpp_dem
