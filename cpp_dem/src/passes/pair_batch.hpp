// The pair pass's linear short kernel on eight contacts at once: each lane of an 8-lane
// register is one contact (structure of arrays), where the per-contact loop keeps one
// contact's 3-vector in a 4-lane register (WideOps). Every lane runs the per-contact loop's
// operations in its order (sphere_sphere_frame, linear_frictional, the force and moments),
// with its branches as selections, so each contact gets the same bits (-ffp-contract=off:
// no multiply-add is fused in either). The kernel (pair_batch_kernel.inc) is compiled in
// pair_batch.cpp for AVX-512, and kernel() gives it where the CPU has it.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstring>

#include "cpp_dem/contacts/pair_contact.hpp"
#include "cpp_dem/core/simd.hpp"

namespace cpp_dem {
namespace pair_batch {

/// The number of contacts a batch runs at once.
constexpr int kLanes = 8;
/// The longest row (candidates of one body) the direct pass runs through the batch, and the
/// most contacts a block of rows queues.
constexpr int kBatchRow = 128;

/// The contacts a block of rows queues for the batch (pair.cpp), by field (structure of
/// arrays), kCap of them and the lanes that pad the last batch: each contact's branch vector
/// d = x_j - x_i (m), its squared length (m^2; the batch takes its square root and the
/// overlap), radii (m), its record's slot and its bodies; and what the batch gives back: j's
/// force f (N) and torque tj (N m), l_i n x f (N m), i's torque (the pass subtracts f and it
/// from i's sums), and whether the contact overlaps beyond the scene's limit (bad: nonzero;
/// its record is left as it was and it gives no force).
template <int kCap>
struct Queue {
  static constexpr int kSize = kCap + kLanes;
  alignas(64) Real dx[kSize], dy[kSize], dz[kSize], dist2[kSize], ri[kSize], rj[kSize];
  alignas(64) int s[kSize], i[kSize], j[kSize];
  alignas(64) Real fx[kSize], fy[kSize], fz[kSize], tx[kSize], ty[kSize], tz[kSize],
      lx[kSize], ly[kSize], lz[kSize];
  alignas(64) long long bad[kSize];
  /// Queues a contact at slot m.
  ALWAYS_INLINE void put(int m, const V4& d, Real dist2_, Real ri_, Real rj_, int s_, int i_,
                         int j_) {
    dx[m] = d[0];
    dy[m] = d[1];
    dz[m] = d[2];
    dist2[m] = dist2_;
    ri[m] = ri_;
    rj[m] = rj_;
    s[m] = s_;
    i[m] = i_;
    j[m] = j_;
  }
  /// Slots n .. the next multiple of kLanes repeat contact n - 1 (n > 0).
  ALWAYS_INLINE void pad(int n) {
    for (int m = n; m % kLanes != 0; ++m) {
      dx[m] = dx[n - 1];
      dy[m] = dy[n - 1];
      dz[m] = dz[n - 1];
      dist2[m] = dist2[n - 1];
      ri[m] = ri[n - 1];
      rj[m] = rj[n - 1];
      s[m] = s[n - 1];
      i[m] = i[n - 1];
      j[m] = j[n - 1];
    }
  }
};

// (the record's rows that the batch loads as 4-lane registers)
static_assert(offsetof(PairContact, ks) == offsetof(PairContact, kn) + sizeof(Real) &&
                  offsetof(PairContact, tan_phi) == offsetof(PairContact, kn) + 2 * sizeof(Real) &&
                  offsetof(PairContact, overlap) == offsetof(PairContact, fs) + 3 * sizeof(Real) &&
                  offsetof(PairContact, fn) == offsetof(PairContact, normal) + 3 * sizeof(Real),
              "PairContact's fields as the batch reads them");

/// The batch's kernel: linear8 (pair_batch_kernel.inc) on the queued contacts 0 .. nq of q
/// (padded to a multiple of kLanes), each an active contact of the linear kernel with a
/// current phys and 0 < dist2 < (ri + rj)^2; the bodies' velocities (m/s) and spins (rad/s)
/// in vel and angvel, dt (s); max_ratio: the scene's largest overlap over the smaller radius;
/// field: the periodic cell's velocity gradient by columns (1/s) and its spin (rad/s), read
/// where kPeriodic. Updates their records (pairs) and slip energies (dissip, J) as the
/// per-contact loop does and puts their results into q. Returns whether a contact overlaps
/// beyond max_ratio (each one's q.bad is set, its record and dissip untouched), which the
/// per-contact loop reports as the pass's error.
using Kernel = bool (*)(Queue<kBatchRow>& q, int nq, PairContact* pairs, Real* dissip,
                        const Vec3* vel, const Vec3* angvel, Real dt, Real max_ratio,
                        const V4* field);

/// The kernel for this CPU (pair_batch.cpp: compiled for AVX-512), or null where it has
/// none: the pass then runs every contact in its per-contact loop.
template <bool kYadeShear, bool kPeriodic>
Kernel kernel();

}  // namespace pair_batch
}  // namespace cpp_dem
