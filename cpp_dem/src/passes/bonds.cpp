// The bond pass: contact and parallel bonds between spheres (laws/bond.hpp), their breakage,
// and the bookkeeping that keeps bonded pairs out of the pair pass.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "cpp_dem/laws/bond.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr long kParallelMinBonds = 256;
std::pair<int, int> ordered(int a, int b) { return a < b ? std::pair(a, b) : std::pair(b, a); }
}

void BondParams::validate() const {
  require(std::isfinite(kn) && kn > 0, "kn", kn, "must be > 0 (N/m)");
  require(std::isfinite(ks) && ks >= 0, "ks", ks, "must be >= 0 (N/m)");
  require(std::isfinite(friction) && friction >= 0, "friction", friction,
          "must be >= 0 (Coulomb coefficient mu)");
  require(std::isfinite(cb_tensile) && cb_tensile >= 0, "cb_tensile", cb_tensile,
          "must be >= 0 (N; 0 = unbreakable)");
  require(std::isfinite(cb_shear) && cb_shear >= 0, "cb_shear", cb_shear,
          "must be >= 0 (N; 0 = unbreakable)");
  require(std::isfinite(pb_kn) && pb_kn >= 0, "pb_kn", pb_kn,
          "must be >= 0 (Pa/m; 0 = no parallel bond)");
  require(std::isfinite(pb_ks) && pb_ks >= 0, "pb_ks", pb_ks, "must be >= 0 (Pa/m)");
  require(std::isfinite(pb_radius_factor) && pb_radius_factor > 0 && pb_radius_factor <= 1,
          "pb_radius_factor", pb_radius_factor,
          "must be in (0, 1] (lambda_bar: R_bar = lambda_bar min(R_a, R_b); a cement disc "
          "wider than the smaller sphere is not a parallel bond)");
  require(std::isfinite(pb_tensile) && pb_tensile >= 0, "pb_tensile", pb_tensile,
          "must be >= 0 (Pa; 0 = unbreakable)");
  require(std::isfinite(pb_shear) && pb_shear >= 0, "pb_shear", pb_shear,
          "must be >= 0 (Pa; 0 = unbreakable)");
}

int Scene::add_bond(int a, int b, const BondParams& p) {
  check_body(a);
  check_body(b);
  if (a == b) throw ParameterError("bond: spheres a and b must differ (got " + std::to_string(a) + ")");
  p.validate();
  if (bond_topology_dirty_) rebuild_bond_adjacency();
  const int sa = slot_of(a), sb = slot_of(b);
  for (int s : {sa, sb}) {
    if (bodies_.kind[s] != BODY_SPHERE)
      throw ParameterError("bond " + std::to_string(a) + "-" + std::to_string(b) + ": body " +
                           std::to_string(id_of(s)) + " is not a sphere");
    if (bodies_.clump[s] >= 0)
      throw ParameterError("bond " + std::to_string(a) + "-" + std::to_string(b) + ": body " +
                           std::to_string(id_of(s)) + " is a member of clump " +
                           std::to_string(bodies_.clump[s]) +
                           " (clump members are rigid: bond the clump's neighbours instead)");
  }
  const std::pair<int, int> key = ordered(sa, sb);
  if (std::binary_search(bond_pairs_.begin(), bond_pairs_.end(), key))
    throw ParameterError("bond " + std::to_string(a) + "-" + std::to_string(b) +
                         ": the two spheres are bonded already");
  // In a periodic cell the bond joins a to the nearest image of b (across a face when the
  // two lie on either side of it): its shift, kept relative to the bodies' wrap counts.
  int shift[3] = {0, 0, 0};
  if (cell_.on) {
    const Vec3 f = cell_.h.inverse() * (bodies_.pos[sb] - bodies_.pos[sa]);
    for (int ax = 0; ax < 3; ++ax) {
      if (!cell_.periodic[ax]) continue;
      const long rel = -std::lround(f[ax]) -
                       (bodies_.image_of(sb)[ax] - bodies_.image_of(sa)[ax]);
      if (rel < std::numeric_limits<std::int16_t>::min() ||
          rel > std::numeric_limits<std::int16_t>::max())
        throw ParameterError("bond " + std::to_string(a) + "-" + std::to_string(b) +
                             ": the spheres' images are " + std::to_string(rel) +
                             " cells apart; at most 32767 (wrap counts this far apart "
                             "are not a neighbour pair)");
      shift[ax] = static_cast<int>(rel);
    }
  }
  Bond l;
  for (int ax = 0; ax < 3; ++ax) l.cell_shift[ax] = static_cast<std::int16_t>(shift[ax]);
  l.a = sa;
  l.b = sb;
  const Vec3 branch = bodies_.pos[sb] + bond_shift(l) - bodies_.pos[sa];
  const Real dist = branch.norm();
  if (!(dist > 0))
    throw ParameterError("bond " + std::to_string(a) + "-" + std::to_string(b) +
                         ": the spheres' centres coincide");
  {
    // A bond stands for cement between neighbours: the surface gap may be at most the
    // smaller radius (a bond across a wider gap spans where a third grain could sit).
    const Real ra = bodies_.radius[sa], rb = bodies_.radius[sb];
    const Real gap = dist - ra - rb, allowed = std::min(ra, rb);
    if (gap > allowed)
      throw ParameterError("bond " + std::to_string(a) + "-" + std::to_string(b) +
                           ": surface gap " + fmt_real(gap) + " m; must be <= " +
                           fmt_real(allowed) + " m (the smaller radius): bond neighbours "
                           "that touch or nearly touch");
  }
  bond_setup(p, bodies_.radius[sa], bodies_.radius[sb], dist, l);
  l.normal = branch / dist;
  bonds_.push_back(l);
  bond_pairs_.insert(std::upper_bound(bond_pairs_.begin(), bond_pairs_.end(), key), key);
  bond_topology_dirty_ = true;
  dirty_ = true;  // the pair pass must forget the pair
  return static_cast<int>(bonds_.size()) - 1;
}

void Scene::rebuild_bond_adjacency() {
  const int n = num_bodies();
  body_bond_off_.assign(n + 1, 0);
  for (const Bond& l : bonds_) {
    body_bond_off_[l.a + 1]++;
    body_bond_off_[l.b + 1]++;
  }
  for (int b = 0; b < n; ++b) body_bond_off_[b + 1] += body_bond_off_[b];
  body_bond_.resize(body_bond_off_[n]);
  std::vector<int> fill(body_bond_off_.begin(), body_bond_off_.end() - 1);
  for (int k = 0; k < num_bonds(); ++k) {
    body_bond_[fill[bonds_[k].a]++] = k;
    body_bond_[fill[bonds_[k].b]++] = k;
  }
  bond_pairs_.clear();
  for (const Bond& l : bonds_) bond_pairs_.push_back(ordered(l.a, l.b));
  std::sort(bond_pairs_.begin(), bond_pairs_.end());
  bond_topology_dirty_ = false;
}

void Scene::remap_bonds(const std::vector<int>& perm) {
  if (bonds_.empty()) return;
  std::vector<int> new_of_old(perm.size());
  for (size_t s = 0; s < perm.size(); ++s) new_of_old[perm[s]] = static_cast<int>(s);
  for (Bond& l : bonds_) {
    l.a = new_of_old[l.a];
    l.b = new_of_old[l.b];
  }
  bond_topology_dirty_ = true;
}

void Scene::drop_bonded_candidates() {
  if (bonds_.empty()) return;
  if (bond_topology_dirty_) rebuild_bond_adjacency();
  // Both lists are sorted by (i, j): one merge.
  size_t q = 0;
  drop_candidates([&](int i, int j) {
    const std::pair<int, int> p(i, j);
    while (q < bond_pairs_.size() && bond_pairs_[q] < p) ++q;
    return q < bond_pairs_.size() && bond_pairs_[q] == p;
  });
}

void Scene::compute_bonds(long& err) {
  if (bond_topology_dirty_) rebuild_bond_adjacency();
  compute_bonds_hot(err);
  // Breakage, in bond order: the part is removed, its energy counted, the event recorded.
  const long nb = static_cast<long>(bonds_.size());
  for (long k = 0; k < nb; ++k) {
    Bond& l = bonds_[k];
    if (l.pending_break < 0) continue;
    BondBreak ev;
    ev.step = step_;
    ev.time = time_;
    ev.bond = static_cast<int>(k);
    ev.mode = l.pending_break;
    ev.value = l.pending_value;
    bond_breaks_.push_back(ev);
    dropped_plastic_ += bond_release(l, l.pending_break, bodies_.radius[l.a],
                                     bodies_.radius[l.b], bodies_.pos[l.a],
                                     Vec3(bodies_.pos[l.b] + bond_shift(l)));
    l.pending_break = -1;
  }
}

void Scene::compute_bonds_hot(long& err) {
  // (Multiversioned as the other hot passes, core/types.hpp: bond_step is inlined into each
  // clone. The AVX clones do the baseline's IEEE operations in its order, contraction off:
  // the same bits, 1.10 x faster on bench/ab_build.py's bonds scene.)
  const long nb = static_cast<long>(bonds_.size());
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  long first_bad = std::numeric_limits<long>::max();
  // Periodic cell: b at its image, with the mean field's velocity L d and spin added to the
  // stored fluctuations, as the pair pass sees a contact's j (passes/pair.cpp).
  const bool periodic = cell_.on;
  const Mat3 lgrad = cell_.vel_grad;
  const Vec3 spin = periodic ? cell_.spin() : Vec3::Zero();
#pragma omp parallel for schedule(static) reduction(min : first_bad) if (nb > kParallelMinBonds)
  for (long k = 0; k < nb; ++k) {
    Bond& l = bonds_[k];
    const Real ra = bodies_.radius[l.a], rb = bodies_.radius[l.b];
    Real overlap;
    if (!periodic) {
      overlap = bond_step(l, ra, rb, bodies_.pos[l.a], bodies_.pos[l.b], bodies_.vel[l.a],
                          bodies_.vel[l.b], bodies_.angvel[l.a], bodies_.angvel[l.b], dt);
    } else {
      const Vec3 xb = bodies_.pos[l.b] + bond_shift(l);
      const Vec3 vb = bodies_.vel[l.b] + lgrad * (xb - bodies_.pos[l.a]);
      overlap = bond_step(l, ra, rb, bodies_.pos[l.a], xb, bodies_.vel[l.a], vb,
                          Vec3(bodies_.angvel[l.a] + spin), Vec3(bodies_.angvel[l.b] + spin),
                          dt);
    }
    if (!(overlap <= max_ratio * std::min(ra, rb))) first_bad = std::min(first_bad, k);
  }
  err = first_bad;
}

void Scene::raise_bond_overlap(long k) const {
  const Bond& l = bonds_[k];
  const Real gap = (bodies_.pos[l.b] + bond_shift(l) - bodies_.pos[l.a]).norm() -
                   bodies_.radius[l.a] - bodies_.radius[l.b];
  std::ostringstream os;
  os.precision(4);
  os << "blow-up at step " << step_ << ": bonded spheres " << id_of(l.a) << " and "
     << id_of(l.b) << " (bond " << k << ") overlap by "
     << (l.gap0 - gap) / std::min(bodies_.radius[l.a], bodies_.radius[l.b])
     << " of the smaller radius (max_overlap_ratio=" << max_overlap_ratio_
     << "); the time step may be too large or the bond's linear contact too soft";
  throw BlowUpError(os.str());
}

}  // namespace cpp_dem
