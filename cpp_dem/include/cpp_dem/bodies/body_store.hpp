// The body store: the state of every body as structure of arrays, in storage order (slots;
// see Scene's "storage order"). A new body kind (clumps, bonded particles) adds its arrays
// here, to push() and to for_each_array(); the passes read the arrays directly.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// Kinds of body in the store.
enum BodyKind : std::uint8_t {
  BODY_SPHERE = 0,     ///< a grain: a sphere to the collider
  BODY_GRID_NODE = 1,  ///< a geogrid node (000 §2.2): 6 DOF, touched through its links
};
// (A clump member is a BODY_SPHERE with clump >= 0; the clump itself is in ClumpStore.)

/// Gives a store's energy accumulators (ke, damp_dissip, ext_work, pos_at_energy_reset) one
/// entry per item of its pos: the new ones zero, each position its reference (BodyStore's,
/// ClumpStore's size_energy).
template <class Store>
void size_energy_arrays(Store& s) {
  const size_t n = s.pos.size(), old = s.ke.size();
  s.ke.resize(n, 0);
  s.damp_dissip.resize(n, 0);
  s.ext_work.resize(n, 0);
  s.pos_at_energy_reset.resize(n);
  for (size_t k = old; k < n; ++k) s.pos_at_energy_reset[k] = s.pos[k];
}

/// Room in v, an array of one entry per body of n (none where v has not, or n is 0), for
/// count more: at least half its capacity more, so that many small batches cost linear time.
template <class V>
void reserve_per_body(V& v, std::size_t n, std::size_t count) {
  if (n > 0 && v.size() == n && v.capacity() < n + count)
    v.reserve(std::max(n + count, v.capacity() + v.capacity() / 2));
}

struct BodyStore {
  std::vector<Vec3> pos;         ///< centres, m
  std::vector<Vec3> vel;         ///< velocities, m/s
  std::vector<Vec3> angvel;      ///< spins, rad/s
  std::vector<Vec3> force;       ///< resultant force of the last step, N
  std::vector<Vec3> torque;      ///< resultant torque of the last step, N m
  /// Imposed external force, N; empty until one is set (then one entry per body): a scene
  /// without imposed loads carries none of its 24 bytes a body. Read through ext_force_of.
  std::vector<Vec3> ext_force;
  std::vector<Vec3> ext_torque;  ///< imposed external torque, N m (empty as ext_force)
  std::vector<Quat> ori;         ///< orientations
  std::vector<Real> radius;      ///< m (a grid node's: the geogrid's R_c)
  std::vector<Real> mass;        ///< kg
  std::vector<Real> inertia;     ///< kg m^2 (spherical)
  std::vector<int> material;     ///< material index
  std::vector<std::uint8_t> blocked;  ///< blocked DOFs (Dof mask)
  std::vector<std::uint8_t> kind;     ///< BodyKind
  std::vector<int> clump;             ///< index of the clump a member belongs to, -1: free
  /// Periodic cell: how many cell vectors the body was shifted by when wrapped into the cell
  /// (its unwrapped position is pos + H image); zero without a cell. Empty until a body is
  /// first wrapped (Scene::wrap_into_cell), then one entry per body: a scene without a cell
  /// carries none of its 12 bytes a body. Read through image_of.
  std::vector<std::array<int, 3>> image;
  // Energy accumulators per body: allocated when the scene first tracks energy (empty
  // before: a scene that never does carries none of their 48 bytes a body), then one entry
  // per body (Scene::push_body, Scene::size_energy).
  std::vector<Real> ke;                    ///< kinetic energy at the last step, J
  std::vector<Real> damp_dissip;           ///< dissipated by local damping, J
  std::vector<Real> ext_work;              ///< work of external forces and imposed DOFs, J
  std::vector<Vec3> pos_at_energy_reset;   ///< m
  /// Density scaling (Scene::set_density_scaling): the factor s >= 1 of the body's inertia;
  /// it moves as a body of mass s x mass and moment s x inertia, while its weight stays
  /// mass x g. 1 when scaling is off, and for a clump member (its clump carries the factor).
  /// Empty until density scaling first sets a factor (Scene::update_density_scaling), then
  /// one entry per body; read through inertia_scale_of.
  std::vector<Real> inertia_scale;

  int size() const { return static_cast<int>(pos.size()); }

  /// Appends one body at rest.
  void push(const Vec3& x, Real r, Real m, Real i, int mat, std::uint8_t k) {
    if (!ext_force.empty()) ext_force.push_back(Vec3::Zero());  // (once set, one per body)
    if (!ext_torque.empty()) ext_torque.push_back(Vec3::Zero());
    pos.push_back(x);
    vel.push_back(Vec3::Zero());
    angvel.push_back(Vec3::Zero());
    force.push_back(Vec3::Zero());
    torque.push_back(Vec3::Zero());
    ori.push_back(Quat::Identity());
    radius.push_back(r);
    mass.push_back(m);
    inertia.push_back(i);
    material.push_back(mat);
    blocked.push_back(DOF_NONE);
    kind.push_back(k);
    clump.push_back(-1);
    if (!image.empty()) image.push_back({0, 0, 0});  // (once made, one per body)
    if (!inertia_scale.empty()) inertia_scale.push_back(1.0);
  }

  /// Room for count more bodies in every array that holds one entry per body (so not in one
  /// made on its first use and still empty; with no body yet, none is told apart: nothing).
  /// A batch is stored at its size, not grown by doubling one body at a time; small batches
  /// grow by half at least (linear time).
  void reserve_more(std::size_t count) {
    const std::size_t n = pos.size();
    for_each_array([&](auto& v) { reserve_per_body(v, n, count); });
  }

  /// Body b's imposed force and torque (zero where none was ever set).
  const Vec3& ext_force_of(int b) const { return ext_force.empty() ? kZeroVec3 : ext_force[b]; }
  const Vec3& ext_torque_of(int b) const { return ext_torque.empty() ? kZeroVec3 : ext_torque[b]; }
  /// Body b's wrap count in the periodic cell (zero where no body was ever wrapped).
  std::array<int, 3> image_of(int b) const {
    return image.empty() ? std::array<int, 3>{0, 0, 0} : image[b];
  }
  /// Body b's inertia factor of density scaling (1 where none was ever set).
  Real inertia_scale_of(int b) const { return inertia_scale.empty() ? 1.0 : inertia_scale[b]; }

  /// Gives the energy accumulators one entry per body: zero, each position its reference.
  void size_energy() { size_energy_arrays(*this); }

  /// Calls f(array) for every per-body array, in a fixed order (the checkpoint's).
  template <class F>
  void for_each_array(F&& f) {
    visit(*this, f);
  }
  template <class F>
  void for_each_array(F&& f) const {
    visit(*this, f);
  }

 private:
  template <class Self, class F>
  static void visit(Self& b, F& f) {
    f(b.pos), f(b.vel), f(b.angvel), f(b.force), f(b.torque), f(b.ext_force), f(b.ext_torque);
    f(b.ori), f(b.radius), f(b.mass), f(b.inertia), f(b.material), f(b.blocked), f(b.kind);
    f(b.clump), f(b.image);
    f(b.ke), f(b.damp_dissip), f(b.ext_work), f(b.pos_at_energy_reset);
    f(b.inertia_scale);  // (last: checkpoints before version 10 end before it)
  }

 public:

  /// Reorders every array: the body at slot perm[s] moves to slot s.
  void permute(const std::vector<int>& perm) {
    const size_t n = perm.size();
    for_each_array([&](auto& v) {
      if (v.size() != n) return;
      auto old = v;
      for (size_t b = 0; b < n; ++b) v[b] = old[perm[b]];
    });
  }
};

}  // namespace cpp_dem
