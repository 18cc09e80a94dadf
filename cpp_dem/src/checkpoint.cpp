#include "cpp_dem/checkpoint.hpp"

#include <cstring>
#include <string>
#include <type_traits>

#include "cpp_dem/control/controllers.hpp"

namespace cpp_dem {

namespace {
constexpr char kMagic[8] = {'C', 'P', 'D', 'E', 'M', 'C', 'K', 'P'};

// The records below hold only numbers (doubles, ints, Eigen fixed-size vectors): no pointers,
// no heap. They are copied byte for byte; the blob header stores their sizes, so a blob from
// a build with another layout is refused instead of misread.
template <class T>
constexpr bool kPlain = std::is_standard_layout_v<T> && !std::is_pointer_v<T>;

class Writer {
 public:
  std::vector<std::uint8_t> buf;
  void raw(const void* p, size_t n) {
    const auto* c = static_cast<const std::uint8_t*>(p);
    buf.insert(buf.end(), c, c + n);
  }
  template <class T>
  void put(const T& v) {
    static_assert(kPlain<T>);
    raw(static_cast<const void*>(&v), sizeof(T));
  }
  template <class T>
  void vec(const std::vector<T>& v) {
    static_assert(kPlain<T>);
    const std::uint64_t n = v.size();
    put(n);
    if (n) raw(static_cast<const void*>(v.data()), n * sizeof(T));
  }
};

class Reader {
 public:
  Reader(const std::vector<std::uint8_t>& b) : buf(b) {}
  const std::vector<std::uint8_t>& buf;
  size_t at = 0;
  void raw(void* p, size_t n) {
    if (at + n > buf.size())
      throw ParameterError("checkpoint: truncated blob (needs " + std::to_string(at + n) +
                           " bytes, has " + std::to_string(buf.size()) + ")");
    std::memcpy(p, buf.data() + at, n);
    at += n;
  }
  template <class T>
  T get() {
    T v;
    raw(static_cast<void*>(&v), sizeof(T));
    return v;
  }
  template <class T>
  void get(T& v) {
    raw(static_cast<void*>(&v), sizeof(T));
  }
  template <class T>
  void vec(std::vector<T>& v) {
    const auto n = get<std::uint64_t>();
    if (n > buf.size()) throw ParameterError("checkpoint: corrupt vector length");
    v.resize(n);
    if (n) raw(static_cast<void*>(v.data()), n * sizeof(T));
  }
};

/// Sizes of every record type, in a fixed order: the layout fingerprint.
/// (Before version 10 the body store had one array fewer, inertia_scale.)
std::vector<std::uint64_t> layout(std::uint32_t version = Checkpoint::kVersion) {
  const std::uint64_t body_store = sizeof(BodyStore) - (version < 10 ? sizeof(std::vector<Real>) : 0);
  std::vector<std::uint64_t> l = {sizeof(Real),        body_store,        sizeof(Vec3),        sizeof(Quat),       sizeof(Material),
          sizeof(Wall),        sizeof(PairContact), sizeof(PairOutput), sizeof(WallContact), sizeof(GridLink),
          sizeof(PFacet),      sizeof(GridContact), sizeof(BreakEvent), sizeof(ContactPhys),
          sizeof(ContactState), sizeof(PairContactCold), sizeof(PeriodicCell), sizeof(Bond),
          sizeof(BondBreak), sizeof(PairLaw)};
  // (Version 11 added the wall openings.)
  if (version >= 11) l.push_back(sizeof(WallOpening));
  return l;
}
}  // namespace

std::vector<std::uint8_t> Checkpoint::save(const Scene& s) {
  Writer w;
  w.raw(kMagic, sizeof(kMagic));
  w.put(kVersion);
  w.vec(layout());
  w.vec(s.materials_);
  w.vec(s.pair_laws_);
  // Bodies.
  s.bodies_.for_each_array([&](const auto& v) { w.vec(v); });
  s.clumps_.for_each_array([&](const auto& v) { w.vec(v); });
  w.vec(s.id_of_slot_);
  w.put(s.spatial_sort_);
  w.vec(s.pos_at_build_);
  w.vec(s.radius_at_build_);
  w.vec(s.walls_);
  w.vec(s.wall_openings_);
  w.put(s.cell_);
  w.put(s.max_radius_at_build_);
  // Contacts and adjacency.
  w.vec(s.pairs_);
  w.vec(s.pair_cold_);
  w.vec(s.pair_out_);
  w.vec(s.wall_contacts_);
  w.vec(s.pair_jadj_off_);
  w.vec(s.pair_jslot_);
  w.vec(s.pair_ioff_);
  w.vec(s.wall_adj_off_);
  w.vec(s.wall_adj_);
  // Geogrid.
  w.put(s.num_nodes_);
  w.vec(s.links_);
  w.vec(s.facets_);
  w.vec(s.grid_contacts_);
  w.vec(s.breaks_);
  w.vec(s.bonds_);
  w.vec(s.bond_breaks_);
  w.put(s.dropped_plastic_);
  w.vec(s.node_link_off_);
  w.vec(s.node_link_);
  w.vec(s.link_facet_);
  w.vec(s.sphere_gc_off_);
  w.vec(s.sphere_gc_);
  w.vec(s.node_gc_off_);
  w.vec(s.node_gc_);
  w.put(s.grid_topology_dirty_);
  w.put(s.grid_wall_contacts_);
  w.vec(s.candidates_);
  w.vec(s.candidate_images_);
  // Energy bookkeeping.
  w.put(s.dropped_friction_);
  w.put(s.dropped_viscous_);
  w.put(s.energy_reference_);
  w.put(s.energy_reference_set_);
  // Parameters and counters.
  w.put(s.dt_);
  w.put(s.gravity_);
  w.put(s.local_damping_);
  w.put(s.margin_);
  w.put(s.max_overlap_ratio_);
  w.put(s.max_step_ratio_);
  w.put(s.dt_check_period_);
  w.put(s.track_energy_);
  w.put(s.clump_rotation_);
  w.put(s.shear_kinematics_);
  w.put(s.ts_safety_);
  w.put(s.ts_period_);
  w.put(s.ds_on_);
  w.put(s.ds_target_dt_);
  w.put(s.ds_safety_);
  w.put(s.ds_period_);
  w.put(s.ds_stale_);
  w.put(s.step_);
  w.put(s.time_);
  w.put(s.phys_version_);
  w.put(s.dirty_);
  w.put(s.builds_);
  // Controllers.
  const std::uint64_t nc = s.controllers_.size();
  w.put(nc);
  for (const auto& c : s.controllers_) {
    w.put(c->period);
    w.put(c->enabled);
    const auto* st = dynamic_cast<const StatefulController*>(c.get());
    w.put(static_cast<std::uint8_t>(st ? 1 : 0));
    if (st) w.vec(st->save_state());
  }
  return std::move(w.buf);
}

void Checkpoint::load(Scene& s, const std::vector<std::uint8_t>& blob) {
  Reader r(blob);
  char magic[8];
  r.raw(magic, sizeof(magic));
  if (std::memcmp(magic, kMagic, sizeof(kMagic)) != 0)
    throw ParameterError("checkpoint: not a cpp_dem checkpoint blob (bad magic)");
  const auto version = r.get<std::uint32_t>();
  if (version < 8 || version > kVersion)
    throw ParameterError("checkpoint: format version " + std::to_string(version) +
                         ", this build reads versions 8 to " + std::to_string(kVersion));
  std::vector<std::uint64_t> lay;
  r.vec(lay);
  if (lay != layout(version))
    throw ParameterError("checkpoint: written by a build with other record layouts (struct "
                         "sizes differ); restart with the build that wrote it");
  // Read everything into a copy first, so a bad blob leaves the scene untouched.
  Scene t;
  r.vec(t.materials_);
  r.vec(t.pair_laws_);
  // (The inertia factors, the last arrays of both stores, from version 10 on; before, 1.)
  t.bodies_.for_each_array([&](auto& v) {
    if (version >= 10 || static_cast<const void*>(&v) != &t.bodies_.inertia_scale) r.vec(v);
  });
  const size_t nb = t.bodies_.pos.size();
  if (version < 10) t.bodies_.inertia_scale.assign(nb, 1.0);
  t.bodies_.for_each_array([&](const auto& v) {
    if (v.size() != nb) throw ParameterError("checkpoint: corrupt body arrays");
  });
  t.clumps_.for_each_array([&](auto& v) {
    if (version >= 10 || static_cast<const void*>(&v) != &t.clumps_.inertia_scale) r.vec(v);
  });
  if (version < 10) t.clumps_.inertia_scale.assign(t.clumps_.pos.size(), 1.0);
  if (t.clumps_.inertia_scale.size() != t.clumps_.pos.size())
    throw ParameterError("checkpoint: corrupt clump arrays");
  {
    const size_t ncl = t.clumps_.pos.size(), nm = t.clumps_.member.size();
    bool ok = t.clumps_.member_off.size() == (ncl ? ncl + 1 : 0) && t.clumps_.member_local.size() == nm;
    for (int m : t.clumps_.member) ok = ok && m >= 0 && static_cast<size_t>(m) < nb;
    if (!ok) throw ParameterError("checkpoint: corrupt clump arrays");
  }
  r.vec(t.id_of_slot_);
  r.get(t.spatial_sort_);
  if (!t.id_of_slot_.empty()) {
    if (t.id_of_slot_.size() != t.bodies_.pos.size())
      throw ParameterError("checkpoint: corrupt storage order");
    t.slot_of_id_.assign(t.id_of_slot_.size(), -1);
    for (size_t b = 0; b < t.id_of_slot_.size(); ++b) {
      const int id = t.id_of_slot_[b];
      if (id < 0 || id >= static_cast<int>(t.bodies_.pos.size()) || t.slot_of_id_[id] != -1)
        throw ParameterError("checkpoint: corrupt storage order");
      t.slot_of_id_[id] = static_cast<int>(b);
    }
  }
  r.vec(t.pos_at_build_);
  r.vec(t.radius_at_build_);
  r.vec(t.walls_);
  if (version >= 11)
    r.vec(t.wall_openings_);
  else
    t.wall_openings_.assign(t.walls_.size(), WallOpening{});
  if (t.wall_openings_.size() != t.walls_.size())
    throw ParameterError("checkpoint: corrupt wall openings");
  for (const WallOpening& o : t.wall_openings_)
    if (o.axis < -1 || o.axis > 2) throw ParameterError("checkpoint: corrupt wall openings");
  r.get(t.cell_);
  r.get(t.max_radius_at_build_);
  r.vec(t.pairs_);
  r.vec(t.pair_cold_);
  r.vec(t.pair_out_);
  r.vec(t.wall_contacts_);
  r.vec(t.pair_jadj_off_);
  r.vec(t.pair_jslot_);
  r.vec(t.pair_ioff_);
  r.vec(t.wall_adj_off_);
  r.vec(t.wall_adj_);
  r.get(t.num_nodes_);
  r.vec(t.links_);
  r.vec(t.facets_);
  r.vec(t.grid_contacts_);
  r.vec(t.breaks_);
  r.vec(t.bonds_);
  r.vec(t.bond_breaks_);
  for (const Bond& l : t.bonds_)
    if (l.a < 0 || l.b < 0 || static_cast<size_t>(l.a) >= nb || static_cast<size_t>(l.b) >= nb)
      throw ParameterError("checkpoint: corrupt bonds");
  t.bond_topology_dirty_ = true;  // adjacency and pair list are made again from the bonds
  r.get(t.dropped_plastic_);
  r.vec(t.node_link_off_);
  r.vec(t.node_link_);
  r.vec(t.link_facet_);
  r.vec(t.sphere_gc_off_);
  r.vec(t.sphere_gc_);
  r.vec(t.node_gc_off_);
  r.vec(t.node_gc_);
  r.get(t.grid_topology_dirty_);
  r.get(t.grid_wall_contacts_);
  r.vec(t.candidates_);
  r.vec(t.candidate_images_);
  r.get(t.dropped_friction_);
  r.get(t.dropped_viscous_);
  r.get(t.energy_reference_);
  r.get(t.energy_reference_set_);
  r.get(t.dt_);
  r.get(t.gravity_);
  r.get(t.local_damping_);
  r.get(t.margin_);
  r.get(t.max_overlap_ratio_);
  r.get(t.max_step_ratio_);
  r.get(t.dt_check_period_);
  r.get(t.track_energy_);
  r.get(t.clump_rotation_);
  // Version 8 had no shear kinematics: its scenes ran the default (t's own).
  if (version >= 9) {
    r.get(t.shear_kinematics_);
    if (static_cast<std::uint8_t>(t.shear_kinematics_) > 1)
      throw ParameterError("checkpoint: corrupt shear kinematics");
  }
  r.get(t.ts_safety_);
  r.get(t.ts_period_);
  if (version >= 10) {
    r.get(t.ds_on_);
    r.get(t.ds_target_dt_);
    r.get(t.ds_safety_);
    r.get(t.ds_period_);
    r.get(t.ds_stale_);
    if (t.ds_on_ && !(t.ds_target_dt_ > 0 && t.ds_safety_ > 0 && t.ds_period_ >= 1))
      throw ParameterError("checkpoint: corrupt density scaling");
  }
  r.get(t.step_);
  r.get(t.time_);
  r.get(t.phys_version_);
  r.get(t.dirty_);
  t.disp_valid_ = false;  // need_rebuild measures the displacements itself
  r.get(t.builds_);
  const auto nc = r.get<std::uint64_t>();
  if (nc != s.controllers_.size())
    throw ParameterError("checkpoint: the saved scene had " + std::to_string(nc) +
                         " controllers, this scene has " + std::to_string(s.controllers_.size()) +
                         "; add the same controllers, in the same order, before loading");
  struct Ctl {
    int period;
    bool enabled;
    bool stateful;
    std::vector<Real> state;
  };
  std::vector<Ctl> ctl(nc);
  for (std::uint64_t k = 0; k < nc; ++k) {
    r.get(ctl[k].period);
    r.get(ctl[k].enabled);
    ctl[k].stateful = r.get<std::uint8_t>() != 0;
    if (ctl[k].stateful) r.vec(ctl[k].state);
    const bool here = dynamic_cast<StatefulController*>(s.controllers_[k].get()) != nullptr;
    if (here != ctl[k].stateful)
      throw ParameterError("checkpoint: controller " + std::to_string(k) +
                           " is of another kind than the saved one");
  }
  if (r.at != blob.size())
    throw ParameterError("checkpoint: " + std::to_string(blob.size() - r.at) +
                         " unexpected trailing bytes");
  if (!kGeogridBuilt && (t.num_nodes_ > 0 || !t.links_.empty()))
    throw ParameterError("checkpoint: the saved scene has a geogrid; this build has no geogrid "
                         "support (built with -DCPP_DEM_GEOGRID=OFF)");
  for (std::uint64_t k = 0; k < nc; ++k) {
    if (ctl[k].stateful)
      dynamic_cast<StatefulController*>(s.controllers_[k].get())->load_state(ctl[k].state);
    s.controllers_[k]->period = ctl[k].period;
    s.controllers_[k]->enabled = ctl[k].enabled;
  }
  t.controllers_ = std::move(s.controllers_);
  // The cell grid is scratch of the broad phase (rebuilt from scratch at every build).
  s = std::move(t);
}

}  // namespace cpp_dem
