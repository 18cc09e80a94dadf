// The broad phase of the step: when to rebuild, the spatial storage order, and the merge of
// the new candidate lists with the contacts that carry history.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr Real kInf = std::numeric_limits<Real>::infinity();
constexpr int kFreshRecord = -2;  // (rebuild: a candidate that takes a fresh record)
}  // namespace

Real Scene::default_margin() const {
  if (default_margin_ >= 0) return default_margin_;
  if (bodies_.radius.empty()) return 0;
  Real s = 0;
  for (Real r : bodies_.radius) s += r;
  default_margin_ = 0.2 * s / bodies_.radius.size();
  return default_margin_;
}

// ---- broad phase ----------------------------------------------------------------------------

std::vector<std::pair<int, int>> Scene::candidate_pairs() const {
  std::vector<std::pair<int, int>> out;
  out.reserve(cand_j_.size());
  for (int i = 0; i + 1 < static_cast<int>(pair_ioff_.size()); ++i)
    for (int q = pair_ioff_[i]; q < pair_ioff_[i + 1]; ++q) out.emplace_back(i, cand_second(q));
  return out;
}

void Scene::set_candidate_rows(const std::vector<std::pair<int, int>>& pairs, int n) {
  cand_off_.assign(n + 1, 0);
  cand_j_.resize(pairs.size());
  for (size_t q = 0; q < pairs.size(); ++q) {
    cand_off_[pairs[q].first + 1]++;
    cand_j_[q] = pairs[q].second;  // (sorted by (i, j): rows in order)
  }
  for (int b = 0; b < n; ++b) cand_off_[b + 1] += cand_off_[b];
}

bool Scene::need_rebuild() const {
  if (dirty_) return true;
  const Real half = 0.5 * (margin_ > 0 ? margin_ : default_margin());
  for (const Wall& w : walls_)
    if (w.moved_since_build > half) return true;
  for (const CylinderWall& w : cylinder_walls_)
    if (w.moved_since_build > half) return true;
  for (const MeshWall& w : mesh_walls_)
    if (w.moved_since_build > half) return true;
  // A deforming periodic cell changes every branch vector l by (F_b - I) l, F_b = H H_build^-1:
  // at most |F_b - I| (2 r_max + margin) for a pair that was out of reach at the build.
  Real cell_part = 0;
  Mat3 fb = Mat3::Identity();
  if (cell_.on && cell_.h != cell_.h_at_build) {
    fb = cell_.h * cell_.h_at_build.inverse();
    cell_part = 0.5 * (fb - Mat3::Identity()).norm() * (2 * max_radius_at_build_ + 2 * half);
  }
  // The last integration pass measured the displacements already (nothing moved since).
  if (disp_valid_) return max_disp_ + cell_part > half;
  const int n = num_bodies();
  Real worst = 0;
  if (cell_part > 0) {
#pragma omp parallel for reduction(max : worst) schedule(static) if (n > kParallelMin)
    for (int b = 0; b < n; ++b) {
      worst = std::max(worst, displacement_since_build(b, fb));
    }
    return worst + cell_part > half;
  }
#pragma omp parallel for reduction(max : worst) schedule(static) if (n > kParallelMin)
  for (int b = 0; b < n; ++b) {
    worst = std::max(worst, displacement_since_build(b));
  }
  return worst > half;
}

namespace {
/// The lowest 21 bits of v spread to every third bit (Morton code of one axis).
std::uint64_t spread_bits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}
}  // namespace

void Scene::sort_bodies_spatially() {
  const int n = num_bodies();
  std::vector<int> slots;  // sphere slots, ascending; grid nodes keep theirs
  Vec3 lo = Vec3::Constant(kInf), hi = Vec3::Constant(-kInf);
  Real rsum = 0;
  for (int b = 0; b < n; ++b) {
    if (bodies_.kind[b] != BODY_SPHERE) continue;
    if (!bodies_.pos[b].allFinite()) return;
    slots.push_back(b);
    lo = lo.cwiseMin(bodies_.pos[b]);
    hi = hi.cwiseMax(bodies_.pos[b]);
    rsum += bodies_.radius[b];
  }
  if (slots.size() < 2) return;
  // Cells one mean diameter wide (at most 2^21 per axis), in Morton (Z) order: a body's
  // neighbours are mostly within a few hundred slots of it.
  const Real cell = std::max(2.0 * rsum / static_cast<Real>(slots.size()),
                             (hi - lo).maxCoeff() / 2097151.0);
  if (!(cell > 0)) return;
  std::vector<std::pair<std::uint64_t, int>> key(slots.size());
  for (size_t k = 0; k < slots.size(); ++k) {
    const Vec3 c = (bodies_.pos[slots[k]] - lo) / cell;
    std::uint64_t code = 0;
    for (int a = 0; a < 3; ++a) {
      const auto q = static_cast<std::uint64_t>(std::clamp(c[a], 0.0, 2097151.0));
      code |= spread_bits(q) << a;
    }
    key[k] = {code, slots[k]};
  }
  std::sort(key.begin(), key.end());  // ties by slot: the order is deterministic
  // perm[new slot] = old slot.
  std::vector<int> perm(n);
  for (int b = 0; b < n; ++b) perm[b] = b;
  bool identity = true;
  for (size_t k = 0; k < slots.size(); ++k) {
    perm[slots[k]] = key[k].second;
    identity = identity && key[k].second == slots[k];
  }
  if (identity) return;
  bodies_.permute(perm);
  clumps_.remap_members(perm);
  remap_bonds(perm);
  // pos_at_build_ and radius_at_build_ are set at the end of the rebuild that called this,
  // pair_fi_ / pair_ti_ by the next pair pass.
  std::vector<int> ids(n);
  for (int b = 0; b < n; ++b) ids[b] = id_of(perm[b]);
  id_of_slot_.swap(ids);
  slot_of_id_.assign(n, 0);
  for (int b = 0; b < n; ++b) slot_of_id_[id_of_slot_[b]] = b;
  disp_valid_ = false;
}

void Scene::rebuild() {
  default_margin_ = -1;  // (bodies added, or put in space order: summed again)
  // Bodies added since the last build grew the per-body arrays one body at a time (up to
  // twice their size): give the slack back (a no-op where an array is already tight).
  if (dirty_) {
    bodies_.for_each_array([](auto& v) { v.shrink_to_fit(); });
    clumps_.for_each_array([](auto& v) { v.shrink_to_fit(); });
    id_of_slot_.shrink_to_fit();
    slot_of_id_.shrink_to_fit();
  }
  // Spatial order while no contact (and so no contact history) exists yet.
  if (spatial_sort_ && cand_j_.empty() && wall_contacts_.empty() && grid_contacts_.empty() &&
      cylinder_contacts_.empty() && mesh_contacts_.empty())
    sort_bodies_spatially();
  const Real margin = margin_ > 0 ? margin_ : default_margin();
  const int n = num_bodies();
  // The old records in candidate order, (i, j) order, with their first bodies (a record's
  // is its candidate's row, which the new build's candidates replace).
  struct OldRecord {
    int i, j, k;
  };
  std::vector<OldRecord> old;
  old.reserve(pairs_.size());
  for (int i = 0; i + 1 < static_cast<int>(pair_ioff_.size()); ++i)
    for (int q = pair_ioff_[i]; q < pair_ioff_[i + 1]; ++q)
      if (cand_slot(q) >= 0) old.push_back({i, pairs_[cand_slot(q)].j, cand_slot(q)});
  if (cell_.on) {
    wrap_into_cell();
    std::vector<std::pair<int, int>> found;
    find_periodic_pairs(bodies_.pos, bodies_.radius, bodies_.kind, margin, cell_, found,
                        candidate_images_);
    set_candidate_rows(found, n);
  } else {
    grid_.build(bodies_.pos, bodies_.radius, bodies_.kind, margin);
    grid_.find_pairs(bodies_.pos, bodies_.radius, margin, cand_off_, cand_j_);
    if (candidate_images_.capacity() > 0) std::vector<std::uint8_t>().swap(candidate_images_);
  }
  if (has_clumps()) {
    // Two members of one clump never touch.
    const auto& cl = bodies_.clump;
    drop_candidates([&cl](int i, int j) { return cl[i] >= 0 && cl[i] == cl[j]; });
    std::vector<std::uint8_t>().swap(candidate_images_);  // (clumps: never periodic)
  }
  drop_bonded_candidates();  // a bonded pair is its bond's contact
  // Merge the new candidate list with the old contacts' records, keeping those that carry
  // history (both in (i, j) order). A candidate without history has no record (cand_j_ < 0)
  // unless the scene has the cold part, which keeps one for every candidate, or it
  // touches now: it takes its fresh record here, in candidate order, and not at the next
  // pass (a packing's first build: every contact), the same record either way.
  const auto touching = [this](int i, int j, int q) {
    const Real rsum = bodies_.radius[i] + bodies_.radius[j];
    return (bodies_.pos[j] + pair_shift(q) - bodies_.pos[i]).squaredNorm() < rsum * rsum;
  };
  const size_t ncand = cand_j_.size();
  size_t e = 0;  // (the next old record)
  // (first the old record of each candidate, -1 for none; then the records, sized once)
  std::vector<int> slot(ncand, -1);
  size_t kept = 0;
  for (int i = 0; i < n; ++i) {
    for (int q = cand_off_[i]; q < cand_off_[i + 1]; ++q) {
      const std::pair<int, int> ij(i, cand_j_[q]);
      for (; e < old.size() && std::make_pair(old[e].i, old[e].j) < ij; ++e)
        drop_pair_dissipation(old[e].k);
      if (e < old.size() && old[e].i == i && old[e].j == ij.second) {
        const int k = old[e++].k;
        if (pair_keeps_record(pairs_[k].active, pair_dissip_[k])) {
          slot[q] = k;
          ++kept;
        }
        // (else a record without history: its dissipation, zero, needs no drop)
      }
      if (slot[q] < 0 && (pair_cold_on_ || touching(i, ij.second, q))) {
        slot[q] = kFreshRecord;
        ++kept;
      }
    }
  }
  for (; e < old.size(); ++e) drop_pair_dissipation(old[e].k);
  std::vector<PairContact> next;
  std::vector<PairContactCold> next_cold;  // (only where the scene has the cold part)
  std::vector<Real> next_dissip;
  // (room for a sixteenth more without the cold part: contacts form between builds)
  const size_t cap = pair_cold_on_ ? kept : kept + kept / 16 + 16;
  next.reserve(cap);
  if (pair_cold_on_) next_cold.reserve(kept);
  next_dissip.reserve(cap);
  for (int i = 0; i < n; ++i) {
    for (int q = cand_off_[i]; q < cand_off_[i + 1]; ++q) {
      const int k = slot[q];
      if (k >= 0) {
        next.push_back(pairs_[k]);
        next_dissip.push_back(pair_dissip_[k]);
        if (pair_cold_on_) next_cold.push_back(pair_cold_[k]);
      } else if (k == kFreshRecord) {
        next.push_back(fresh_pair(cand_j_[q], kNoShift));
        next_dissip.push_back(0.0);
        if (pair_cold_on_) next_cold.emplace_back();
      } else {
        cand_j_[q] = ~cand_j_[q];  // (no record: its second body's complement)
        continue;
      }
      // (The image may change for a kept contact: a body was wrapped into the cell.)
      next.back().image = candidate_image(q);
      cand_j_[q] = static_cast<int>(next.size()) - 1;
    }
  }
  pairs_.swap(next);
  pair_cold_.swap(next_cold);
  pair_dissip_.swap(next_dissip);
  // Sphere–wall candidates: signed distance to the plane below r + margin, and the centre
  // not beyond the plane by more than r (one-sided walls ignore what is behind them).
  const auto wall_candidate = [&](int b, int w) {
    if (bodies_.kind[b] != BODY_SPHERE && !grid_wall_contacts_) return false;  // grid nodes: only if asked for
    const Wall& wl = walls_[w];
    const Real s = wl.sense * (bodies_.pos[b][wl.axis] - wl.position);
    return s < bodies_.radius[b] + margin && s > -bodies_.radius[b];
  };
  WallContactMerge merge(wall_contacts_,
                         [this](const WallContact& c) { drop_dissipation(c.state); });
  {
    // (counted first: the list is made at its size, 240 B a contact, not grown by doubling)
    std::size_t count = 0;
    for (int b = 0; b < n; ++b)
      for (int w = 0; w < num_walls(); ++w) count += wall_candidate(b, w);
    merge.reserve(count);
  }
  for (int b = 0; b < n; ++b)
    for (int w = 0; w < num_walls(); ++w)
      if (wall_candidate(b, w)) merge.add(b, w);
  std::vector<WallContact> wnext = merge.finish();
  wall_contacts_.swap(wnext);
  // Adjacency (CSR) in contact order, so reductions into bodies have a fixed order.
  // (the candidates' rows)
  if (cand_off_.size() == static_cast<size_t>(n) + 1) {
    pair_ioff_.swap(cand_off_);
  } else {
    pair_ioff_.assign(n + 1, 0);
  }
  std::vector<int>().swap(cand_off_);  // (the build's scratch: pair_ioff_ holds the rows)
  // The pass's outputs and their slots, for the next pass's kind as it will choose it (unless
  // a material change gives the scene the cold part first: the pass then makes them itself).
  release_pair_cross();  // (made again by a threaded direct pass)
  if (pair_pass_direct()) {
    release_pair_outputs();
  } else {
    pair_out_.assign(cand_j_.size(), PairOutput());
    index_pair_outputs(pair_jadj_off_, pair_jslot_);
  }
  contacts_by_body(wall_contacts_, n, wall_adj_off_, wall_adj_);
  if constexpr (kGeogridBuilt) {
    if (has_grid()) rebuild_grid_contacts(margin);
  }
  if (!cylinder_walls_.empty()) rebuild_cylinder_contacts(margin);
  if (!mesh_walls_.empty()) rebuild_mesh_contacts(margin);
  grid_.release();  // (the cell grid is the build's scratch)
  pos_at_build_ = bodies_.pos;
  // (the radii at the build are kept only once one changes: set_radii)
  if (!radius_at_build_.empty()) std::vector<Real>().swap(radius_at_build_);
  cell_.h_at_build = cell_.h;
  max_radius_at_build_ = 0;
  for (Real r : bodies_.radius) max_radius_at_build_ = std::max(max_radius_at_build_, r);
  min_radius_ = -1;  // check_tunnelling takes it again
  for (Wall& w : walls_) w.moved_since_build = 0;
  dirty_ = false;
  ++builds_;
}

ColliderStats Scene::collider_stats() const {
  ColliderStats s;
  s.builds = builds_;
  s.pair_candidates = static_cast<long>(cand_j_.size());
  s.pair_records = static_cast<long>(pairs_.size());
  s.wall_candidates = static_cast<long>(wall_contacts_.size());
  s.grid_candidates = static_cast<long>(grid_contacts_.size());
  return s;
}

}  // namespace cpp_dem
