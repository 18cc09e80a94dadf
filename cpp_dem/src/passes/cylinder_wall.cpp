// Cylindrical walls (bodies/cylinder_wall.hpp): adding them, their contacts' candidates at a
// build, the contact pass (the general law, as a plane wall's contact with an opening edge),
// and their motion and work after the integration.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/laws/registry.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr Real kInf = std::numeric_limits<Real>::infinity();

std::string fmt_vec(const Vec3& v) {
  return "(" + fmt_real(v[0]) + ", " + fmt_real(v[1]) + ", " + fmt_real(v[2]) + ")";
}
}  // namespace

int Scene::add_cylinder_wall(const Vec3& centre, const Vec3& axis, Real radius, bool inside,
                             int material, Real lo, Real hi) {
  if (!centre.allFinite())
    throw ParameterError("centre=" + fmt_vec(centre) + ": must be finite (m)");
  const Real len = axis.norm();
  if (!(std::isfinite(len) && len > 0))
    throw ParameterError("axis=" + fmt_vec(axis) + ": must be a finite non-zero vector");
  require(std::isfinite(radius) && radius > 0, "radius", radius, "must be > 0 (m)");
  require(!std::isnan(lo), "lo", lo, "must be a number (m along the axis; -inf: no lower end)");
  const std::string above = "must be above lo=" + fmt_real(lo) + " (m along the axis; inf: no "
                            "upper end)";
  require(!std::isnan(hi) && hi > lo, "hi", hi, above.c_str());
  this->material(material);
  if (cell_.on)
    throw ParameterError("add_cylinder_wall: the scene is a periodic cell; cylindrical walls "
                         "are not supported in one");
  CylinderWall w;
  w.centre = centre;
  w.axis = axis / len;
  w.radius = radius;
  w.inside = inside ? 1 : 0;
  w.material = material;
  w.lo = lo;
  w.hi = hi;
  cylinder_walls_.push_back(w);
  dirty_ = true;
  return num_cylinder_walls() - 1;
}

CylinderWall& Scene::cylinder_wall(int id) {
  if (id < 0 || id >= num_cylinder_walls())
    throw ParameterError("cylinder=" + std::to_string(id) + ": no such cylindrical wall (the "
                         "scene has " + std::to_string(num_cylinder_walls()) + ")");
  return cylinder_walls_[id];
}
const CylinderWall& Scene::cylinder_wall(int id) const {
  return const_cast<Scene*>(this)->cylinder_wall(id);
}

void Scene::set_cylinder_radius(int id, Real radius) {
  CylinderWall& w = cylinder_wall(id);
  require(std::isfinite(radius) && radius > 0, "radius", radius, "must be > 0 (m)");
  w.moved_since_build += std::abs(radius - w.radius);
  w.radius = radius;
}

void Scene::update_phys(WallContact& c, const CylinderWall& w) const {
  // As a plane wall's: infinite radius and mass (see mix_materials).
  c.phys = mix_materials(materials_[w.material], materials_[bodies_.material[c.body]], kInf,
                         stiffness_radius(c.body), kInf, bodies_.mass[c.body],
                         pair_law(w.material, bodies_.material[c.body]));
  c.simple = false;  // (the general law: the normal turns with the contact point)
  c.phys_version = phys_version_;
  note_formed_contact(c.phys, c.body, -1);
}

void Scene::rebuild_cylinder_contacts(Real margin) {
  // Candidates: the centre within r + margin of the surface on the wall's side (the rim
  // beyond an end: within r + margin of it), not beyond the surface by r or more. Merged with
  // the old list (both sorted by body, then cylinder) so that kept contacts keep history.
  WallContactMerge merge(cylinder_contacts_,
                         [this](const WallContact& c) { drop_dissipation(c.state); });
  const int n = num_bodies();
  for (int b = 0; b < n; ++b) {
    if (bodies_.kind[b] != BODY_SPHERE && !grid_wall_contacts_) continue;
    const Real r = bodies_.radius[b];
    for (int w = 0; w < num_cylinder_walls(); ++w) {
      Vec3 nrm, e;
      Real dist;
      if (cylinder_contact(cylinder_walls_[w], bodies_.pos[b], r, nrm, dist, e) &&
          dist < r + margin)
        merge.add(b, w);
    }
  }
  cylinder_contacts_ = merge.finish();
  contacts_by_body(cylinder_contacts_, n, cyl_adj_off_, cyl_adj_);
  for (CylinderWall& w : cylinder_walls_) w.moved_since_build = 0;
}

void Scene::compute_cylinder_forces(long& err_contact) {
  const long nc = static_cast<long>(cylinder_contacts_.size());
  long err = std::numeric_limits<long>::max();
  const Real dt = dt_;
#pragma omp parallel for reduction(min : err) schedule(static) if (nc > kParallelMin)
  for (long k = 0; k < nc; ++k) {
    WallContact& c = cylinder_contacts_[k];
    const CylinderWall& w = cylinder_walls_[c.wall];
    const int b = c.body;
    const Real r = bodies_.radius[b];
    Vec3 n, e;
    Real dist;
    if (!cylinder_contact(w, bodies_.pos[b], r, n, dist, e) || dist >= r) {
      if (c.active) {
        c.active = false;
        c.state.clear_history();
        c.force.setZero();
        c.torque.setZero();
      }
      continue;
    }
    const Real overlap = r - dist;
    if (!(overlap <= max_overlap_ratio_ * r)) {
      err = std::min(err, k);
      continue;
    }
    if (!c.active || c.phys_version != phys_version_) update_phys(c, w);
    c.active = true;
    // The wall's surface moves with its velocity and, radially, with its radius's rate.
    ContactGeometry g;
    g.overlap = overlap;
    g.normal = n;
    g.branch2 = -(r - 0.5 * overlap) * n;
    g.branch1 = bodies_.pos[b] + g.branch2;  // unused by the law (the wall does not rotate)
    g.rel_vel = (bodies_.vel[b] + bodies_.angvel[b].cross(g.branch2)) -
                (w.velocity + w.radial_velocity * e);
    g.angvel_sum = bodies_.angvel[b];
    g.rel_angvel = bodies_.angvel[b];
    const LawOutput out = apply_law(c.phys, g, dt, c.state);
    c.force = out.force2;
    c.torque = g.branch2.cross(out.force2) + out.moment2;
  }
  err_contact = err;
  if (err != std::numeric_limits<long>::max()) return;
  // The walls' force, normal push and work, summed in contact order. The work of the step:
  // the force on each sphere times the wall surface's velocity at the contact point (its
  // translation, and its radius's rate along the outward radial direction there), times dt.
  for (CylinderWall& w : cylinder_walls_) {
    w.force.setZero();
    w.normal_force = 0;
  }
  for (const WallContact& c : cylinder_contacts_) {
    if (!c.active) continue;
    CylinderWall& w = cylinder_walls_[c.wall];
    w.force -= c.force;
    w.normal_force += c.force.dot(c.state.normal);
    Vec3 n, e;
    Real dist;
    cylinder_contact(w, bodies_.pos[c.body], bodies_.radius[c.body], n, dist, e);
    w.work += c.force.dot(w.velocity + w.radial_velocity * e) * dt;
  }
}

void Scene::raise_cylinder_overlap(long k) const {
  const WallContact& c = cylinder_contacts_[k];
  Vec3 n, e;
  Real dist = 0;
  cylinder_contact(cylinder_walls_[c.wall], bodies_.pos[c.body], bodies_.radius[c.body], n, dist,
                   e);
  std::ostringstream os;
  os.precision(4);
  os << "blow-up at step " << step_ << ": body " << id_of(c.body) << " overlaps cylindrical wall "
     << c.wall << " by " << (bodies_.radius[c.body] - dist) / bodies_.radius[c.body]
     << " of its radius (max_overlap_ratio=" << max_overlap_ratio_
     << (step_ == 0 ? "); the initial configuration overlaps this much: move the bodies "
                      "apart or relax the overlaps first"
                    : "); the time step may be too large, the contact too soft or the wall too "
                      "fast")
     << blow_up_hint(c.body);
  throw BlowUpError(os.str());
}

void Scene::move_cylinder_walls() {
  for (size_t k = 0; k < cylinder_walls_.size(); ++k) {
    CylinderWall& w = cylinder_walls_[k];
    const Real dx = w.velocity.norm() * dt_, dr = w.radial_velocity * dt_;
    w.centre += w.velocity * dt_;
    w.radius += dr;
    if (!(w.radius > 0)) {
      std::ostringstream os;
      os << "cylindrical wall " << k << " at step " << step_ << ": its radius fell to " << w.radius
         << " m (radial_velocity " << w.radial_velocity << " m/s): it must stay > 0";
      throw BlowUpError(os.str());
    }
    w.moved_since_build += dx + std::abs(dr);
  }
}

}  // namespace cpp_dem
