// The pair pass's linear short kernel on eight contacts at once: each lane of an 8-lane
// register is one contact (structure of arrays), where the per-contact loop keeps one
// contact's 3-vector in a 4-lane register (WideOps). Every lane runs the per-contact loop's
// operations in its order (sphere_sphere_frame, linear_frictional, the force and moments),
// with its branches as selections, so each contact gets the same bits (-ffp-contract=off:
// no multiply-add is fused in either). GCC lowers the 8-lane type to one AVX-512 register
// or two AVX2 ones in the pass's clones.
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

/// The contacts a block of rows queues for the batch (pair.cpp), by field (structure of
/// arrays), kCap of them and the lanes that pad the last batch: each contact's branch vector
/// d = x_j - x_i (m), distance and overlap (m), radii (m), its record's slot and its bodies;
/// and what the batch gives back: j's force f (N) and torque tj (N m), and l_i n x f (N m),
/// i's torque (the pass subtracts f and it from i's sums).
template <int kCap>
struct Queue {
  static constexpr int kSize = kCap + kLanes;
  alignas(64) Real dx[kSize], dy[kSize], dz[kSize], dist[kSize], overlap[kSize], ri[kSize],
      rj[kSize];
  alignas(64) int s[kSize], i[kSize], j[kSize];
  alignas(64) Real fx[kSize], fy[kSize], fz[kSize], tx[kSize], ty[kSize], tz[kSize],
      lx[kSize], ly[kSize], lz[kSize];
  /// Queues a contact at slot m.
  ALWAYS_INLINE void put(int m, const V4& d, Real dist_, Real overlap_, Real ri_, Real rj_,
                         int s_, int i_, int j_) {
    dx[m] = d[0];
    dy[m] = d[1];
    dz[m] = d[2];
    dist[m] = dist_;
    overlap[m] = overlap_;
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
      dist[m] = dist[n - 1];
      overlap[m] = overlap[n - 1];
      ri[m] = ri[n - 1];
      rj[m] = rj[n - 1];
      s[m] = s[n - 1];
      i[m] = i[n - 1];
      j[m] = j[n - 1];
    }
  }
};

/// The 4 x 4 transpose: rows a, b, c, e to columns r0..r3 (r0 = {a0, b0, c0, e0}, ...).
ALWAYS_INLINE void transpose4(const V4& a, const V4& b, const V4& c, const V4& e, V4& r0, V4& r1,
                              V4& r2, V4& r3) {
  const V4 t0 = __builtin_shuffle(a, b, V4i{0, 4, 2, 6});
  const V4 t1 = __builtin_shuffle(a, b, V4i{1, 5, 3, 7});
  const V4 t2 = __builtin_shuffle(c, e, V4i{0, 4, 2, 6});
  const V4 t3 = __builtin_shuffle(c, e, V4i{1, 5, 3, 7});
  r0 = __builtin_shuffle(t0, t2, V4i{0, 1, 4, 5});
  r1 = __builtin_shuffle(t1, t3, V4i{0, 1, 4, 5});
  r2 = __builtin_shuffle(t0, t2, V4i{2, 3, 6, 7});
  r3 = __builtin_shuffle(t1, t3, V4i{2, 3, 6, 7});
}

/// Eight lanes: two 4-lane halves.
typedef double V8 __attribute__((vector_size(64)));
typedef long long V8i __attribute__((vector_size(64)));
ALWAYS_INLINE V8 join(const V4& lo, const V4& hi) {
  return __builtin_shufflevector(lo, hi, 0, 1, 2, 3, 4, 5, 6, 7);
}
ALWAYS_INLINE V4 low(const V8& v) { return __builtin_shufflevector(v, v, 0, 1, 2, 3); }
ALWAYS_INLINE V4 high(const V8& v) { return __builtin_shufflevector(v, v, 4, 5, 6, 7); }

/// Eight 3-vectors (one per lane) in three registers of their components.
struct X3 {
  V8 x, y, z;
};
ALWAYS_INLINE X3 operator+(const X3& a, const X3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
ALWAYS_INLINE X3 operator-(const X3& a, const X3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
ALWAYS_INLINE X3 operator-(const X3& a) { return {-a.x, -a.y, -a.z}; }
/// Each lane's scalar times its vector.
ALWAYS_INLINE X3 operator*(const V8& s, const X3& a) { return {s * a.x, s * a.y, s * a.z}; }
/// dot3's order: (x x' + y y') + z z'.
ALWAYS_INLINE V8 dot(const X3& a, const X3& b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
/// cross3's lanes.
ALWAYS_INLINE X3 cross(const X3& a, const X3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
ALWAYS_INLINE X3 select(const V8i& m, const X3& a, const X3& b) {
  return {m ? a.x : b.x, m ? a.y : b.y, m ? a.z : b.z};
}
/// The lanes' 3-vectors from eight registers, one a lane (their lane 3 is not read).
ALWAYS_INLINE X3 columns(const V4 (&r)[8]) {
  V4 x0, y0, z0, w0, x1, y1, z1, w1;
  transpose4(r[0], r[1], r[2], r[3], x0, y0, z0, w0);
  transpose4(r[4], r[5], r[6], r[7], x1, y1, z1, w1);
  return {join(x0, x1), join(y0, y1), join(z0, z1)};
}
/// The lanes' 3-vectors as eight registers with lane 3 set to w's lane, each to store(l, r).
template <class Store>
ALWAYS_INLINE void rows(const X3& a, const V8& w, Store store) {
  V4 r0, r1, r2, r3;
  transpose4(low(a.x), low(a.y), low(a.z), low(w), r0, r1, r2, r3);
  store(0, r0);
  store(1, r1);
  store(2, r2);
  store(3, r3);
  transpose4(high(a.x), high(a.y), high(a.z), high(w), r0, r1, r2, r3);
  store(4, r0);
  store(5, r1);
  store(6, r2);
  store(7, r3);
}

// (the record's rows that the batch loads as 4-lane registers)
static_assert(offsetof(PairContact, ks) == offsetof(PairContact, kn) + sizeof(Real) &&
                  offsetof(PairContact, tan_phi) == offsetof(PairContact, kn) + 2 * sizeof(Real) &&
                  offsetof(PairContact, overlap) == offsetof(PairContact, fs) + 3 * sizeof(Real) &&
                  offsetof(PairContact, fn) == offsetof(PairContact, normal) + 3 * sizeof(Real),
              "PairContact's fields as the batch reads them");

ALWAYS_INLINE V8 load8(const Real* p) {
  V8 r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
ALWAYS_INLINE void store8(Real* p, const V8& v) { std::memcpy(p, &v, sizeof v); }

/// The linear short kernel (the per-contact loop's linear branch, kYadeShear as there) on
/// the queued contacts m .. m + 7 of q, each an active contact of the linear kernel with a
/// current phys and dist > 0; the bodies' velocities (m/s) and spins (rad/s) in vel and
/// angvel, dt (s); kPeriodic: the cell's velocity gradient by columns l0, l1, l2 (1/s) and
/// spin (rad/s), added to the stored fluctuations as the loop does. Updates their records
/// (pairs) and slip energies (dissip, J) as the loop does and puts their results into q. A lane may repeat another's contact (the padding of
/// the last batch): it writes the same values.

template <bool kYadeShear, bool kPeriodic, class Q>
ALWAYS_INLINE void linear8(Q& q, int m, PairContact* pairs, Real* dissip, const Vec3* vel,
                           const Vec3* angvel, Real dt, const V4& l0, const V4& l1,
                           const V4& l2, const V4& spin) {
  PairContact* c[8];
  V4 r[8];
  V8 dis;
  for (int l = 0; l < 8; ++l) {
    c[l] = &pairs[q.s[m + l]];
    dis[l] = dissip[q.s[m + l]];
  }
  const X3 d = {load8(q.dx + m), load8(q.dy + m), load8(q.dz + m)};
  const V8 dist = load8(q.dist + m), overlap = load8(q.overlap + m), ri8 = load8(q.ri + m),
           rj = load8(q.rj + m);
  for (int l = 0; l < 8; ++l) r[l] = v4(vel[q.i[m + l]]);
  const X3 vi3 = columns(r);
  for (int l = 0; l < 8; ++l) r[l] = v4(angvel[q.i[m + l]]);
  X3 wi3 = columns(r);
  for (int l = 0; l < 8; ++l) r[l] = v4(vel[q.j[m + l]]);
  X3 vj = columns(r);
  for (int l = 0; l < 8; ++l) r[l] = v4(angvel[q.j[m + l]]);
  X3 wj = columns(r);
  if constexpr (kPeriodic) {
    // the mean field's spin on both, and its velocity L d on j (d holds j's image)
    const X3 sp = {V8{} + spin[0], V8{} + spin[1], V8{} + spin[2]};
    wi3 = wi3 + sp;
    wj = wj + sp;
    vj = vj + X3{(l0[0] * d.x + l1[0] * d.y) + l2[0] * d.z,
                 (l0[1] * d.x + l1[1] * d.y) + l2[1] * d.z,
                 (l0[2] * d.x + l1[2] * d.y) + l2[2] * d.z};
  }
  for (int l = 0; l < 8; ++l) r[l] = load4(c[l]->fs.data());
  X3 fs = columns(r);
  for (int l = 0; l < 8; ++l) r[l] = load4(c[l]->normal.data());
  const X3 n_old = columns(r);
  // (kn, ks, tan_phi and fs's first component lie in a row in the record)
  for (int l = 0; l < 8; ++l) r[l] = load4(&c[l]->kn);
  const X3 phys = columns(r);
  const V8 kn = phys.x, ks = phys.y, tan_phi = phys.z;
  // sphere_sphere_frame (dist > 0)
  const V8 inv = 1.0 / dist;
  const X3 n = inv * d;
  const V8 li = ri8 - 0.5 * overlap, lj = rj - 0.5 * overlap;
  X3 rel_vel;
  if constexpr (kYadeShear) {
    const V8 rsum = ri8 + rj;
    const V8 alpha = rsum / (rsum - overlap);
    rel_vel = alpha * (vj - vi3) - cross(rj * wj + ri8 * wi3, n);
  } else {
    rel_vel = (vj - vi3) - cross(lj * wj + li * wi3, n);
  }
  // linear_frictional: frictional_spring with fn = kn overlap
  const V8 fn = kn * overlap;
  const X3 angvel_sum = wi3 + wj;
  const V8 vn = dot(rel_vel, n);
  const X3 vt = rel_vel - vn * n;
  {
    // frame_turn and turn_into_frame, where the old normal is not zero
    const X3 axis = cross(n_old, n);
    const X3 twist = ((0.5 * dt) * dot(n, angvel_sum)) * n;
    X3 t = fs;
    t = t - cross(t, axis);
    t = t - cross(t, twist);
    t = t - dot(t, n) * n;
    fs = select(dot(n_old, n_old) > 0, t, fs);
  }
  fs = fs - (ks * dt) * vt;
  // cap_magnitude with the cap tan_phi max(fn, 0)
  const V8 cap = tan_phi * ((fn > 0) ? fn : V8{});
  const V8 t2 = dot(fs, fs);
  const V8i slip = t2 > cap * cap;
  bool any = false;
  for (int l = 0; l < 8; ++l) any |= slip[l] != 0;
  if (any) {
    V8 nrm;
    for (int l = 0; l < 8; ++l) nrm[l] = std::sqrt(t2[l]);
    const V8 scale = cap / nrm;
    const X3 capped = select(nrm > 0, scale * fs, X3{V8{}, V8{}, V8{}});
    const V8 gained = dis + dot(fs - capped, capped) / ks;
    dis = (slip & (ks > 0)) ? gained : dis;
    fs = select(slip, capped, fs);
  }
  // The record, the force f = fn n + fs and the moments (n x f = n x fs)
  rows(fs, overlap, [&](int l, const V4& v) { store4(c[l]->fs.data(), v); });
  rows(n, fn, [&](int l, const V4& v) { store4(c[l]->normal.data(), v); });
  for (int l = 0; l < 8; ++l) dissip[q.s[m + l]] = dis[l];
  const X3 f = fn * n + fs;
  const X3 nxf = cross(n, fs);
  const X3 tj = (-lj) * nxf, lnxf = li * nxf;
  store8(q.fx + m, f.x);
  store8(q.fy + m, f.y);
  store8(q.fz + m, f.z);
  store8(q.tx + m, tj.x);
  store8(q.ty + m, tj.y);
  store8(q.tz + m, tj.z);
  store8(q.lx + m, lnxf.x);
  store8(q.ly + m, lnxf.y);
  store8(q.lz + m, lnxf.z);
}

}  // namespace pair_batch
}  // namespace cpp_dem
