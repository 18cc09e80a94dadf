// The pair pass: every sphere–sphere contact, body-major, in two vector forms (4-lane
// registers where the CPU has AVX2, Eigen elsewhere) around the same law kernels.
#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/core/simd.hpp"
#include "cpp_dem/geometry/sphere_sphere.hpp"
#include "cpp_dem/laws/hertz_mindlin.hpp"
#include "cpp_dem/laws/linear.hpp"
#include "cpp_dem/laws/registry.hpp"
#include "cpp_dem/scene.hpp"
#include "pair_batch.hpp"

namespace cpp_dem {

namespace {

using pair_batch::kBatchRow;
/// The passes without the batch after one that queued under a quarter of its candidates.
constexpr int kBatchRest = 32;

/// The scenes below this many bodies run the batch (with the kernel compiled for AVX-512),
/// on any number of threads. Measured with the profile driver (three runs each, median), the
/// step with the batch against without, one thread: 1.10 x as fast at 7 000 bodies and at
/// 10 000, 0.97 x at 20 000; two threads: 1.12 x at 10 000, 0.95 x at 20 000, 0.94 x at
/// 30 000 (from 20 000 bodies on the per-contact loop prefetches: kPrefetchMinBodies).
constexpr int kBatchMaxBodies = 20000;

// The pair pass's modes (compute_pair_forces_hot, pair_bodies_narrow): j's shares into the
// outputs, summed by the reduction; j's and i's into the bodies' sums at once; a threaded
// direct pass's cross pairs' shares into their PairCross.
constexpr int kPassOutputs = 0, kPassDirect = 1, kPassCross = 2;

/// Pair contact c with the Hertz–Mindlin short kernel (hertz_frictional; kDamped:
/// hertz_damped, with the dashpots of its cold record's phys) on its hot record: j's force
/// and torque into force_j and torque_j (PairOutput's padded vectors), i's shares (as the
/// pass adds them) into dfi and dti; slip energy into dissip_friction, viscous energy into
/// the cold record. The force and the moments are general_pair's expressions, to the bit:
/// the composed law's force fn n + fs plus its shear dashpot's (zero without one), the
/// branches li n and -lj n, and its zero rolling moment added on j and subtracted on i (a -0
/// component comes out as general_pair's).
template <bool kDamped, class Ops, class V>
ALWAYS_INLINE void hertz_pair(PairContact& c, PairContactCold* cold, Real& dissip_friction,
                              Real* force_j, Real* torque_j, const V& n, Real overlap, Real li, Real lj,
                              const V& rel_vel, const V& angvel_sum, Real dt, V& dfi, V& dti,
                              Ops ops) {
  V fs = ops.load_head(c.fs.data());
  V fvs = ops.zero();
  const Real fn =
      kDamped ? hertz_damped<Ops>(fs, ops.load_head(c.normal.data()), n, overlap, rel_vel,
                                  angvel_sum, cold->phys, dt, dissip_friction,
                                  cold->dissip_viscous, fvs)
              : hertz_frictional<Ops>(fs, ops.load_head(c.normal.data()), n, overlap, rel_vel,
                                      angvel_sum, c.kn, c.ks, c.tan_phi, dt, dissip_friction);
  ops.store_with(c.fs.data(), fs, overlap);  // fs, overlap
  ops.store_with(c.normal.data(), n, fn);    // normal, fn
  const V f = fn * n + fs + fvs;
  ops.store_padded(force_j, f);
  ops.store_padded(torque_j, V(ops.cross(V(-lj * n), f) + ops.zero()));
  const V f_i = -f;
  dfi = f_i;
  dti = V(ops.cross(V(li * n), f_i) - ops.zero());
}

}  // namespace

void Scene::update_phys(PairContact& c, size_t k, int i) {
  // (k: the record's slot; a new record, pair_new_, has none and the scene no cold part)
  ContactPhys local;
  ContactPhys& p = pair_cold_on_ ? pair_cold_[k].phys : local;
  const int j = c.j;
  mix_materials(materials_[bodies_.material[i]], materials_[bodies_.material[j]],
                stiffness_radius(i), stiffness_radius(j), bodies_.mass[i], bodies_.mass[j],
                pair_law(bodies_.material[i], bodies_.material[j]), p);
  c.kn = p.kn;
  c.ks = p.ks;
  c.tan_phi = p.tan_phi;
  c.kernel = pair_kernel(p);
  c.model = static_cast<std::uint8_t>(p.model);
  if (!pair_cold_on_ && c.kernel != kLinearKernel && c.kernel != kHertzKernel) {
    // (ensure_pair_cold made no cold part for materials that need one: the pass skips the
    // contact and the step stops with a logic_error)
#pragma omp atomic write
    pair_cold_missing_ = 1;
  }
  note_formed_contact(p, i, j);
}


LawOutput Scene::apply_pair_law(size_t k, const ContactGeometry& g, Real dt) {
  PairContact& c = pairs_[k];
  PairContactCold& cold = pair_cold_[k];  // (the composed law: the scene has the cold part)
  ContactState s = record_state(k);  // (k: the record's slot)
  const LawOutput out = apply_law(cold.phys, g, dt, s);
  c.fs = s.fs;
  c.normal = s.normal;
  c.overlap = s.overlap;
  c.fn = s.fn;
  cold.mr = s.mr;
  pair_dissip_[k] = s.dissip_friction;
  cold.dissip_viscous = s.dissip_viscous;
  return out;
}

/// Pair contact record k has opened: forget its springs' history
/// (ContactState::clear_history) and its output o.
void Scene::open_pair(long k, PairOutput* o) {
  PairContact& c = pairs_[k];
  c.active = false;
  c.fs.setZero();
  c.normal.setZero();
  c.overlap = 0;
  c.fn = 0;
  if (pair_cold_on_) pair_cold_[k].mr.setZero();
  if (o) *o = PairOutput();
}

/// Pair contact k with the composed law (no short kernel for its law and parts): normal n,
/// overlap (m), branch lengths li, lj (m), relative velocity (m/s), sum and difference of the
/// spins (rad/s).
/// Writes j's force and torque into o; returns i's force (N) and torque (N m).
std::pair<Vec3, Vec3> Scene::general_pair(long k, PairOutput& o, const Vec3& n, Real overlap,
                                          Real li, Real lj, const Vec3& rel_vel,
                                          const Vec3& angvel_sum, const Vec3& rel_angvel) {
  const ContactGeometry g =
      sphere_sphere_geometry(n, overlap, li, lj, rel_vel, angvel_sum, rel_angvel);
  const LawOutput out = apply_pair_law(k, g, dt_);
  o.force = out.force2;
  // Moments, 000 eq (6): tau = (R - delta/2) n x F, plus rolling resistance.
  o.torque_j = g.branch2.cross(out.force2) + out.moment2;
  return {-out.force2, g.branch1.cross(-out.force2) - out.moment2};
}

/// The bodies [first, second) whose contacts fall in thread t's equal share of the contact
/// list (of nt threads): a body owns its contacts with larger slots, so equal body counts
/// would give some threads much more work than others.
std::pair<int, int> Scene::pair_bodies_of_thread(long t, long nt) const {
  const int n = num_bodies();
  const long nc = pair_ioff_.empty() ? 0 : static_cast<long>(pair_ioff_.back());
  const auto first_body_at = [&](long k) {
    return static_cast<int>(std::lower_bound(pair_ioff_.begin(), pair_ioff_.begin() + n, k) -
                            pair_ioff_.begin());
  };
  return {first_body_at(t * nc / nt), t + 1 == nt ? n : first_body_at((t + 1) * nc / nt)};
}

/// Bodies [b0, b1) of the pair pass and their contacts with Eigen's Vector3d (NarrowOps), for
/// CPUs without AVX2 and builds without multiversioning (compute_pair_forces_narrow). The same
/// arithmetic as the loop in compute_pair_forces, which is written out there with 4-lane
/// registers: instantiated from one template with WideOps it ran 12 % slower at 1e3 (same
/// instructions, measured 0.070 against 0.063 ms per step, not understood), so the loop is
/// written twice. kYadeShear: ShearKinematics::Yade (sphere_sphere_frame).
template <bool kYadeShear>
void Scene::pair_bodies_narrow(int r0, int r1, long& err_out, int mode, int jlimit,
                               long cursor) {
  using Ops = NarrowOps;
  using V = Ops::V;
  const Ops ops;
  long err = err_out;
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  // (the materials changed since the last pass: every active contact's parameters anew)
  const bool stale = pair_phys_version_ != phys_version_;
  // Local pointers: the loop's stores of bools could alias the vectors' own pointers, so
  // through the members the compiler reloaded them for every access.
  const Vec3* const pos = bodies_.pos.data();
  const Vec3* const vel = bodies_.vel.data();
  const Vec3* const angvel = bodies_.angvel.data();
  const Real* const radius = bodies_.radius.data();
  const int* const ioff = pair_ioff_.data();
  // (a candidate's record slot, or ~j: cand_j_)
  const int* const cand = cand_j_.data();
  const std::uint8_t* const images = candidate_images_.empty() ? nullptr : candidate_images_.data();
  const int* const jslot = pair_jslot_.data();
  PairContact* const pairs = pairs_.data();
  Real* const dissip = pair_dissip_.data();
  PairOutput* const out_j = pair_out_.data();
  Real* const out_fi = pair_fi_.data()->data();
  Real* const out_ti = pair_ti_.data()->data();
  Vec3* const fsum = bodies_.force.data();
  Vec3* const tsum = bodies_.torque.data();
  const int* const cross_k = pair_cross_k_.data();
  PairCross* const cross = pair_cross_.data();
  const long thread = thread_and_team().first;
  PairContact fresh;  // (a candidate touching without a record: its new record)
  Real fresh_dissip = 0;
  // (kPassDirect: j's force and torque added to its sums (fsum, tsum) at once, i's at the
  // end of its contacts, in the order the reduction adds pair_out_'s; kPassCross: the
  // cross pairs' shares; compute_pair_forces_hot)
  const bool direct = mode == kPassDirect;
  const bool shares = mode == kPassCross;
  // Periodic cell: j is seen at its image, and the mean field's velocity L d and spin are
  // added to the stored fluctuations (bodies/cell.hpp).
  const bool periodic = cell_.on;
  const Mat3 lgrad = cell_.vel_grad;
  const Vec3 spin = cell_.spin();
  for (int r = r0; r < r1; ++r) {
    // (rows: bodies, or in kPassCross single cross pairs)
    const int k0 = shares ? cross_k[r] : ioff[r], k1 = shares ? k0 + 1 : ioff[r + 1];
    const int i = shares ? cross[r].i : r;
    // i's share: -force and torque_i summed over its contacts.
    V fi = ops.zero(), ti = ops.zero();
    bool gave = false;  // (kPassCross)
    if (k0 < k1) {
      const V xi = ops.load(pos[i]), vi = ops.load(vel[i]);
      const V wi = periodic ? V(ops.load(angvel[i]) + spin) : ops.load(angvel[i]);
      const Real ri = radius[i];
      for (int k = k0; k < k1; ++k) {
        // (k: the candidate; s: its record, or -1)
        PairOutput* const o = direct ? nullptr : shares ? &cross[r].out : &out_j[jslot[k]];
        // (its record, or < 0; with the cold part, kPassOutputs, every candidate's record is at
        // its index)
        const int s = direct || shares ? cand[k] : k;
        const int j = s >= 0 ? pairs[s].j : ~s;
        if (direct && j >= jlimit) {
          // a cross pair: its shares were computed first; i's is added in its place
          const PairCross& x = cross[cursor++];
          if (x.on) {
            fi += ops.load_head(x.fi.data());
            ti += ops.load_head(x.ti.data());
          }
          continue;
        }
        const std::uint8_t image = images ? images[k] : kNoShift;
        V d = ops.load(pos[j]) - xi;
        if (periodic) d += ops.load_padded(image_offset_[image].data());
        const Real dist2 = ops.dot(d, d);
        const Real rj = radius[j];
        const Real rsum = ri + rj;
        if (dist2 >= rsum * rsum) {
          if (s >= 0 && pairs[s].active) open_pair(s, o);  // the contact opened
          continue;
        }
        const Real dist = std::sqrt(dist2);
        const Real overlap = rsum - dist;
        if (!(overlap <= max_ratio * std::min(ri, rj))) {
          err = std::min(err, static_cast<long>(k));
          continue;
        }
        if (s < 0) {
          fresh = fresh_pair(j, image);
          fresh_dissip = 0;
        }
        PairContact& c = s >= 0 ? pairs[s] : fresh;
        Real& dis = s >= 0 ? dissip[s] : fresh_dissip;
        if (!c.active || stale) update_phys(c, s, i);
        c.active = true;
        gave = true;
        V wj = ops.load(angvel[j]), vj = ops.load(vel[j]);
        if (periodic) {
          wj += spin;
          vj += lgrad * d;
        }
        V n, rel_vel;
        Real li, lj;
        sphere_sphere_frame<Ops, kYadeShear>(d, dist, overlap, ri, rj, vi, vj, wi, wj, n, li, lj,
                                             rel_vel);
        if (c.kernel != kLinearKernel) {
          V dfi, dti;  // (i's shares)
          if (c.kernel == kHertzKernel) {
            alignas(32) Real hf[4], ht[4];  // (direct: j's share, added below)
            hertz_pair<false>(c, nullptr, dis, o ? o->force.data() : hf,
                              o ? o->torque_j.data() : ht, n, overlap, li, lj, rel_vel,
                              V(wi + wj), dt, dfi, dti, ops);
            fi += dfi;
            ti += dti;
            if (!o) {
              ops.store(fsum[j], V(ops.load(fsum[j]) + ops.load_padded(hf)));
              ops.store(tsum[j], V(ops.load(tsum[j]) + ops.load_padded(ht)));
            }
            if (s < 0) keep_new_pair(thread, k, c, dis);
          } else if (!pair_cold_on_ || !o) {
            continue;  // (a bug: pair_cold_missing_ stops the step)
          } else if (c.kernel == kHertzDampedKernel) {
            // (with the cold part every candidate has its record, at its index: s == k)
            hertz_pair<true>(c, &pair_cold_[s], dis, o->force.data(), o->torque_j.data(),
                             n, overlap, li, lj, rel_vel, V(wi + wj), dt, dfi, dti, ops);
            fi += dfi;
            ti += dti;
          } else {
            const auto on_i = general_pair(s, *o, ops.vec(n), overlap, li, lj, ops.vec(rel_vel),
                                           ops.vec(wi + wj), ops.vec(wj - wi));
            fi += ops.load(on_i.first);
            ti += ops.load(on_i.second);
          }
          continue;
        }
        // The short kernel on the hot record: (fs, overlap) and (normal, fn) in the record.
        V fs = ops.load_head(c.fs.data());
        const Real fn = linear_frictional<Ops>(fs, ops.load_head(c.normal.data()), n, overlap,
                                               rel_vel, V(wi + wj), c.kn, c.ks, c.tan_phi, dt,
                                               dis);
        ops.store_with(c.fs.data(), fs, overlap);  // fs, overlap
        ops.store_with(c.normal.data(), n, fn);    // normal, fn
        const V f = fn * n + fs;
        // Moments (000 eq 6): -l_j n x F on j, l_i n x (-F) on i; n x F = n x fs.
        const V nxf = ops.cross(n, fs);
        if (o) {
          ops.store_padded(o->force.data(), f);
          ops.store_padded(o->torque_j.data(), V(-lj * nxf));
        } else {
          ops.store(fsum[j], V(ops.load(fsum[j]) + f));
          ops.store(tsum[j], V(ops.load(tsum[j]) + V(-lj * nxf)));
        }
        fi -= f;
        ti -= li * nxf;
        if (s < 0) keep_new_pair(thread, k, c, dis);
      }
    }
    if (shares) {
      ops.store_padded(cross[r].fi.data(), fi);
      ops.store_padded(cross[r].ti.data(), ti);
      cross[r].on = gave;
    } else if (direct) {
      ops.store(fsum[i], V(ops.load(fsum[i]) + fi));
      ops.store(tsum[i], V(ops.load(tsum[i]) + ti));
    } else {
      ops.store_padded(out_fi + 4L * i, fi);
      ops.store_padded(out_ti + 4L * i, ti);
    }
  }
  err_out = err;
}

void Scene::compute_pair_forces(long& err_contact) {
  ensure_pair_cold();
  if (pair_new_.size() < static_cast<size_t>(max_threads())) pair_new_.resize(max_threads());
  if (shear_kinematics_ == ShearKinematics::Yade) compute_pair_forces_hot<true>(err_contact);
  else compute_pair_forces_hot<false>(err_contact);
  pair_phys_version_ = phys_version_;  // (every active contact's parameters are now of it)
  adopt_new_pairs();
  if (pair_cold_missing_)
    throw std::logic_error("cpp_dem: a pair contact's law needs the contacts' cold part, "
                           "which ensure_pair_cold did not make (a bug: please report it)");
}

void Scene::release_pair_outputs() {
  // (swapped with empty vectors: clear() would keep their memory)
  if (pair_out_.capacity() > 0) std::vector<PairOutput>().swap(pair_out_);
  if (pair_jadj_off_.capacity() > 0) std::vector<int>().swap(pair_jadj_off_);
  if (pair_jslot_.capacity() > 0) std::vector<int>().swap(pair_jslot_);
  if (pair_fi_.capacity() > 0) std::vector<std::array<Real, 4>>().swap(pair_fi_);
  if (pair_ti_.capacity() > 0) std::vector<std::array<Real, 4>>().swap(pair_ti_);
}

bool Scene::pair_pass_direct() const { return !pair_cold_on_; }

void Scene::index_pair_outputs(std::vector<int>& jadj_off, std::vector<int>& jslot) const {
  jadj_off.clear();
  jslot.clear();
  if (pair_ioff_.empty()) return;  // (no build yet)
  const int n = static_cast<int>(pair_ioff_.size()) - 1;  // (the last build's bodies)
  jadj_off.assign(n + 1, 0);
  const int nc = static_cast<int>(cand_j_.size());
  for (int k = 0; k < nc; ++k) jadj_off[cand_second(k) + 1]++;
  for (int b = 0; b < n; ++b) jadj_off[b + 1] += jadj_off[b];
  jslot.resize(nc);
  std::vector<int> fill(jadj_off.begin(), jadj_off.end() - 1);
  for (int k = 0; k < nc; ++k) jslot[k] = fill[cand_second(k)]++;
}

namespace {
constexpr std::size_t kNewPairsKept = 256;  // (a thread's list of new records kept between passes)
}  // namespace

void Scene::keep_new_pair(long t, int k, const PairContact& c, Real dissip) {
  pair_new_[t].push_back(NewPair{k, dissip, c});
}

void Scene::adopt_new_pairs() {
  size_t m = 0;
  for (const auto& v : pair_new_) m += v.size();
  if (m == 0) return;
  std::vector<NewPair> all;
  all.reserve(m);
  for (auto& v : pair_new_) {
    all.insert(all.end(), v.begin(), v.end());
    // (a few a step are kept for the next; the many of a first touch, as a packing's first
    // step, are given back)
    if (v.capacity() > kNewPairsKept) std::vector<NewPair>().swap(v);
    else v.clear();
  }
  // (each thread's in its own order: the records go in candidate order, whatever the threads)
  std::sort(all.begin(), all.end(), [](const NewPair& a, const NewPair& b) { return a.k < b.k; });
  const size_t need = pairs_.size() + m;
  if (need > pairs_.capacity()) {
    // (room for a sixteenth more: contacts form a few at a time between builds)
    const size_t cap = need + need / 16 + 16;
    pairs_.reserve(cap);
    pair_dissip_.reserve(cap);
  }
  for (const NewPair& e : all) {
    cand_j_[e.k] = static_cast<int>(pairs_.size());
    pairs_.push_back(e.c);
    pair_dissip_.push_back(e.dissip);
  }
}

void Scene::materialize_pairs() {
  const size_t nc = cand_j_.size();
  bool identity = pairs_.size() == nc;
  for (size_t k = 0; k < nc && identity; ++k) identity = cand_j_[k] == static_cast<int>(k);
  if (identity) return;
  std::vector<PairContact> next(nc);
  std::vector<Real> next_dissip(nc, 0.0);
  const int nrows = static_cast<int>(pair_ioff_.size()) - 1;
  for (int i = 0; i < nrows; ++i) {
    for (int k = pair_ioff_[i]; k < pair_ioff_[i + 1]; ++k) {
      const int s = cand_slot(k);
      if (s >= 0) {
        next[k] = pairs_[s];
        next_dissip[k] = pair_dissip_[s];
      } else {
        next[k] = fresh_pair(cand_second(k), candidate_image(k));
      }
      cand_j_[k] = static_cast<int>(k);
    }
  }
  pairs_.swap(next);
  pair_dissip_.swap(next_dissip);
}

void Scene::compact_pairs(const std::vector<PairContactDisk>& disk) {
  // (disk and pair_dissip_ hold one record for each candidate, in candidate order)
  const size_t nc = disk.size();
  size_t kept = 0;
  for (size_t k = 0; k < nc; ++k) kept += pair_keeps_record(disk[k].active, pair_dissip_[k]);
  std::vector<PairContact> next;
  std::vector<Real> next_dissip;
  const size_t cap = pair_cold_on_ ? kept : kept + kept / 16 + 16;
  next.reserve(cap);
  next_dissip.reserve(cap);
  // The active records' phys were made at one version, the last pass's (the scene's own
  // unless the materials changed after that pass).
  pair_phys_version_ = phys_version_;
  for (size_t k = 0; k < nc; ++k) {
    const PairContactDisk& d = disk[k];
    if (d.active && d.phys_version != phys_version_) pair_phys_version_ = d.phys_version;
    if (!pair_keeps_record(d.active, pair_dissip_[k])) {
      cand_j_[k] = ~cand_j_[k];  // (no record: its second body's complement)
      continue;
    }
    cand_j_[k] = static_cast<int>(next.size());
    next.push_back(hot_pair(d));
    next_dissip.push_back(pair_dissip_[k]);
  }
  pairs_.swap(next);
  pair_dissip_.swap(next_dissip);
}

void Scene::expanded_pairs(std::vector<PairContactDisk>& out, std::vector<Real>& dissip) const {
  const size_t nc = cand_j_.size();
  out.assign(nc, PairContactDisk());
  dissip.assign(nc, 0.0);
  const int nrows = static_cast<int>(pair_ioff_.size()) - 1;
  for (int i = 0; i < nrows; ++i) {
    for (int k = pair_ioff_[i]; k < pair_ioff_[i + 1]; ++k) {
      const int s = cand_slot(k);
      if (s >= 0 && pair_keeps_record(pairs_[s].active, pair_dissip_[s])) {
        // (an active contact's phys are of the last pass's version; an inactive one's are
        // made again at its next touch)
        out[k] = disk_pair(pairs_[s], i, pairs_[s].active ? pair_phys_version_ : -1);
        dissip[k] = pair_dissip_[s];
      } else {
        // (a record that carries no history is saved as the fresh one it is equal to in all
        // but the parameters of its last touch, which its next touch makes again)
        out[k] = disk_pair(fresh_pair(cand_second(k), candidate_image(k)), i, -1);
      }
    }
  }
}

void Scene::ensure_pair_cold() {
  if (pair_cold_on_ || pair_cold_version_ == phys_version_) return;
  pair_cold_version_ = phys_version_;
  const int nm = static_cast<int>(materials_.size());
  bool need = false;
  for (int a = 0; a < nm && !need; ++a) {
    for (int b = a; b < nm && !need; ++b) {
      const Material& ma = materials_[a];
      const Material& mb = materials_[b];
      // (the kernel does not depend on the radii and masses, but for rolling resistance,
      // whose stiffness is > 0 where both its factors are and the shear stiffness is)
      const std::uint8_t kernel = pair_kernel(mix_materials(ma, mb, 1.0, 1.0, 1.0, 1.0,
                                                            pair_law(a, b)));
      const bool rolling = ma.rolling_stiffness + mb.rolling_stiffness > 0 &&
                           ma.rolling_friction + mb.rolling_friction > 0;
      need = rolling || (kernel != kLinearKernel && kernel != kHertzKernel);
    }
  }
  if (!need) return;
  pair_cold_on_ = true;
  materialize_pairs();   // (a record for every candidate, at its index)
  release_pair_cross();  // (a pass with the cold part keeps its outputs instead)
  // (every active contact's phys is made again, into its cold part, at its next step:
  // phys_version_ has changed since the last check, or no step has run)
  pair_cold_.assign(pairs_.size(), PairContactCold());
}

/// How many contacts ahead the pair pass prefetches the second body's state, in a scene of
/// at least kPrefetchMinBodies bodies (bench/ab_build.py, spheres, one thread: 0.98 x at
/// 1e4, 1.02 x at 3e4, 1.15 x at 1e5; two threads: 0.94 x at 1e4, 1.09 x at 3e4, 1.10 x at
/// 5e4, 1.12 x at 1e5; 8 ahead on one thread: 1.05 x more at 1e5, 0.97 x at 1e4).
constexpr int kPrefetchAhead = 4;
constexpr int kPrefetchMinBodies = 20000;

template <bool kYadeShear>
void Scene::compute_pair_forces_hot(long& err_contact) {
  // Body-major: body i and its candidate pairs (i, j), j > i, its row of cand_j_ (sorted by
  // (i, j); each candidate's record in pairs_, or none: Scene::cand_j_). i's position, velocities and radius are loaded once; i's share of the forces
  // and torques is summed in registers, in contact order, into pair_fi_/pair_ti_; j's share
  // goes to its slot in pair_out_, which holds the contacts grouped by j (in contact order
  // within a body), so reduce_and_integrate reads them contiguously. Both orders are fixed,
  // so the sums do not depend on the number of threads. 3-vectors in 4-lane registers
  // (WideOps) where the CPU has AVX2; otherwise the same loop with Eigen's Vector3d.
  const int n = num_bodies();
  // With the short kernels alone (no cold part: every contact's force is f_n n + f_s, kept
  // in its hot record) the pass adds each contact's force and torque to its bodies' sums in
  // the bodies' own force and torque (pair_direct_), which the reduction then completes:
  // pair_out_, pair_fi_ and pair_ti_ are not kept (64 B a contact and 64 B a body less to
  // write and read back). On more threads each sums its own bodies, and the contacts whose
  // second body another thread sums (cross pairs) have their shares computed first
  // (pair_cross_): the same sums in the same order.
  const long ncontacts = static_cast<long>(cand_j_.size());  // (the candidates)
  pair_direct_ = pair_pass_direct();
  if (pair_direct_) {
    release_pair_outputs();
  } else {
    pair_fi_.resize(n);
    pair_ti_.resize(n);
    // (after direct passes)
    if (pair_out_.size() != cand_j_.size()) pair_out_.assign(cand_j_.size(), PairOutput());
    if (pair_jslot_.size() != cand_j_.size() || pair_jadj_off_.size() != pair_ioff_.size())
      index_pair_outputs(pair_jadj_off_, pair_jslot_);
  }
  if (!use_wide_ops()) {
    compute_pair_forces_narrow(err_contact);
    return;
  }
  const long nc = ncontacts;
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  const bool stale = pair_phys_version_ != phys_version_;  // (as in pair_bodies_narrow)
  long err = std::numeric_limits<long>::max();
  // The loop works through local pointers: its stores of bools could alias the vectors'
  // own pointers, so through the members the compiler reloads them for every access.
  const Vec3* const pos = bodies_.pos.data();
  const Vec3* const vel = bodies_.vel.data();
  const Vec3* const angvel = bodies_.angvel.data();
  const Real* const radius = bodies_.radius.data();
  const int* const ioff = pair_ioff_.data();
  // (a candidate's record slot, or ~j: cand_j_)
  const int* const cand = cand_j_.data();
  const std::uint8_t* const images =
      candidate_images_.empty() ? nullptr : candidate_images_.data();
  const int* const jslot = pair_jslot_.data();
  PairContact* const pairs = pairs_.data();
  Real* const dissip = pair_dissip_.data();
  PairOutput* const out_j = pair_out_.data();
  Real* const out_fi = pair_fi_.data()->data();
  Real* const out_ti = pair_ti_.data()->data();
  Vec3* const fsum = bodies_.force.data();  // (direct)
  Vec3* const tsum = bodies_.torque.data();
  // Periodic cell: j is seen at its image, and the mean field's velocity L d and spin are
  // added to the stored fluctuations (bodies/cell.hpp). The loop is instantiated twice, so
  // the cell costs the wall-bounded scene nothing.
  const V4 l0 = v4(cell_.vel_grad.col(0)), l1 = v4(cell_.vel_grad.col(1)),
           l2 = v4(cell_.vel_grad.col(2)), spin = v4(cell_.spin());
  const Real* const offsets = image_offset_.data()->data();
  const V4 field[4] = {l0, l1, l2, spin};
  // (the batch's kernel for this CPU, without and with the cell)
  const pair_batch::Kernel batch_kernel[2] = {pair_batch::kernel<kYadeShear, false>(),
                                              pair_batch::kernel<kYadeShear, true>()};
  // The batch (below) runs on a CPU with AVX-512 (pair_batch.cpp), in a direct pass of a
  // scene under kBatchMaxBodies. A pass that queued under a quarter of its candidates (few
  // active linear contacts: Hertz-Mindlin grains, a loose cloud) turns it off for the next
  // kBatchRest passes: the loop without it is the faster one there (its instantiation with the
  // batch ran a scene of few contacts 5 % slower).
  const bool batching = pair_direct_ && batch_kernel[0] != nullptr && n < kBatchMaxBodies &&
                        pair_batch_rest_ == 0;
  if (pair_batch_rest_ > 0) --pair_batch_rest_;
  long queued = 0;  // (the contacts the batch ran)
#pragma omp parallel reduction(min : err) reduction(+ : queued) if (nc > kParallelMin)
  {
    const auto [t, nt] = thread_and_team();
    const bool crossing = pair_direct_ && nt > 1;
    if (crossing) {
#pragma omp single
      {
        if (pair_cross_nt_ != nt) index_pair_cross(static_cast<int>(nt));
      }
    }
    const auto [b0, b1] = crossing ? std::pair<int, int>(pair_cross_b_[t], pair_cross_b_[t + 1])
                                   : pair_bodies_of_thread(t, nt);
    const int* const cross_k = pair_cross_k_.data();
    PairCross* const cross = pair_cross_.data();
    // (Captured by value: the pointers stay in registers; by reference they were taken as
    // addresses the loop's stores might alias, and reloaded, 14 % more instructions.)
    const int kend = ioff[b1];  // (the thread's last contact + 1)
    PairContact fresh;  // (a candidate touching without a record: its new record)
    Real fresh_dissip = 0;
    const long thread = t;
    const bool prefetch = n >= kPrefetchMinBodies;
    // Rows r0 .. r1: bodies, or in kPassCross cross slots (one contact each). kPassDirect:
    // the contacts with j >= jlimit are cross pairs, whose shares are pair_cross_[cursor..].
    // batch_tag: the instantiation with the batch (below).
    const auto loop = [=, &err, &queued, &fresh, &fresh_dissip](
                          auto periodic_tag, auto mode_tag, auto batch_tag, int r0, int r1,
                          int jlimit, long cursor) __attribute__((always_inline)) {
    constexpr bool kPeriodic = decltype(periodic_tag)::value;
    // (kDirect: j's share into its sums at once, i's at the end of its contacts; kShares:
    // a cross pair's shares into its PairCross)
    constexpr bool kDirect = decltype(mode_tag)::value == kPassDirect;
    constexpr bool kShares = decltype(mode_tag)::value == kPassCross;
    // The direct pass runs its active linear contacts eight at a time (pair_batch.hpp): the
    // rows of a block queue them, the batch runs them, and every share is then added in the
    // order of the rows and their contacts (flush), so the sums are the per-contact loop's.
    // The bodies' sums are not read in the pass, so deferring them changes only their time.
    constexpr bool kBatch = decltype(batch_tag)::value && kDirect;
    struct Entry {
      V4 dfi, dti, fj, tj;  // the shares of a contact outside the batch: i's, and j's
      int q;                // or its place in the queue
      int j;                // (j: with j's share; -1: i's alone, a cross pair's; queued: k)
    };
    constexpr int kCap = kBatch ? kBatchRow : 1;
    [[maybe_unused]] pair_batch::Queue<kCap> queue;
    [[maybe_unused]] Entry entry[kCap];
    [[maybe_unused]] int row_end[kCap], row_body[kCap];
    [[maybe_unused]] int nq = 0, ne = 0, nr = 0;
    [[maybe_unused]] int last_linear = 0;  // (the last row's active linear contacts)
    [[maybe_unused]] const auto flush = [&]() __attribute__((always_inline)) {
      // The queued contacts, kLanes at a time (the last lanes repeat the last contact), then
      // the block's rows in order: each contact's shares (j's into its sums, i's into fi
      // and ti), then i's sums.
      queued += nq;
      bool any_bad = false;
      if constexpr (kBatch) {
        if (nq > 0) {
          queue.pad(nq);
          any_bad = batch_kernel[kPeriodic](queue, nq, pairs, dissip, vel, angvel, dt,
                                            max_ratio, field);
        }
      }
      int e = 0;
      for (int m = 0; m < nr; ++m) {
        V4 fi = V4{}, ti = V4{};
        for (; e < row_end[m]; ++e) {
          const Entry& x = entry[e];
          if (x.q >= 0) {
            const int a = x.q;
            if (__builtin_expect(any_bad, 0) && queue.bad[a]) {
              // overlapping beyond the limit (the loop's check, run in the batch)
              err = std::min(err, static_cast<long>(x.j));
              continue;
            }
            // (component by component: the same sums as the 4-lane ones; x - y is x + (-y))
            const int jq = queue.j[a];
            fsum[jq][0] += queue.fx[a];
            fsum[jq][1] += queue.fy[a];
            fsum[jq][2] += queue.fz[a];
            tsum[jq][0] += queue.tx[a];
            tsum[jq][1] += queue.ty[a];
            tsum[jq][2] += queue.tz[a];
            fi -= V4{queue.fx[a], queue.fy[a], queue.fz[a], 0.0};
            ti -= V4{queue.lx[a], queue.ly[a], queue.lz[a], 0.0};
          } else {
            if (x.j >= 0) {
              store3(fsum[x.j], v4(fsum[x.j]) + x.fj);
              store3(tsum[x.j], v4(tsum[x.j]) + x.tj);
            }
            fi += x.dfi;
            ti += x.dti;
          }
        }
        const int i = row_body[m];
        store3(fsum[i], v4(fsum[i]) + fi);
        store3(tsum[i], v4(tsum[i]) + ti);
      }
      nq = ne = nr = 0;
    };
    for (int r = r0; r < r1; ++r) {
      const int k0 = kShares ? cross_k[r] : ioff[r], k1 = kShares ? k0 + 1 : ioff[r + 1];
      const int i = kShares ? cross[r].i : r;
      // i's share: -force and torque_i summed over its contacts.
      V4 fi = V4{}, ti = V4{};
      [[maybe_unused]] bool gave = false;  // (kShares)
      // (kBatch: a row of at most kCap candidates joins the block, its active linear
      // contacts queued and the others' shares kept in entry, in contact order; a longer row
      // runs alone, after the block. A block starts at a row after one with such contacts, so
      // a scene without them (Hertz-Mindlin grains) pays nothing for it.)
      [[maybe_unused]] const bool batch =
          kBatch && k1 - k0 <= kCap && (nr > 0 || last_linear > 0);
      if constexpr (kBatch) {
        last_linear = 0;
        if (nr > 0 && (!batch || ne + (k1 - k0) > kCap || nr == kCap)) flush();
      }
      // i's shares of a contact, and j's share with it (give_ij)
      const auto give_i = [&](const V4& dfi, const V4& dti) __attribute__((always_inline)) {
        if (kBatch && batch) {
          entry[ne].dfi = dfi;
          entry[ne].dti = dti;
          entry[ne].q = -1;
          entry[ne].j = -1;
          ++ne;
        } else {
          fi += dfi;
          ti += dti;
        }
      };
      // (kSub: i's shares are f and t subtracted, the linear kernel's form; in an entry they
      // are kept negated, as x - y is x + (-y) to the bit)
      [[maybe_unused]] const auto give_ij = [&](auto sub_tag, int j, const V4& fj, const V4& tj,
                                                const V4& f, const V4& t)
          __attribute__((always_inline)) {
        constexpr bool kSub = decltype(sub_tag)::value;
        if (kBatch && batch) {
          entry[ne].dfi = kSub ? -f : f;
          entry[ne].dti = kSub ? -t : t;
          entry[ne].fj = fj;
          entry[ne].tj = tj;
          entry[ne].q = -1;
          entry[ne].j = j;
          ++ne;
        } else {
          store3(fsum[j], v4(fsum[j]) + fj);
          store3(tsum[j], v4(tsum[j]) + tj);
          if constexpr (kSub) {
            fi -= f;
            ti -= t;
          } else {
            fi += f;
            ti += t;
          }
        }
      };
      if (k0 < k1) {
        const V4 xi = v4(pos[i]), vi = v4(vel[i]);
        V4 wi = v4(angvel[i]);
        if constexpr (kPeriodic) wi += spin;
        const Real ri = radius[i];
        // Candidate k's record, or < 0 (cand_j_); with the cold part, kPassOutputs, every
        // candidate's record is at its index.
        const auto record_of = [cand](int k) { return kDirect || kShares ? cand[k] : k; };
        for (int k = k0; k < k1; ++k) {
          // (k: the candidate; s: its record, or -1)
          PairOutput* const o = kDirect ? nullptr : kShares ? &cross[r].out : &out_j[jslot[k]];
          const int s = record_of(k);
          const int j = s >= 0 ? pairs[s].j : ~s;
          if constexpr (kDirect) {
            if (j >= jlimit) {
              // a cross pair: its shares were computed first; i's is added in its place
              const PairCross& x = cross[cursor++];
              if (x.on) give_i(load4(x.fi.data()), load4(x.ti.data()));
              continue;
            }
          }
          if (!kShares && prefetch && k + kPrefetchAhead < kend) {
            // (a scene larger than the caches: the state of a contact's second body some
            // contacts ahead, toward the cache, its reads being the scattered ones of the
            // pass; at 1e4 bodies it slowed the pass, 0.98 x on one thread, 0.94 x on two)
            const int sn = record_of(k + kPrefetchAhead);
            const int jn = sn >= 0 ? pairs[sn].j : ~sn;
            __builtin_prefetch(&pos[jn]);
            __builtin_prefetch(&vel[jn]);
            __builtin_prefetch(&angvel[jn]);
            if constexpr (kDirect) {
              __builtin_prefetch(&fsum[jn], 1);
              __builtin_prefetch(&tsum[jn], 1);
            }
          }
          [[maybe_unused]] std::uint8_t image = kNoShift;
          V4 d = v4(pos[j]) - xi;
          if constexpr (kPeriodic) {
            if (images) image = images[k];
            d += load4(offsets + 4 * image);
          }
          const Real dist2 = dot3(d, d);
          const Real rj = radius[j];
          const Real rsum = ri + rj;
          if (dist2 >= rsum * rsum) {
            if (s >= 0 && pairs[s].active) open_pair(s, o);  // the contact opened
            continue;
          }
          if constexpr (kBatch) {
            // an active contact of the linear kernel: queued for the batch (pair_batch.hpp),
            // which takes the square root, the overlap and its check below, eight at a time
            // (dist2 > 0: dist > 0)
            if (batch && s >= 0 && dist2 > 0 && pairs[s].active && !stale &&
                pairs[s].kernel == kLinearKernel) {
              queue.put(nq, d, dist2, ri, rj, s, i, j);
              entry[ne].q = nq++;
              entry[ne].j = k;
              ++ne;
              ++last_linear;
              continue;
            }
          }
          const Real dist = std::sqrt(dist2);
          const Real overlap = rsum - dist;
          if (!(overlap <= max_ratio * std::min(ri, rj))) {
            err = std::min(err, static_cast<long>(k));
            continue;
          }
          if (__builtin_expect(s < 0, 0)) {
            fresh = fresh_pair(j, image);
            fresh_dissip = 0;
          }
          PairContact& c = s >= 0 ? pairs[s] : fresh;
          Real& dis = s >= 0 ? dissip[s] : fresh_dissip;
          if (!c.active || stale) update_phys(c, s, i);
          c.active = true;
          if constexpr (kShares) gave = true;
          V4 wj = v4(angvel[j]), vj = v4(vel[j]);
          if constexpr (kPeriodic) {
            wj += spin;
            vj += l0 * d[0] + l1 * d[1] + l2 * d[2];
          }
          V4 n, rel_vel;
          Real li, lj;
          sphere_sphere_frame<WideOps, kYadeShear>(d, dist, overlap, ri, rj, vi, vj, wi, wj, n,
                                                   li, lj, rel_vel);
          if (c.kernel != kLinearKernel) {
            if (c.kernel == kHertzKernel) {
              V4 dfi, dti;  // (i's shares)
              if constexpr (kDirect) {
                alignas(32) Real hf[4], ht[4];
                hertz_pair<false>(c, nullptr, dis, hf, ht, n, overlap, li, lj, rel_vel,
                                  V4(wi + wj), dt, dfi, dti, WideOps());
                give_ij(std::false_type{}, j, load4(hf), load4(ht), dfi, dti);
              } else {
                hertz_pair<false>(c, nullptr, dis, o->force.data(), o->torque_j.data(), n,
                                  overlap, li, lj, rel_vel, V4(wi + wj), dt, dfi, dti,
                                  WideOps());
                give_i(dfi, dti);
              }
              if (__builtin_expect(s < 0, 0)) keep_new_pair(thread, k, c, dis);
            } else if (kDirect || !pair_cold_on_) {
              continue;  // (a bug: pair_cold_missing_ stops the step)
            } else if (c.kernel == kHertzDampedKernel) {
              // (with the cold part every candidate has its record, at its index: s == k)
              V4 dfi, dti;
              hertz_pair<true>(c, &pair_cold_[s], dis, o->force.data(), o->torque_j.data(),
                               n, overlap, li, lj, rel_vel, V4(wi + wj), dt, dfi, dti,
                               WideOps());
              give_i(dfi, dti);
            } else {
              const auto on_i = general_pair(s, *o, vec3(n), overlap, li, lj, vec3(rel_vel),
                                             vec3(wi + wj), vec3(wj - wi));
              give_i(v4(on_i.first), v4(on_i.second));
            }
            continue;
          }
          // The short kernel on the hot record, with 3-vectors in 4-lane registers:
          // (fs, overlap) and (normal, fn) are loaded as one register each.
          V4 fs = zero_lane3(load4(c.fs.data()));
          const Real fn = linear_frictional<WideOps>(fs, zero_lane3(load4(c.normal.data())), n,
                                                     overlap, rel_vel, wi + wj, c.kn, c.ks,
                                                     c.tan_phi, dt, dis);
          store4(c.fs.data(), with_lane3(fs, overlap));  // fs, overlap
          store4(c.normal.data(), with_lane3(n, fn));    // normal, fn
          const V4 f = fn * n + fs;
          // Moments (000 eq 6): -l_j n x F on j, l_i n x (-F) on i; n x F = n x fs.
          const V4 nxf = cross3(n, fs);
          if constexpr (kDirect) {
            give_ij(std::true_type{}, j, f, -lj * nxf, f, li * nxf);
          } else {
            store4(o->force.data(), f);  // with its padding (lane 3, zero)
            store4(o->torque_j.data(), -lj * nxf);
            fi -= f;
            ti -= li * nxf;
          }
          if constexpr (kBatch) last_linear += s >= 0;
          if (__builtin_expect(s < 0, 0)) keep_new_pair(thread, k, c, dis);
        }
      }
      if constexpr (kBatch) {
        if (batch) {
          row_end[nr] = ne;
          row_body[nr++] = i;
          continue;
        }
      }
      // (lane 3 is zero: every term had a zero lane 3)
      if constexpr (kShares) {
        store4(cross[r].fi.data(), fi);
        store4(cross[r].ti.data(), ti);
        cross[r].on = gave;
      } else if constexpr (kDirect) {
        store3(fsum[i], v4(fsum[i]) + fi);
        store3(tsum[i], v4(tsum[i]) + ti);
      } else {
        store4(out_fi + 4L * i, fi);
        store4(out_ti + 4L * i, ti);
      }
    }
    if constexpr (kBatch) {
      if (nr > 0) flush();
    }
    };
    // (inlined: a lambda called apart from the pass would be compiled for the baseline CPU,
    // outside the pass's multiversioned clones)
    const auto run = [&](auto mode_tag, int r0, int r1, int jlimit, long cursor)
        __attribute__((always_inline)) {
      constexpr bool kDirect = decltype(mode_tag)::value == kPassDirect;
      const auto with = [&](auto periodic_tag) __attribute__((always_inline)) {
        if (kDirect && batching)
          loop(periodic_tag, mode_tag, std::bool_constant<kDirect>{}, r0, r1, jlimit, cursor);
        else
          loop(periodic_tag, mode_tag, std::false_type{}, r0, r1, jlimit, cursor);
      };
      if (cell_.on) with(std::true_type{});
      else with(std::false_type{});
    };
    if (!pair_direct_) {
      run(std::integral_constant<int, kPassOutputs>{}, b0, b1, 0, 0);
    } else if (!crossing) {
      start_pair_sums(b0, b1);
      run(std::integral_constant<int, kPassDirect>{}, b0, b1, std::numeric_limits<int>::max(), 0);
    } else {
      // The cross pairs' shares, each thread an equal part of them; then this thread's
      // bodies' sums, started, given their cross shares (in contact order), and its rows.
      const auto [s0, s1] = thread_share(static_cast<long>(pair_cross_k_.size()), t, nt);
      run(std::integral_constant<int, kPassCross>{}, static_cast<int>(s0), static_cast<int>(s1),
          0, 0);
#pragma omp barrier
      start_pair_sums(b0, b1);
      add_cross_shares(t);
      run(std::integral_constant<int, kPassDirect>{}, b0, b1, b1, pair_cross_t_[t]);
    }
  }
  if (batching && 4 * queued < nc) pair_batch_rest_ = kBatchRest;
  pair_batched_ = queued;
  err_contact = err;
}

void Scene::compute_pair_forces_narrow(long& err_contact) {
  // (compute_pair_forces has sized pair_fi_ and pair_ti_; the same steps as the wide form's)
  long err = std::numeric_limits<long>::max();
#pragma omp parallel reduction(min : err) if (static_cast<long>(cand_j_.size()) > kParallelMin)
  {
    const auto [t, nt] = thread_and_team();
    const auto run = [&](int r0, int r1, int mode, int jlimit, long cursor) {
      if (shear_kinematics_ == ShearKinematics::Yade)
        pair_bodies_narrow<true>(r0, r1, err, mode, jlimit, cursor);
      else
        pair_bodies_narrow<false>(r0, r1, err, mode, jlimit, cursor);
    };
    if (!pair_direct_ || nt == 1) {
      const auto [b0, b1] = pair_bodies_of_thread(t, nt);
      if (pair_direct_) start_pair_sums(b0, b1);
      run(b0, b1, pair_direct_ ? kPassDirect : kPassOutputs, std::numeric_limits<int>::max(), 0);
    } else {
#pragma omp single
      {
        if (pair_cross_nt_ != nt) index_pair_cross(static_cast<int>(nt));
      }
      const int b0 = pair_cross_b_[t], b1 = pair_cross_b_[t + 1];
      const auto [s0, s1] = thread_share(static_cast<long>(pair_cross_k_.size()), t, nt);
      run(static_cast<int>(s0), static_cast<int>(s1), kPassCross, 0, 0);
#pragma omp barrier
      start_pair_sums(b0, b1);
      add_cross_shares(t);
      run(b0, b1, kPassDirect, b1, pair_cross_t_[t]);
    }
  }
  err_contact = err;
}

void Scene::start_pair_sums(int b0, int b1) {
  // The sums start where the reduction starts: the external force and the weight.
  const Vec3 g = gravity_;
  for (int b = b0; b < b1; ++b) {
    const Vec3& fe = bodies_.ext_force_of(b);
    const Vec3& te = bodies_.ext_torque_of(b);
    const Real m = bodies_.mass[b];
    for (int a = 0; a < 3; ++a) {
      bodies_.force[b][a] = fe[a] + m * g[a];
      bodies_.torque[b][a] = te[a];
    }
  }
}

void Scene::add_cross_shares(long t) {
  // (in contact order: the slots of a body, pair_cross_j_, are; few, so not in the pass's
  // vector forms, whose sums these are to the bit)
  for (int e = pair_cross_jt_[t]; e < pair_cross_jt_[t + 1]; ++e) {
    const PairCross& x = pair_cross_[pair_cross_j_[e]];
    if (!x.on) continue;
    bodies_.force[x.j] += x.out.force;
    bodies_.torque[x.j] += x.out.torque_j;
  }
}

void Scene::index_pair_cross(int nt) {
  // The threads' bodies: each thread computes an equal part of the cross pairs apart, so the
  // rows are split by their other contacts, those the thread computes in its rows (counted
  // at the split by equal contacts, pair_bodies_of_thread: the cross pairs change little
  // when the borders move).
  const int n = static_cast<int>(pair_ioff_.size()) - 1;
  const auto tail = [&](int i, int jlimit) {  // (a row is sorted by j: its cross pairs are its tail)
    int k = pair_ioff_[i + 1];
    while (k > pair_ioff_[i] && cand_second(k - 1) >= jlimit) --k;
    return k;
  };
  std::vector<long> own(n + 1, 0);  // (cumulative: the rows' contacts that are not cross)
  for (int t = 0; t < nt; ++t) {
    const auto [b0, b1] = pair_bodies_of_thread(t, nt);
    for (int i = b0; i < b1; ++i) own[i + 1] = tail(i, b1) - pair_ioff_[i];
  }
  for (int i = 0; i < n; ++i) own[i + 1] += own[i];
  pair_cross_b_.assign(nt + 1, n);
  for (int t = 0; t < nt; ++t)
    pair_cross_b_[t] = static_cast<int>(
        std::lower_bound(own.begin(), own.end(), t * own[n] / nt) - own.begin());
  pair_cross_k_.clear();
  pair_cross_t_.assign(nt + 1, 0);
  for (int t = 0; t < nt; ++t) {
    const int b0 = pair_cross_b_[t], b1 = pair_cross_b_[t + 1];
    for (int i = b0; i < b1; ++i) {
      for (int k = tail(i, b1); k < pair_ioff_[i + 1]; ++k) pair_cross_k_.push_back(k);
    }
    pair_cross_t_[t + 1] = static_cast<int>(pair_cross_k_.size());
  }
  const int ns = static_cast<int>(pair_cross_k_.size());
  pair_cross_.assign(ns, PairCross());
  pair_cross_j_.resize(ns);
  for (int s = 0; s < ns; ++s) {
    pair_cross_[s].i = pair_first_body(pair_cross_k_[s]);
    pair_cross_[s].j = cand_second(pair_cross_k_[s]);
    pair_cross_j_[s] = s;
  }
  // (stable: within a body j its slots stay in contact order)
  std::stable_sort(pair_cross_j_.begin(), pair_cross_j_.end(),
                   [&](int a, int b) { return pair_cross_[a].j < pair_cross_[b].j; });
  pair_cross_jt_.assign(nt + 1, ns);
  for (int t = 0; t < nt; ++t) {
    pair_cross_jt_[t] = static_cast<int>(
        std::lower_bound(pair_cross_j_.begin(), pair_cross_j_.end(), pair_cross_b_[t],
                         [&](int s, int b) { return pair_cross_[s].j < b; }) -
        pair_cross_j_.begin());
  }
  pair_cross_nt_ = nt;
}

void Scene::release_pair_cross() {
  pair_cross_nt_ = 0;
  if (pair_cross_.capacity() > 0) std::vector<PairCross>().swap(pair_cross_);
  for (auto* v : {&pair_cross_k_, &pair_cross_t_, &pair_cross_j_, &pair_cross_jt_, &pair_cross_b_})
    if (v->capacity() > 0) std::vector<int>().swap(*v);
}

}  // namespace cpp_dem
