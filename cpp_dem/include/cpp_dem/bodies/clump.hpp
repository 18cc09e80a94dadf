// Clumps: rigid bodies made of member spheres (Yade's Clump, PFC's clump). The members are
// spheres in the body store (kind BODY_SPHERE, BodyStore::clump = the clump's index), so the
// broad phase, the contact geometry and the laws see spheres; the scene never pairs two
// members of one clump. Each step the integration pass treats members as fully blocked
// bodies, then the clump pass (integrate/clumps.cpp) sums their forces and torques into the
// clump, integrates the clump in its principal axes and sets the members' state from it.
#pragma once

#include <cstdint>
#include <vector>

#include "cpp_dem/bodies/body_store.hpp"
#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

struct ClumpStore {
  // Per clump (index c).
  std::vector<Vec3> pos;        ///< centre of mass, m
  std::vector<Vec3> vel;        ///< velocity at the last half step, m/s
  std::vector<Vec3> angvel;     ///< spin at the last half step (global frame), rad/s
  std::vector<Vec3> angmom;     ///< angular momentum at the last half step (global), kg m^2/s
  std::vector<Quat> ori;        ///< orientation: principal frame -> global
  std::vector<Mat3> rot;        ///< rotation matrix of ori (kept with it; the pass reads it)
  std::vector<Vec3> force;      ///< resultant force of the last step (members + gravity), N
  std::vector<Vec3> torque;     ///< resultant torque about the centre of mass, N m
  std::vector<Vec3> ext_force;  ///< imposed force on the clump, N (empty until one is set)
  std::vector<Vec3> ext_torque; ///< imposed torque on the clump, N m (empty until one is set)
  std::vector<Real> mass;       ///< kg
  std::vector<Vec3> inertia;    ///< principal moments, kg m^2
  /// Radius the members' contacts take for their stiffness (and the mixing rules), m; 0: each
  /// member's own radius (as Yade and LIGGGHTS). The clump's equivalent radius makes the
  /// grain as stiff as its equivalent sphere whatever the number of members.
  std::vector<Real> stiffness_radius;
  std::vector<std::uint8_t> blocked;  ///< Dof mask; a blocked DOF keeps its velocity
  std::vector<int> member_off;        ///< members of c: member_off[c] .. member_off[c + 1]
  // Energy accumulators: empty until the scene first tracks energy, then one entry per clump
  // (as BodyStore's).
  std::vector<Real> ke, damp_dissip, ext_work;
  std::vector<Vec3> pos_at_energy_reset;
  /// Density scaling: the factor s >= 1 of the clump's mass and principal moments (see
  /// BodyStore::inertia_scale).
  std::vector<Real> inertia_scale;
  // Per member (index e in member_off order).
  std::vector<int> member;        ///< slot of the member sphere
  std::vector<Vec3> member_local; ///< member centre in the principal frame, m

  int size() const { return static_cast<int>(pos.size()); }

  /// The imposed force and torque on clump c: zero where none has been set (the arrays are
  /// allocated when one first is), as BodyStore's.
  const Vec3& ext_force_of(int c) const { return ext_force.empty() ? kZeroVec3 : ext_force[c]; }
  const Vec3& ext_torque_of(int c) const { return ext_torque.empty() ? kZeroVec3 : ext_torque[c]; }

  /// Calls f(array) for every array in a fixed order (the checkpoint's).
  template <class F>
  void for_each_array(F&& f) {
    visit(*this, f);
  }
  template <class F>
  void for_each_array(F&& f) const {
    visit(*this, f);
  }

  /// Gives the energy accumulators one entry per clump: zero, each centre its reference.
  void size_energy() { size_energy_arrays(*this); }

  /// The member slots after the body store's permutation (perm[new slot] = old slot).
  void remap_members(const std::vector<int>& perm) {
    if (member.empty()) return;
    std::vector<int> new_of_old(perm.size());
    for (size_t s = 0; s < perm.size(); ++s) new_of_old[perm[s]] = static_cast<int>(s);
    for (int& m : member) m = new_of_old[m];
  }

 private:
  template <class Self, class F>
  static void visit(Self& s, F& f) {
    f(s.pos), f(s.vel), f(s.angvel), f(s.angmom), f(s.ori), f(s.rot), f(s.force), f(s.torque);
    f(s.ext_force), f(s.ext_torque), f(s.mass), f(s.inertia), f(s.stiffness_radius), f(s.blocked);
    f(s.member_off), f(s.ke), f(s.damp_dissip), f(s.ext_work), f(s.pos_at_energy_reset);
    f(s.member), f(s.member_local);
    f(s.inertia_scale);  // (last: checkpoints before version 10 end before it)
  }
};

/// Puts clump c's members at its pose: positions, velocities (v + w x r), spins and
/// orientations; keeps the rotation matrix of its orientation (cs.rot) for the next step.
/// on_member(slot, position) is called for each member as it is placed. (Always inlined: the
/// clump pass calls it once per clump.)
struct NoMemberHook {
  void operator()(int, const Vec3&) const {}
};
template <class OnMember = NoMemberHook>
__attribute__((always_inline)) inline void place_members(ClumpStore& cs, BodyStore& bs, int c,
                                                         OnMember&& on_member = {}) {
  const Mat3 rot = cs.ori[c].toRotationMatrix();
  cs.rot[c] = rot;
  const Vec3 x = cs.pos[c], v = cs.vel[c], w = cs.angvel[c];
  const Quat q = cs.ori[c];
  for (int e = cs.member_off[c]; e < cs.member_off[c + 1]; ++e) {
    const int s = cs.member[e];
    const Vec3 r = rot * cs.member_local[e];
    const Vec3 p = x + r;
    bs.pos[s] = p;
    bs.vel[s] = v + w.cross(r);
    bs.angvel[s] = w;
    bs.ori[s] = q;
    on_member(s, p);
  }
}

}  // namespace cpp_dem
