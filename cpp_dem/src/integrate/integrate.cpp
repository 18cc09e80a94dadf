// The integration pass: contact forces reduced into bodies in a fixed order, then leapfrog
// with Cundall local damping, blocked DOFs and orientations.
#include <algorithm>
#include <cmath>
#include <limits>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/core/simd.hpp"
#include "cpp_dem/scene.hpp"
#include "terms.hpp"

namespace cpp_dem {

namespace {
using namespace integrate_terms;

/// One leapfrog half of the update for a run of `count` degrees of freedom of flat arrays:
/// the accelerations acc (m/s^2 or rad/s^2, zero for a blocked DOF) are damped (Cundall local
/// damping, lambda) and give the new velocities vel; with pos (not null) the positions follow,
/// pos += vel dt. Returns the sum of the new positions and velocities, which is finite unless
/// one of them is not (or the sum overflows; the caller then tests each body). The loop is
/// elementwise, so the compiler vectorises it across bodies.
template <bool kDamp>
inline Real leapfrog_dofs(Real* __restrict vel, const Real* __restrict acc, Real* __restrict pos,
                          long count, Real dt, Real lambda) {
  Real check = 0;
  if (pos) {
#pragma omp simd reduction(+ : check)
    for (long k = 0; k < count; ++k) {
      const Real v = vel[k] + (kDamp ? damp_component(acc[k], vel[k], dt, lambda) : acc[k]) * dt;
      vel[k] = v;
      pos[k] += v * dt;
      check += pos[k] + v;
    }
  } else {
#pragma omp simd reduction(+ : check)
    for (long k = 0; k < count; ++k) {
      const Real v = vel[k] + (kDamp ? damp_component(acc[k], vel[k], dt, lambda) : acc[k]) * dt;
      vel[k] = v;
      check += v;
    }
  }
  return check;
}
}  // namespace

void Scene::reduce_and_integrate(long& err_body) { reduce_and_integrate_hot(err_body); }

void Scene::reduce_and_integrate_hot(long& err_body) {
  const int n = num_bodies();
  const Real dt = dt_;
  const Real lambda = local_damping_;
  const bool energy = track_energy_;
  const bool grid = has_grid();  // constant false without the geogrid: the branch vanishes
  const bool bonded = has_bonds();
  const bool cylinders = !cylinder_walls_.empty();
  const bool meshes = !mesh_walls_.empty();
  const bool renormalize = step_ % kRenormalizePeriod == 0;
  long err = std::numeric_limits<long>::max();
  Real worst = 0;
  // A deforming periodic cell: each body then takes the mean field's map x -> A x (and the
  // mean spin's rotation) here, while it is in the cache, and the broad phase's measure is
  // its displacement beyond the cell's, |x - F_b x_build| (integrate/cell.cpp).
  const bool mean_field = cell_.on && (!cell_.vel_grad.isZero(0) || cell_.h != cell_.h_at_build);
  MeanFieldStep field;
  if (mean_field) field = mean_field_step();
  const auto finish_body = [&](int b) __attribute__((always_inline)) {
    if (!mean_field) return displacement_since_build(b);
    field.apply(bodies_.pos[b], bodies_.ori[b]);
    return displacement_since_build(b, field.fb);
  };

  // Reduce the contact forces into body b in a fixed order: the contacts where b is j (in
  // contact order, contiguous in pair_out_), the sum over the contacts where b is i (which
  // the pair pass formed in contact order), walls, the geogrid's contacts and links, then
  // bonds.
  const Real* const fi = pair_fi_.data()->data();
  const Real* const ti = pair_ti_.data()->data();
  // (With the 3-vector operations of `ops`, WideOps or NarrowOps: see the pair pass.)
  // A two-sided record (a geogrid link, a bond) gives its body b force_b and torque_b, or
  // its body a -force_b and torque_a.
  const auto add_two_sided = [](const auto& l, int b, auto& f, auto& t, auto ops)
      __attribute__((always_inline)) {
    if (l.b == b) {
      f += ops.load(l.force_b);
      t += ops.load(l.torque_b);
    } else {
      f -= ops.load(l.force_b);
      t += ops.load(l.torque_a);
    }
  };
  // (After a direct pair pass, pair_direct_, the bodies' force and torque hold these first
  // three terms summed in this order: the external force and the weight, j's shares, i's.)
  const bool direct = pair_direct_;
  const auto sum_forces = [&](int b, auto& f, auto& t, auto ops) __attribute__((always_inline)) {
    if (direct) {
      f = ops.load(bodies_.force[b]);
      t = ops.load(bodies_.torque[b]);
    } else {
      f = ops.load(bodies_.ext_force_of(b)) + bodies_.mass[b] * ops.load(gravity_);
      t = ops.load(bodies_.ext_torque_of(b));
      for (int e = pair_jadj_off_[b]; e < pair_jadj_off_[b + 1]; ++e) {
        const PairOutput& o = pair_out_[e];  // zero when inactive
        f += ops.load_padded(o.force.data());
        t += ops.load_padded(o.torque_j.data());
      }
      f += ops.load_padded(fi + 4L * b);
      t += ops.load_padded(ti + 4L * b);
    }
    for (int e = wall_adj_off_[b]; e < wall_adj_off_[b + 1]; ++e) {
      const WallContact& c = wall_contacts_[wall_adj_[e]];
      if (!c.active) continue;
      f += ops.load(c.force);
      t += ops.load(c.torque);
    }
    if (cylinders) {
      for (int e = cyl_adj_off_[b]; e < cyl_adj_off_[b + 1]; ++e) {
        const WallContact& c = cylinder_contacts_[cyl_adj_[e]];
        if (!c.active) continue;
        f += ops.load(c.force);
        t += ops.load(c.torque);
      }
    }
    if (meshes) {
      // (from the mesh pass's shares: a touching pair's contacts are its first n slots, the
      // same forces and torques as its records', read without the 664-B records)
      for (int e = mesh_adj_off_[b]; e < mesh_adj_off_[b + 1]; ++e) {
        const long k = mesh_adj_[e];
        for (long q = MeshContact::kMaxSubs * k, end = q + mesh_sum_code_[k] % 4; q < end; ++q) {
          f += ops.load(mesh_sum_f_[q]);
          t += ops.load(mesh_sum_t_[q]);
        }
      }
    }
    if (grid) {
      // Grain side of grain–geogrid contacts.
      // (grid_live_: the contacts' active bits, packed, read before the contact itself)
      for (int e = sphere_gc_off_[b]; e < sphere_gc_off_[b + 1]; ++e) {
        if (!(grid_live_[sphere_gc_[e]] & kGridActive)) continue;
        const GridContact& c = grid_contacts_[sphere_gc_[e]];
        f += ops.load(c.force);
        t += ops.load(c.torque_sphere);
      }
      // Node side: the virtual sphere's force and torque split by the weights (000 eq 19).
      for (int e = node_gc_off_[b]; e < node_gc_off_[b + 1]; ++e) {
        if (!(grid_live_[node_gc_[e] / 3] & kGridActive)) continue;
        const GridContact& c = grid_contacts_[node_gc_[e] / 3];
        const Real w = c.w[node_gc_[e] % 3];
        f -= w * ops.load(c.force);
        t += w * ops.load(c.torque_virtual);
      }
      // Cohesive links.
      for (int e = node_link_off_[b]; e < node_link_off_[b + 1]; ++e) {
        const GridLink& l = links_[node_link_[e]];
        if (!l.broken) add_two_sided(l, b, f, t, ops);
      }
    }
    if (bonded) {
      // Bonds, in bond order.
      for (int e = body_bond_off_[b]; e < body_bond_off_[b + 1]; ++e)
        add_two_sided(bonds_[body_bond_[e]], b, f, t, ops);
    }
    ops.store(bodies_.force[b], f);
    ops.store(bodies_.torque[b], t);
  };
  const auto forces_finite = [&](int b) { return bodies_.force[b].allFinite() && bodies_.torque[b].allFinite(); };
  // Forces and accelerations of bodies [b0, b1) (inverse masses and inertias from b0 on);
  // false if a force or torque may be non-finite.
  const auto block_forces = [&](int b0, int b1, const Real* inv_m, const Real* inv_i,
                                Vec3* acc_l, Vec3* acc_a, auto ops) __attribute__((always_inline)) {
    using V = typename decltype(ops)::V;
    V fcheck = ops.zero();  // sum of every force and torque: finite unless one of them is not
    for (int b = b0; b < b1; ++b) {
      V f, t;
      sum_forces(b, f, t, ops);
      fcheck += f + t;
      V al = f * inv_m[b - b0], aa = t * inv_i[b - b0];
      if (const std::uint8_t dofs = bodies_.blocked[b]) {
        // A blocked DOF keeps its imposed velocity: zero acceleration, nothing to damp.
        for (int a = 0; a < 3; ++a) {
          if (dofs & (DOF_X << a)) al[a] = 0;
          if (dofs & (DOF_RX << a)) aa[a] = 0;
        }
      }
      ops.store(acc_l[b - b0], al);
      ops.store(acc_a[b - b0], aa);
    }
    return std::isfinite(fcheck[0] + fcheck[1] + fcheck[2]);
  };
  // Forces of the clump members [b0, b1) only; false if one may be non-finite.
  const auto member_forces = [&](int b0, int b1, auto ops) __attribute__((always_inline)) {
    using V = typename decltype(ops)::V;
    V fcheck = ops.zero();
    for (int b = b0; b < b1; ++b) {
      V f, t;
      sum_forces(b, f, t, ops);
      fcheck += f + t;
    }
    return std::isfinite(fcheck[0] + fcheck[1] + fcheck[2]);
  };
  const bool wide = use_wide_ops();

  if (!energy) {
    // Blocks of bodies, each in three passes while it stays in the L1 cache: forces and
    // accelerations per body, then the velocities and positions as flat arrays of degrees of
    // freedom (vectorised across bodies), then orientations and checks. Every body's
    // update is the same arithmetic whatever the blocks or threads.
    // (The accelerations live in a block's buffers, acc_l and acc_a: 48 B a body less than
    // arrays of every body's, and they stay in the L1 cache.)
    Real* const vel = bodies_.vel.data()->data();
    Real* const angvel = bodies_.angvel.data()->data();
    Real* const pos = bodies_.pos.data()->data();
    const Real* const mass = bodies_.mass.data();
    const Real* const inertia = bodies_.inertia.data();
    const Real* const scale =
        ds_on_ && !bodies_.inertia_scale.empty() ? bodies_.inertia_scale.data() : nullptr;
    const bool has_clumps = clumps_.size() > 0;
    const int* const clump_of = bodies_.clump.data();
    const bool radii_grown = !radius_at_build_.empty();  // (finish_body adds the growth)
    constexpr int kBlock = kBodyBlock;
    const int nblocks = (n + kBlock - 1) / kBlock;
#pragma omp parallel reduction(min : err) reduction(max : worst) if (n > kParallelMin)
    {
      const auto [t, nt] = thread_and_team();
      const auto blocks = thread_share(nblocks, t, nt);
      for (long blk = blocks.first; blk < blocks.second; ++blk) {
        const int b0 = static_cast<int>(blk) * kBlock, b1 = std::min(n, b0 + kBlock);
        const int count = b1 - b0;
        // A block of clump members only (a scene of clumps, its members stored together):
        // the clump pass sets their positions, velocities, spins and orientations from their
        // clump and measures their displacement, so this pass gives them their forces and
        // nothing more (fully blocked, their velocities would not change here anyway).
        bool members_only = has_clumps && !mean_field;
        for (int b = b0; b < b1 && members_only; ++b) members_only = clump_of[b] >= 0;
        if (members_only) {
          const bool ok =
              wide ? member_forces(b0, b1, WideOps()) : member_forces(b0, b1, NarrowOps());
          if (!ok) {
            for (int b = b0; b < b1; ++b)
              if (!forces_finite(b)) err = std::min(err, static_cast<long>(b));
          }
          continue;
        }
        // Inverse masses and inertias of the block (vectorised divisions).
        Real inv_m[kBlock], inv_i[kBlock];
        if (scale) {
          // Density scaling: the inertia times the body's factor (the weight above is not).
#pragma omp simd
          for (int q = 0; q < count; ++q) {
            inv_m[q] = 1.0 / (mass[b0 + q] * scale[b0 + q]);
            inv_i[q] = 1.0 / (inertia[b0 + q] * scale[b0 + q]);
          }
        } else {
#pragma omp simd
          for (int q = 0; q < count; ++q) {
            inv_m[q] = 1.0 / mass[b0 + q];
            inv_i[q] = 1.0 / inertia[b0 + q];
          }
        }
        Vec3 acc_l[kBlock], acc_a[kBlock];
        const bool forces_ok =
            wide ? block_forces(b0, b1, inv_m, inv_i, acc_l, acc_a, WideOps())
                 : block_forces(b0, b1, inv_m, inv_i, acc_l, acc_a, NarrowOps());
        if (!forces_ok) {
          // Only now the exact test; a body with a non-finite force or torque does not move.
          for (int b = b0; b < b1; ++b) {
            if (!forces_finite(b)) {
              err = std::min(err, static_cast<long>(b));
              acc_l[b - b0].setZero();
              acc_a[b - b0].setZero();
            }
          }
        }
        const long k0 = 3L * b0, k1 = 3L * b1;
        const Real* const acc_lin = acc_l[0].data();
        const Real* const acc_ang = acc_a[0].data();
        Real check;
        if (lambda > 0) {
          check = leapfrog_dofs<true>(vel + k0, acc_lin, pos + k0, 3L * count, dt, lambda) +
                  leapfrog_dofs<true>(angvel + k0, acc_ang, nullptr, 3L * count, dt, lambda);
        } else {
          check = leapfrog_dofs<false>(vel + k0, acc_lin, pos + k0, 3L * count, dt, lambda) +
                  leapfrog_dofs<false>(angvel + k0, acc_ang, nullptr, 3L * count, dt, lambda);
        }
        // Orientations: vectorised across the block when every spin is in the series range.
        Real w2max = 0;
#pragma omp simd reduction(max : w2max)
        for (long k = k0; k < k1; ++k) w2max = std::max(w2max, angvel[k] * angvel[k]);
        if (3 * 0.25 * dt * dt * w2max < kSeriesH2) {  // |w|^2 <= 3 max_a w_a^2
          Real* const q = bodies_.ori[b0].coeffs().data();
          if (renormalize) rotate_orientations<true>(q, angvel + k0, count, dt);
          else rotate_orientations<false>(q, angvel + k0, count, dt);
        } else {
          for (int b = b0; b < b1; ++b) rotate_orientation(bodies_.ori[b], bodies_.angvel[b], dt, renormalize);
        }
        const bool finite = std::isfinite(check);
        if (finite && !mean_field && !radii_grown) {
          // The block's largest displacement since the build from its squared lengths,
          // vectorised, and one square root: sqrt is monotonic and correctly rounded, so
          // this is the largest of finish_body's lengths, to the bit.
          const Real* const p0 = pos_at_build_[b0].data();
          Real d2max = 0;
#pragma omp simd reduction(max : d2max)
          for (long k = k0; k < k1; k += 3) {
            const Real dx = pos[k] - p0[k - k0], dy = pos[k + 1] - p0[k - k0 + 1],
                       dz = pos[k + 2] - p0[k - k0 + 2];
            d2max = std::max(d2max, (dx * dx + dy * dy) + dz * dz);
          }
          worst = std::max(worst, std::sqrt(d2max));
          continue;
        }
        for (int b = b0; b < b1; ++b) {
          if (!finite && (!bodies_.pos[b].allFinite() || !bodies_.vel[b].allFinite() || !bodies_.angvel[b].allFinite())) {
            err = std::min(err, static_cast<long>(b));
            continue;
          }
          worst = std::max(worst, finish_body(b));  // (need_rebuild's check)
        }
      }
    }
  } else {
    // With energy bookkeeping: per body, the same arithmetic plus the damping's dissipation
    // and the work of external forces and of imposed velocities.
#pragma omp parallel for schedule(static) reduction(min : err) reduction(max : worst) \
    if (n > kParallelMin)
    for (int b = 0; b < n; ++b) {
      Vec3 f, t;
      sum_forces(b, f, t, NarrowOps());  // (per body: no gain from the wide form)
      if (bodies_.clump[b] >= 0) continue;  // a clump member: the clump pass books its energy
      // A NaN or inf in any component makes the sum non-finite; only then the exact test.
      if (!std::isfinite((f[0] + f[1] + f[2]) + (t[0] + t[1] + t[2])) && !forces_finite(b)) {
        err = std::min(err, static_cast<long>(b));
        continue;
      }
      const std::uint8_t dofs = bodies_.blocked[b];
      const Vec3 v_old = bodies_.vel[b], w_old = bodies_.angvel[b];
      const Real ds = ds_on_ ? bodies_.inertia_scale_of(b) : 1.0;  // density scaling
      const Real m = bodies_.mass[b] * ds, inertia = bodies_.inertia[b] * ds;
      const Real inv_m = 1.0 / m, inv_i = 1.0 / inertia;
      Real dissip = 0, work = 0;
      // (Imposed velocity: the constraint supplies -f[a]; its work is -f[a] v dt.)
      const Vec3 v = leapfrog_velocity<true>(f, bodies_.ext_force_of(b), m, inv_m, dofs, DOF_X, v_old,
                                             dt, lambda, dissip, work);
      const Vec3 w = leapfrog_velocity<true>(t, bodies_.ext_torque_of(b), inertia, inv_i, dofs, DOF_RX,
                                             w_old, dt, lambda, dissip, work);
      const Vec3 vm = 0.5 * (v_old + v);
      const Vec3 wm = 0.5 * (w_old + w);
      bodies_.ke[b] = 0.5 * m * vm.squaredNorm() + 0.5 * inertia * wm.squaredNorm();
      bodies_.damp_dissip[b] += dissip;
      bodies_.ext_work[b] += work;
      bodies_.vel[b] = v;
      bodies_.angvel[b] = w;
      const Vec3 x = bodies_.pos[b] + v * dt;
      bodies_.pos[b] = x;
      rotate_orientation(bodies_.ori[b], w, dt, renormalize);
      if (!std::isfinite((x[0] + x[1] + x[2]) + (v[0] + v[1] + v[2]) + (w[0] + w[1] + w[2])) &&
          (!x.allFinite() || !v.allFinite() || !w.allFinite())) {
        err = std::min(err, static_cast<long>(b));
        continue;
      }
      worst = std::max(worst, finish_body(b));  // (need_rebuild's check)
    }
  }
  err_body = err;
  if (err == std::numeric_limits<long>::max()) {
    max_disp_ = worst;
    disp_valid_ = true;
  }
}

}  // namespace cpp_dem
