// The wall pass: every sphere–wall contact, by blocks of bodies and wall axis.
#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/core/simd.hpp"
#include "cpp_dem/geometry/sphere_wall.hpp"
#include "cpp_dem/laws/registry.hpp"
#include "cpp_dem/laws/tangential.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr Real kInf = std::numeric_limits<Real>::infinity();
}  // namespace

void Scene::update_phys(WallContact& c) const {
  // The wall has infinite radius and mass (see mix_materials).
  c.phys = mix_materials(materials_[walls_[c.wall].material], materials_[bodies_.material[c.body]],
                         kInf, stiffness_radius(c.body), kInf, bodies_.mass[c.body],
                         pair_law(walls_[c.wall].material, bodies_.material[c.body]));
  c.simple = short_kernel_applies(c.phys);
  c.phys_version = phys_version_;
  note_formed_contact(c.phys, c.body, -1);
}

namespace {
/// A wall contact out of touch: its history and its force go.
inline void release(WallContact& c) {
  if (c.active) {
    c.active = false;
    c.state.clear_history();
    c.force.setZero();
    c.torque.setZero();
  }
}

/// The short kernel of a wall contact: apply_law for a linear law without viscous damping and
/// rolling resistance. The wall's normal n = sense e_AX never turns, so the frame rotation of
/// the stored shear force is the twist about n alone (000 eqs 1-3, 6). v, om: the sphere's
/// velocity (m/s) and spin (rad/s); r: its radius, overlap (m); dt (s).
template <int AX>
__attribute__((always_inline)) inline void wall_short_kernel(WallContact& c, const Wall& w,
                                                             const Vec3& v, const Vec3& om,
                                                             Real r, Real overlap, Real dt) {
  constexpr int A1 = (AX + 1) % 3, A2 = (AX + 2) % 3;
  const Real sense = w.sense;
  const Real ls = (r - 0.5 * overlap) * sense;  // branch vector -l n, times sense
  // Relative velocity at the contact point, v + om x (-l n) - v_wall, tangential part
  // (the AX component drops out).
  const Real v1 = (v[A1] - w.velocity[A1]) - ls * om[A2];
  const Real v2 = (v[A2] - w.velocity[A2]) + ls * om[A1];
  ContactState& st = c.state;
  const Real fn = c.phys.kn * overlap;
  Tan2 f{st.fs[A1], st.fs[A2]};  // the shear force in the wall's plane
  if (st.normal.squaredNorm() > 0) {
    // fs -= fs x (tw n), tw = dt/2 n . om (frame_turn with a normal that never turns).
    const Real tws = 0.5 * dt * (sense * om[AX]) * sense;
    f = Tan2{f.a - f.b * tws, f.b + f.a * tws};
  }
  const Real kdt = c.phys.ks * dt;
  f.a -= kdt * v1;  // 000 eq (2)
  f.b -= kdt * v2;
  cap_magnitude<PlaneOps>(f, c.phys.tan_phi * (fn > 0 ? fn : 0.0), c.phys.ks,
                          st.dissip_friction);  // 000 eq (3)
  // Component by component into the record (Vec3 temporaries went through the stack).
  st.fs[AX] = 0;
  st.fs[A1] = f.a;
  st.fs[A2] = f.b;
  st.normal[AX] = sense;  // w.normal()
  st.normal[A1] = 0;
  st.normal[A2] = 0;
  st.overlap = overlap;
  st.fn = fn;
  c.force[AX] = fn * sense;
  c.force[A1] = f.a;
  c.force[A2] = f.b;
  // Torque (-l n) x f.
  c.torque[AX] = 0;
  c.torque[A1] = ls * f.b;
  c.torque[A2] = -ls * f.a;
}
}  // namespace

void Scene::compute_wall_forces(long& err_contact) { compute_wall_forces_hot(err_contact); }

void Scene::compute_wall_forces_hot(long& err_contact) {
  const long nc = static_cast<long>(wall_contacts_.size());
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  const int version = phys_version_;
  // The contacts by blocks of bodies (those of the integration pass) and, within a block, by
  // wall axis (contact order within an axis): the kernel's axis is a compile-time constant and
  // the branch to it changes at most three times per block, where in contact order (by body)
  // it changed at random and missed (perf, N = 1e3). Each contact is computed independently,
  // so the order does not change any result.
  const int nblocks = (num_bodies() + kBodyBlock - 1) / kBodyBlock;
  if (wall_order_builds_ != builds_ || static_cast<long>(wall_order_.size()) != nc ||
      static_cast<int>(wall_block_off_.size()) != nblocks + 1) {
    std::vector<int> start(3 * nblocks + 1, 0);
    const auto key = [&](long k) {
      return 3 * (wall_contacts_[k].body / kBodyBlock) + walls_[wall_contacts_[k].wall].axis;
    };
    for (long k = 0; k < nc; ++k) ++start[key(k) + 1];
    for (int q = 0; q < 3 * nblocks; ++q) start[q + 1] += start[q];
    wall_block_off_.resize(nblocks + 1);
    for (int blk = 0; blk <= nblocks; ++blk) wall_block_off_[blk] = start[3 * blk];
    wall_order_.resize(nc);
    for (long k = 0; k < nc; ++k) wall_order_[start[key(k)]++] = static_cast<int>(k);
    wall_order_builds_ = builds_;
  }
  const int* const order = wall_order_.data();
  const int* const block_off = wall_block_off_.data();
  WallContact* const contacts = wall_contacts_.data();
  const Wall* const walls = walls_.data();
  const Vec3* const pos = bodies_.pos.data();
  const Vec3* const vel = bodies_.vel.data();
  const Vec3* const angvel = bodies_.angvel.data();
  const Real* const radius = bodies_.radius.data();
  const WallOpening* const openings = wall_openings_.data();
  bool any_opening = false;
  for (const WallOpening& o : wall_openings_) any_opening = any_opening || o.axis >= 0;
  long err = std::numeric_limits<long>::max();
  // (err is an argument: inside the parallel loop it is the thread's reduction copy.)
  const auto one = [&](long k, long& err, auto axis) __attribute__((always_inline)) {
    constexpr int AX = decltype(axis)::value;
    WallContact& c = contacts[k];
    const Wall& w = walls[c.wall];
    const int b = c.body;
    const Real r = radius[b];
    const Real s = w.sense * (pos[b][AX] - w.position);  // wall_distance, AX constant
    if (s >= r || s <= -r) {
      release(c);
      return;
    }
    const Real overlap = r - s;
    if (!(overlap <= max_ratio * r)) {
      err = std::min(err, k);
      return;
    }
    if (!c.active || c.phys_version != version) update_phys(c);
    c.active = true;
    if (c.simple) {
      wall_short_kernel<AX>(c, w, vel[b], angvel[b], r, overlap, dt);
      return;
    }
    // (The general law's geometry only here: its zero-initialised fields cost the short
    // kernel a stack fill per contact.)
    const ContactGeometry g = sphere_wall_geometry(w, pos[b], r, vel[b], angvel[b], overlap);
    const LawOutput out = apply_law(c.phys, g, dt, c.state);
    c.force = out.force2;
    c.torque = g.branch2.cross(out.force2) + out.moment2;
  };
  // An opening (WallOpening): a centre within it, or beyond the plane, meets the wall only
  // at the nearer edge of the opening, a line across the wall (d: from the edge to the
  // centre); the normal then turns in the plane of the wall's and the opening's axes, so the
  // general law takes it.
  const auto edge = [&](long k, long& err, const Vec3& d) {
    WallContact& c = contacts[k];
    const Wall& w = walls[c.wall];
    const int b = c.body;
    const Real r = radius[b];
    const Real dist = d.norm();
    if (dist >= r) {
      release(c);
      return;
    }
    const Real overlap = r - dist;
    if (!(overlap <= max_ratio * r)) {
      err = std::min(err, k);
      return;
    }
    if (!c.active || c.phys_version != version) update_phys(c);
    c.active = true;
    const ContactGeometry g =
        sphere_wall_geometry(w, d / dist, pos[b], r, vel[b], angvel[b], overlap);
    const LawOutput out = apply_law(c.phys, g, dt, c.state);
    c.force = out.force2;
    c.torque = g.branch2.cross(out.force2) + out.moment2;
  };
#pragma omp parallel reduction(min : err) if (nc > kParallelMin)
  {
    const auto [t, nt] = thread_and_team();
    const auto blocks = thread_share(nblocks, t, nt);
    for (long p = block_off[blocks.first]; p < block_off[blocks.second]; ++p) {
      const long k = order[p];
      if (any_opening) {  // (loop-invariant: a scene without openings skips it)
        Vec3 d;
        if (opening_edge(walls[contacts[k].wall], openings[contacts[k].wall],
                         pos[contacts[k].body], d)) {
          edge(k, err, d);
          continue;
        }
      }
      switch (walls[contacts[k].wall].axis) {
        case 0: one(k, err, std::integral_constant<int, 0>()); break;
        case 1: one(k, err, std::integral_constant<int, 1>()); break;
        default: one(k, err, std::integral_constant<int, 2>());
      }
    }
  }
  err_contact = err;
}

}  // namespace cpp_dem
