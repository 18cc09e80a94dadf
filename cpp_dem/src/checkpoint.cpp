#include "cpp_dem/checkpoint.hpp"

#include <cxxabi.h>

#include <cstdlib>
#include <cstring>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <typeinfo>

#include "cpp_dem/control/controllers.hpp"
#include "cpp_dem/laws/registry.hpp"

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

/// A material as versions 8 to 12 stored it (a record of the 8 shared parameters).
struct MaterialV12 {
  ContactModel model;
  std::uint8_t pad_[7];
  Real density, young, poisson, friction_angle, damping_normal, damping_shear,
      rolling_stiffness, rolling_friction;
};
static_assert(sizeof(MaterialV12) == 8 + 8 * sizeof(Real));

std::vector<char> chars(const char* s) { return std::vector<char>(s, s + std::strlen(s)); }

/// The materials by their field list (version 13 on): per material, the law's name, then
/// each parameter's name and stored value.
void put_materials(Writer& w, const std::vector<Material>& materials) {
  w.put(static_cast<std::uint64_t>(materials.size()));
  for (const Material& m : materials) {
    w.vec(chars(law_info(m.model).name));
    const auto fields = material_fields(m.model);
    w.put(static_cast<std::uint64_t>(fields.size()));
    for (const FieldInfo* f : fields) {
      w.vec(chars(f->name));
      w.put(field_value(m, *f));
    }
  }
}

/// Reads what put_materials wrote: a parameter the blob lacks takes its default, a parameter
/// or law this build does not know is refused by name.
std::vector<Material> get_materials(Reader& r) {
  const auto n = r.get<std::uint64_t>();
  if (n > r.buf.size()) throw ParameterError("checkpoint: corrupt material count");
  std::vector<Material> out;
  for (std::uint64_t k = 0; k < n; ++k) {
    const std::string what = "checkpoint: material " + std::to_string(k);
    std::vector<char> name;
    r.vec(name);
    Material m;
    try {
      m.model = law_by_name(std::string(name.begin(), name.end()));
    } catch (const ParameterError& e) {
      throw ParameterError(what + ": " + e.what() + " (a law of another build)");
    }
    const auto fields = material_fields(m.model);
    std::vector<bool> seen(fields.size(), false);
    const auto count = r.get<std::uint64_t>();
    if (count > r.buf.size()) throw ParameterError(what + ": corrupt parameter count");
    for (std::uint64_t j = 0; j < count; ++j) {
      r.vec(name);
      const std::string field(name.begin(), name.end());
      const Real v = r.get<Real>();
      const size_t i = field_index(fields, field);
      if (i == fields.size())
        throw ParameterError(what + " (" + law_info(m.model).name + "): parameter '" + field +
                             "' is not one of this build's (a checkpoint of another build)");
      field_value(m, *fields[i]) = v;
      seen[i] = true;
    }
    for (size_t i = 0; i < fields.size(); ++i) {
      if (seen[i]) continue;
      if (fields[i]->required())
        throw ParameterError(what + ": parameter '" + fields[i]->name + "' is missing");
      field_value(m, *fields[i]) = fields[i]->to_stored(fields[i]->fallback);
    }
    out.push_back(m);
  }
  return out;
}

/// A pair contact's cold part as versions 8 to 14 stored it: with its friction dissipation
/// (now Scene::pair_dissip_) between the rolling moment and the viscous dissipation, and kept
/// by every scene.
struct PairContactColdV14 {
  ContactPhys phys;
  Vec3 mr = Vec3::Zero();
  Real dissip_friction = 0;
  Real dissip_viscous = 0;
};

/// Sizes of every record type, in a fixed order: the layout fingerprint.
/// (Before version 10 the body store had one array fewer, inertia_scale.)
std::vector<std::uint64_t> layout(std::uint32_t version = Checkpoint::kVersion) {
  const std::uint64_t body_store = sizeof(BodyStore) - (version < 10 ? sizeof(std::vector<Real>) : 0);
  // (From version 13 on the materials go by name: no record size.)
  const std::uint64_t material = version < 13 ? sizeof(MaterialV12) : 0;
  std::vector<std::uint64_t> l = {sizeof(Real),        body_store,        sizeof(Vec3),        sizeof(Quat),       material,
          sizeof(Wall),        sizeof(PairContactDisk), sizeof(PairOutput), sizeof(WallContact), sizeof(GridLink),
          sizeof(PFacet),      sizeof(GridContact), sizeof(BreakEvent), sizeof(ContactPhys),
          sizeof(ContactState), version < 15 ? sizeof(PairContactColdV14) : sizeof(PairContactCold), sizeof(PeriodicCell), sizeof(Bond),
          sizeof(BondBreak), sizeof(PairLaw)};
  // (Version 11 added the wall openings.)
  if (version >= 11) l.push_back(sizeof(WallOpening));
  // (Version 14 added the cylindrical walls.)
  if (version >= 14) {
    l.push_back(sizeof(CylinderWall));
    l.push_back(sizeof(MeshWall));
    l.push_back(sizeof(MeshContact));
  }
  return l;
}

/// A controller's kind as the blob stores it: its C++ type's (mangled) name.
std::vector<char> controller_kind(const Controller& c) {
  const char* n = typeid(c).name();
  return std::vector<char>(n, n + std::strlen(n));
}

/// The readable name of a stored kind ("cpp_dem::ServoWall" -> "ServoWall").
std::string kind_name(const std::vector<char>& kind) {
  const std::string mangled(kind.begin(), kind.end());
  int status = 0;
  char* d = abi::__cxa_demangle(mangled.c_str(), nullptr, nullptr, &status);
  std::string out = status == 0 && d ? d : mangled;
  std::free(d);
  const auto colon = out.rfind("::");
  return colon == std::string::npos ? out : out.substr(colon + 2);
}

/// A controller that does nothing: its period goes through Scene::add_controller's check.
class PeriodProbe final : public Controller {
 public:
  void apply(Scene&) override {}
};

const char* kSameScene =
    "; load a checkpoint into the scene it came from (or into a new, empty Scene), or pass "
    "replace=True to replace this scene with the saved one";

std::string body_kind_text(std::uint8_t kind, int clump) {
  const std::string k = kind == BODY_SPHERE ? "sphere" : kind == BODY_GRID_NODE ? "grid node"
                                                                                  : "body";
  return clump >= 0 ? "member of clump " + std::to_string(clump) : "free " + k;
}
}  // namespace

void Checkpoint::check_values(const Scene& t) {
  Scene v;  // scratch: the stored values go through the API's own setters
  const auto stored = [](const std::string& what, auto&& set) {
    try {
      set();
    } catch (const ParameterError& e) {
      throw ParameterError("checkpoint: stored " + what + ": " + e.what() +
                           " (the API refuses this value; the file is corrupt or was edited)");
    }
  };
  for (size_t k = 0; k < t.materials_.size(); ++k)
    stored("material " + std::to_string(k), [&] { v.add_material(t.materials_[k]); });
  for (const PairLaw& l : t.pair_laws_)
    stored("pair law " + std::to_string(l.a) + "-" + std::to_string(l.b),
           [&] { v.set_pair_law(l.a, l.b, l); });
  stored("parameters", [&] {
    v.set_dt(t.dt_);
    v.set_gravity(t.gravity_);
    v.set_local_damping(t.local_damping_);
    v.set_verlet_margin(t.margin_);
    v.set_max_overlap_ratio(t.max_overlap_ratio_);
    v.set_max_step_ratio(t.max_step_ratio_);
    v.set_dt_check_period(t.dt_check_period_);
    v.set_auto_timestep(t.ts_safety_, t.ts_period_);  // (v has no body: dt is kept)
    if (t.ds_on_) v.set_density_scaling(t.ds_target_dt_, t.ds_safety_, t.ds_period_);
  });
  if (t.cell_.on)
    stored("periodic cell", [&] {
      v.set_periodic_cell(t.cell_.h, t.cell_.periodic);
      v.set_velocity_gradient(t.cell_.vel_grad);
    });
  for (size_t k = 0; k < t.walls_.size(); ++k)
    stored("wall " + std::to_string(k), [&] {
      const Wall& w = t.walls_[k];
      const WallOpening& o = t.wall_openings_[k];
      const int id = v.add_wall(w.axis, w.position, w.sense, w.material);
      v.set_wall_opening(id, o.axis, o.lo, o.hi);
    });
  const int n = t.num_bodies();
  if (n > 0)
    stored("bodies", [&] { v.add_spheres(t.by_id(t.bodies_.pos), t.by_id(t.bodies_.radius), 0); });
  const int ncl = t.clumps_.size();
  for (int id = 0; id < n; ++id) {
    const int s = t.slot_of(id);
    const std::uint8_t kind = t.bodies_.kind[s];
    const int clump = t.bodies_.clump[s];
    if (kind != BODY_SPHERE && kind != BODY_GRID_NODE)
      throw ParameterError("checkpoint: stored body " + std::to_string(id) + ": kind " +
                           std::to_string(kind) + ", allowed 0 (sphere) or 1 (grid node); the "
                           "file is corrupt");
    if (clump < -1 || clump >= ncl)
      throw ParameterError("checkpoint: stored body " + std::to_string(id) + ": clump " +
                           std::to_string(clump) + ", allowed -1 (free) to " +
                           std::to_string(ncl - 1) + "; the file is corrupt");
    stored("body " + std::to_string(id), [&] {
      v.set_body_material(id, t.bodies_.material[s]);
      v.set_mass_inertia(id, t.bodies_.mass[s], t.bodies_.inertia[s]);
      v.set_blocked(id, t.bodies_.blocked[s]);
    });
  }
  const ClumpStore& cs = t.clumps_;
  for (int c = 0; c < ncl; ++c) {
    const int e0 = cs.member_off[c], e1 = cs.member_off[c + 1];
    if (e0 < 0 || e1 <= e0 || e1 > static_cast<int>(cs.member.size()) || (c == 0 && e0 != 0) ||
        (c == ncl - 1 && e1 != static_cast<int>(cs.member.size())))
      throw ParameterError("checkpoint: stored clump " + std::to_string(c) +
                           ": corrupt member list; the file is corrupt");
    std::vector<Vec3> local;
    std::vector<Real> radius;
    for (int e = e0; e < e1; ++e) {
      if (t.bodies_.clump[cs.member[e]] != c)
        throw ParameterError("checkpoint: stored clump " + std::to_string(c) + ": member body " +
                             std::to_string(t.id_of(cs.member[e])) + " is not marked as its "
                             "member; the file is corrupt");
      local.push_back(cs.member_local[e]);
      radius.push_back(t.bodies_.radius[cs.member[e]]);
    }
    stored("clump " + std::to_string(c), [&] {
      const int vc = v.add_clump(local, radius, t.bodies_.material[cs.member[e0]], cs.mass[c],
                                 cs.inertia[c], cs.pos[c], cs.ori[c], cs.stiffness_radius[c]);
      v.set_clump_blocked(vc, cs.blocked[c]);
    });
  }
}

void Checkpoint::check_same_scene(const Scene& s, const Scene& t) {
  if (s.num_bodies() == 0 && s.walls_.empty() && s.cylinder_walls_.empty() &&
      s.mesh_walls_.empty() && !s.cell_.on)
    return;  // blank: nothing to replace
  const auto axes = [](const PeriodicCell& c) {
    std::string a;
    for (int k = 0; k < 3; ++k)
      if (c.periodic[k]) a += "xyz"[k];
    return a;
  };
  if (t.cell_.on != s.cell_.on || (t.cell_.on && t.cell_.periodic != s.cell_.periodic)) {
    const auto what = [&](const PeriodicCell& c) {
      return c.on ? "a periodic cell (periodic along " + axes(c) + ")"
                  : std::string("not periodic");
    };
    throw ParameterError("checkpoint: the saved scene is " + what(t.cell_) + ", this scene is " +
                         what(s.cell_) + kSameScene);
  }
  if (t.num_bodies() != s.num_bodies())
    throw ParameterError("checkpoint: the saved scene has " + std::to_string(t.num_bodies()) +
                         " bodies, this scene has " + std::to_string(s.num_bodies()) + kSameScene);
  if (t.clumps_.size() != s.clumps_.size())
    throw ParameterError("checkpoint: the saved scene has " + std::to_string(t.clumps_.size()) +
                         " clumps, this scene has " + std::to_string(s.clumps_.size()) +
                         kSameScene);
  for (int id = 0; id < s.num_bodies(); ++id) {
    const int a = t.slot_of(id), b = s.slot_of(id);
    if (t.bodies_.kind[a] != s.bodies_.kind[b] || t.bodies_.clump[a] != s.bodies_.clump[b])
      throw ParameterError("checkpoint: body " + std::to_string(id) + " is a " +
                           body_kind_text(t.bodies_.kind[a], t.bodies_.clump[a]) +
                           " in the saved scene, a " +
                           body_kind_text(s.bodies_.kind[b], s.bodies_.clump[b]) +
                           " in this one" + kSameScene);
  }
  if (t.walls_.size() != s.walls_.size())
    throw ParameterError("checkpoint: the saved scene has " + std::to_string(t.walls_.size()) +
                         " walls, this scene has " + std::to_string(s.walls_.size()) + kSameScene);
  for (size_t k = 0; k < s.walls_.size(); ++k) {
    const Wall &a = t.walls_[k], &b = s.walls_[k];
    if (a.axis != b.axis || a.sense != b.sense) {
      const auto side = [](const Wall& w) {
        return std::string(w.sense > 0 ? "+" : "-") + "xyz"[w.axis];
      };
      throw ParameterError("checkpoint: wall " + std::to_string(k) + " faces " + side(a) +
                           " in the saved scene, " + side(b) + " in this one" + kSameScene);
    }
  }
  if (t.cylinder_walls_.size() != s.cylinder_walls_.size())
    throw ParameterError("checkpoint: the saved scene has " +
                         std::to_string(t.cylinder_walls_.size()) + " cylindrical walls, this "
                         "scene has " + std::to_string(s.cylinder_walls_.size()) + kSameScene);
  for (size_t k = 0; k < s.cylinder_walls_.size(); ++k)
    if (t.cylinder_walls_[k].inside != s.cylinder_walls_[k].inside) {
      const auto side = [](const CylinderWall& w) {
        return std::string(w.inside ? "inside" : "outside");
      };
      throw ParameterError("checkpoint: cylindrical wall " + std::to_string(k) + " holds its "
                           "spheres " + side(t.cylinder_walls_[k]) + " in the saved scene, " +
                           side(s.cylinder_walls_[k]) + " in this one" + kSameScene);
    }  if (t.mesh_walls_.size() != s.mesh_walls_.size())
    throw ParameterError("checkpoint: the saved scene has " + std::to_string(t.mesh_walls_.size()) +
                         " mesh walls, this scene has " + std::to_string(s.mesh_walls_.size()) +
                         kSameScene);
  // The materials and pair laws: a scene of other grains or laws is another scene (a run
  // that changes them, as a frictionless growth, saves and restores them with its state: the
  // scene rebuilt for its resume is brought to the same ones before the load).
  if (t.materials_.size() != s.materials_.size())
    throw ParameterError("checkpoint: the saved scene has " + std::to_string(t.materials_.size()) +
                         " materials, this scene has " + std::to_string(s.materials_.size()) +
                         kSameScene);
  for (size_t k = 0; k < s.materials_.size(); ++k) {
    const Material &a = t.materials_[k], &b = s.materials_[k];
    if (a.model != b.model)
      throw ParameterError("checkpoint: material " + std::to_string(k) + " follows the " +
                           law_info(a.model).name + " law in the saved scene, the " +
                           law_info(b.model).name + " law in this one" + kSameScene);
    for (const FieldInfo* f : material_fields(a.model)) {
      const Real va = field_value(a, *f), vb = field_value(b, *f);
      if (std::memcmp(&va, &vb, sizeof(Real)) == 0) continue;
      std::ostringstream os;
      os.precision(17);
      os << "checkpoint: material " << k << "'s " << f->name << " is " << va
         << " (stored value) in the saved scene, " << vb << " in this one" << kSameScene;
      throw ParameterError(os.str());
    }
  }
  const auto law_text = [](const std::vector<PairLaw>& laws) {
    std::ostringstream os;
    os.precision(17);
    if (laws.empty()) return std::string("none");
    for (const PairLaw& l : laws) {
      os << "(" << l.a << ", " << l.b << ":";
      if (l.model_set) os << " model " << law_info(l.model).name;
      const std::pair<const char*, Real> v[] = {{"kn", l.kn}, {"ks", l.ks},
                                                {"friction", l.friction},
                                                {"damping_normal", l.damping_normal},
                                                {"damping_shear", l.damping_shear}};
      for (const auto& [name, x] : v)
        if (x >= 0) os << " " << name << " " << x;
      os << ")";
    }
    return os.str();
  };
  const bool same_laws =
      t.pair_laws_.size() == s.pair_laws_.size() &&
      (t.pair_laws_.empty() || std::memcmp(t.pair_laws_.data(), s.pair_laws_.data(),
                                           t.pair_laws_.size() * sizeof(PairLaw)) == 0);
  if (!same_laws)
    throw ParameterError("checkpoint: the pair laws are " + law_text(t.pair_laws_) +
                         " in the saved scene, " + law_text(s.pair_laws_) + " in this one" +
                         kSameScene);
  for (size_t k = 0; k < s.mesh_walls_.size(); ++k)
    if (t.mesh_walls_[k].ntri != s.mesh_walls_[k].ntri)
      throw ParameterError("checkpoint: mesh wall " + std::to_string(k) + " has " +
                           std::to_string(t.mesh_walls_[k].ntri) + " triangles in the saved "
                           "scene, " + std::to_string(s.mesh_walls_[k].ntri) + " in this one" +
                           kSameScene);
}

std::vector<std::uint8_t> Checkpoint::save(const Scene& s) {
  Writer w;
  w.raw(kMagic, sizeof(kMagic));
  w.put(kVersion);
  w.vec(layout());
  put_materials(w, s.materials_);
  w.vec(s.pair_laws_);
  // Bodies. (The wrap counts and the inertia factors exist from their first use on:
  // without them the arrays they stand for, zeros and ones, so the bytes are the same.)
  const size_t nbodies = s.bodies_.pos.size();
  s.bodies_.for_each_array([&](const auto& v) {
    using T = typename std::decay_t<decltype(v)>::value_type;
    const void* const p = &v;
    if (v.empty() && p == &s.bodies_.image) {
      w.vec(std::vector<T>(nbodies, T{}));
    } else if (v.empty() && p == &s.bodies_.inertia_scale) {
      if constexpr (std::is_same_v<T, Real>) w.vec(std::vector<Real>(nbodies, 1.0));
    } else {
      w.vec(v);
    }
  });
  s.clumps_.for_each_array([&](const auto& v) { w.vec(v); });
  w.vec(s.id_of_slot_);
  w.put(s.spatial_sort_);
  w.vec(s.pos_at_build_);
  if (s.radius_at_build_.empty())  // (no radius changed since the build: they are today's)
    w.vec(std::vector<Real>(s.bodies_.radius.begin(),
                            s.bodies_.radius.begin() + s.pos_at_build_.size()));
  else
    w.vec(s.radius_at_build_);
  w.vec(s.walls_);
  w.vec(s.wall_openings_);
  w.put(s.cell_);
  w.put(s.max_radius_at_build_);
  // Contacts and adjacency.
  {
    // (A contact's kernel is saved as the format's flag "linear short kernel", 0 or 1: the
    // Hertz kernels, derived from the phys, are 0 here and found again at the load, so a
    // contact's bytes do not depend on which kernels a build has.)
    // (A record for every candidate pair, in candidate order, with its friction dissipation:
    // the scene keeps them only for the candidates that carry history, Scene::cand_j_.)
    std::vector<PairContactDisk> pairs;
    std::vector<Real> dissip;
    s.expanded_pairs(pairs, dissip);
    for (PairContactDisk& c : pairs) c.kernel = c.kernel == kLinearKernel ? kLinearKernel : 0;
    w.vec(pairs);
    // (Version 15: whether the scene keeps the cold part, the cold part (empty if not) and
    // the friction dissipation.)
    w.put(static_cast<std::uint8_t>(s.pair_cold_on_));
    w.vec(s.pair_cold_);
    w.vec(dissip);
  }
  // (The pair pass's outputs only where the scene has the cold part: without it every
  // contact's force is its hot record's, f_n n + f_s (Scene::pair_force), and a pass on one
  // thread keeps no outputs (pair_direct_), so the bytes do not depend on the threads.)
  if (s.pair_cold_on_)
    w.vec(s.pair_out_);
  else
    w.vec(std::vector<PairOutput>());
  w.vec(s.wall_contacts_);
  {
    // (the slots of the pass's outputs, derived from the pairs: a scene after a direct pass
    // keeps none, and where it keeps them they are these)
    std::vector<int> jadj_off, jslot;
    s.index_pair_outputs(jadj_off, jslot);
    w.vec(jadj_off);
    w.vec(jslot);
  }
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
  // (the candidates as the list of pairs and an image code for each, kNoShift without a cell)
  w.vec(s.candidate_pairs());
  if (s.candidate_images_.empty())
    w.vec(std::vector<std::uint8_t>(s.cand_j_.size(), kNoShift));
  else
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
  w.vec(s.cylinder_walls_);
  w.vec(s.cylinder_contacts_);
  w.vec(s.cyl_adj_off_);
  w.vec(s.cyl_adj_);
  w.vec(s.mesh_walls_);
  w.vec(s.mesh_vertices_);
  w.vec(s.mesh_tris_);
  w.vec(s.mesh_contacts_);
  w.vec(s.mesh_cand_off_);
  w.vec(s.mesh_cand_tri_);
  w.vec(s.mesh_adj_off_);
  w.vec(s.mesh_adj_);
  w.put(s.mesh_dropped_);
  // Controllers.
  const std::uint64_t nc = s.controllers_.size();
  w.put(nc);
  for (const auto& c : s.controllers_) {
    w.vec(controller_kind(*c));
    w.put(c->period);
    w.put(c->enabled);
    const auto* st = dynamic_cast<const StatefulController*>(c.get());
    w.put(static_cast<std::uint8_t>(st ? 1 : 0));
    if (st) w.vec(st->save_state());
  }
  return std::move(w.buf);
}

void Checkpoint::load(Scene& s, const std::vector<std::uint8_t>& blob, bool replace) {
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
  if (version >= 13) {
    t.materials_ = get_materials(r);
  } else {
    std::vector<MaterialV12> old;
    r.vec(old);
    for (const MaterialV12& o : old) {
      Material m = Material::of_law(o.model);  // (a law's own parameters: their defaults)
      m.density = o.density;
      m.young = o.young;
      m.poisson = o.poisson;
      m.friction_angle = o.friction_angle;
      m.damping_normal = o.damping_normal;
      m.damping_shear = o.damping_shear;
      m.rolling_stiffness = o.rolling_stiffness;
      m.rolling_friction = o.rolling_friction;
      t.materials_.push_back(m);
    }
  }
  r.vec(t.pair_laws_);
  // (The inertia factors, the last arrays of both stores, from version 10 on; before, 1.)
  t.bodies_.for_each_array([&](auto& v) {
    if (version >= 10 || static_cast<const void*>(&v) != &t.bodies_.inertia_scale) r.vec(v);
  });
  const size_t nb = t.bodies_.pos.size();
  if (version < 10) t.bodies_.inertia_scale.assign(nb, 1.0);
  // (Arrays allocated on first use hold one entry per body, or none: the energy accumulators,
  // where the scene never tracked energy, BodyStore::size_energy, all four together; the
  // external force and the external torque, each where none was set.)
  const BodyStore& bs = t.bodies_;
  const auto lazy = [&bs](const void* v) {
    return v == &bs.ke || v == &bs.damp_dissip || v == &bs.ext_work ||
           v == &bs.pos_at_energy_reset || v == &bs.ext_force || v == &bs.ext_torque;
  };
  const size_t ne = bs.ke.size();
  t.bodies_.for_each_array([&](const auto& v) {
    if (v.size() != nb && !(lazy(&v) && v.empty()))
      throw ParameterError("checkpoint: corrupt body arrays");
  });
  if (bs.damp_dissip.size() != ne || bs.ext_work.size() != ne || bs.pos_at_energy_reset.size() != ne)
    throw ParameterError("checkpoint: corrupt body arrays");
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
    // (the energy accumulators: one entry per clump, or none; ClumpStore::size_energy)
    const size_t nce = t.clumps_.ke.size(), ncx = t.clumps_.ext_force.size();
    ok = ok && (nce == ncl || nce == 0) && t.clumps_.damp_dissip.size() == nce &&
         t.clumps_.ext_work.size() == nce && t.clumps_.pos_at_energy_reset.size() == nce;
    // (the external force and torque, allocated together when one is first set)
    ok = ok && (ncx == ncl || ncx == 0) && t.clumps_.ext_torque.size() == ncx;
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
  // (one record for every candidate, with its first body and phys version: compact_pairs,
  // below, keeps those that carry history)
  std::vector<PairContactDisk> disk;
  r.vec(disk);
  if (version >= 15) {
    const auto on = r.get<std::uint8_t>();
    if (on > 1) throw ParameterError("checkpoint: corrupt pair contacts");
    t.pair_cold_on_ = on == 1;
    r.vec(t.pair_cold_);
    r.vec(t.pair_dissip_);
  } else {
    // (every scene kept the cold part, the friction dissipation in it)
    std::vector<PairContactColdV14> old;
    r.vec(old);
    t.pair_cold_on_ = true;
    t.pair_cold_.resize(old.size());
    t.pair_dissip_.resize(old.size());
    for (size_t k = 0; k < old.size(); ++k) {
      t.pair_cold_[k].phys = old[k].phys;
      t.pair_cold_[k].mr = old[k].mr;
      t.pair_cold_[k].dissip_viscous = old[k].dissip_viscous;
      t.pair_dissip_[k] = old[k].dissip_friction;
      // (the hot record's model byte was padding, zero: the law's model, from the phys)
      disk[k].model = static_cast<std::uint8_t>(old[k].phys.model);
    }
  }
  if (t.pair_cold_.size() != (t.pair_cold_on_ ? disk.size() : 0) ||
      t.pair_dissip_.size() != disk.size())
    throw ParameterError("checkpoint: corrupt pair contacts");
  t.pair_cold_version_ = -1;
  t.pair_cold_missing_ = 0;
  for (size_t k = 0; k < disk.size(); ++k) {
    // (the Hertz kernels of the contacts saved as the composed law's: see the save)
    PairContactDisk& c = disk[k];
    if (c.kernel != 0 && c.kernel != kLinearKernel)
      throw ParameterError("checkpoint: corrupt pair contacts");
    std::uint8_t kernel = kComposedKernel;
    if (t.pair_cold_on_) {
      kernel = pair_kernel(t.pair_cold_[k].phys);
    } else if (c.model == static_cast<std::uint8_t>(ContactModel::HertzMindlin)) {
      kernel = kHertzKernel;  // (without the cold part only the short kernels run)
    }
    if (c.kernel == 0 && (kernel == kHertzKernel || kernel == kHertzDampedKernel))
      c.kernel = kernel;
  }
  r.vec(t.pair_out_);
  // (format 15: none where the scene has no cold part, whose forces are the hot records')
  if (t.pair_out_.size() != disk.size() && !(version >= 15 && t.pair_out_.empty()))
    throw ParameterError("checkpoint: corrupt pair contacts");
  t.pair_direct_ = t.pair_out_.size() != disk.size();
  t.release_pair_cross();  // (made again by a threaded direct pass)
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
  if constexpr (kGeogridBuilt) t.index_grid_contacts();  // (the step's packed copy follows)
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
  {
    std::vector<std::pair<int, int>> cand;
    r.vec(cand);
    r.vec(t.candidate_images_);
    bool ok = t.candidate_images_.size() == cand.size();
    for (size_t q = 0; q < cand.size() && ok; ++q)
      ok = cand[q].first >= 0 && cand[q].first < cand[q].second &&
           static_cast<size_t>(cand[q].second) < nb &&
           (q == 0 || cand[q - 1] < cand[q]);
    if (!ok) throw ParameterError("checkpoint: corrupt broad-phase candidates");
    if (cand.empty()) {  // (no build yet, or none found: no rows)
      t.cand_off_.clear();
      t.cand_j_.clear();
    } else {
      t.set_candidate_rows(cand, static_cast<int>(nb));
    }
    if (std::all_of(t.candidate_images_.begin(), t.candidate_images_.end(),
                    [](std::uint8_t c) { return c == kNoShift; }))
      std::vector<std::uint8_t>().swap(t.candidate_images_);
    // The pair records are the candidates', one each in their order, in rows pair_ioff_.
    bool pairs_ok = disk.size() == cand.size() && t.pair_ioff_.size() <= nb + 1 &&
                    (!cand.empty() || t.pair_ioff_.empty() || t.pair_ioff_.back() == 0);
    for (size_t q = 0; q < cand.size() && pairs_ok; ++q)
      pairs_ok = disk[q].i == cand[q].first && disk[q].j == cand[q].second &&
                 static_cast<size_t>(cand[q].first) + 1 < t.pair_ioff_.size() &&
                 t.pair_ioff_[cand[q].first] <= static_cast<int>(q) &&
                 static_cast<int>(q) < t.pair_ioff_[cand[q].first + 1];
    if (!pairs_ok) throw ParameterError("checkpoint: corrupt pair contacts");
    t.compact_pairs(disk);
    std::vector<int>().swap(t.cand_off_);  // (the rows are pair_ioff_: Scene::rebuild)
  }
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
  if (t.track_energy_ && (t.bodies_.ke.size() != t.bodies_.pos.size() ||
                          t.clumps_.ke.size() != t.clumps_.pos.size()))
    throw ParameterError("checkpoint: corrupt energy accumulators (energy tracked, not kept)");
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
  if (version >= 14) {
    r.vec(t.cylinder_walls_);
    r.vec(t.cylinder_contacts_);
    r.vec(t.cyl_adj_off_);
    r.vec(t.cyl_adj_);
    for (const CylinderWall& c : t.cylinder_walls_)
      if (!(c.radius > 0 && std::abs(c.axis.norm() - 1) < 1e-9 && c.hi > c.lo &&
            c.material >= 0 && c.material < static_cast<int>(t.materials_.size())))
        throw ParameterError("checkpoint: corrupt cylindrical walls");
    for (const WallContact& c : t.cylinder_contacts_)
      if (c.body < 0 || static_cast<size_t>(c.body) >= nb || c.wall < 0 ||
          static_cast<size_t>(c.wall) >= t.cylinder_walls_.size())
        throw ParameterError("checkpoint: corrupt cylinder contacts");
    const size_t nadj = t.cyl_adj_.size();
    bool adj_ok = t.cyl_adj_off_.empty() || t.cyl_adj_off_.size() == nb + 1;
    for (int e : t.cyl_adj_off_) adj_ok = adj_ok && e >= 0 && static_cast<size_t>(e) <= nadj;
    for (int e : t.cyl_adj_) adj_ok = adj_ok && e >= 0 && static_cast<size_t>(e) < t.cylinder_contacts_.size();
    if (!adj_ok) throw ParameterError("checkpoint: corrupt cylinder contacts");
    r.vec(t.mesh_walls_);
    r.vec(t.mesh_vertices_);
    r.vec(t.mesh_tris_);
    r.vec(t.mesh_contacts_);
    r.vec(t.mesh_cand_off_);
    r.vec(t.mesh_cand_tri_);
    r.vec(t.mesh_adj_off_);
    r.vec(t.mesh_adj_);
    r.get(t.mesh_dropped_);
    bool mesh_ok = t.mesh_cand_off_.empty() ||
                   (t.mesh_cand_off_.size() == t.mesh_contacts_.size() + 1 &&
                    static_cast<size_t>(t.mesh_cand_off_.back()) == t.mesh_cand_tri_.size());
    for (const MeshWall& m : t.mesh_walls_)
      mesh_ok = mesh_ok && m.vert_off >= 0 && m.nvert >= 3 && m.tri_off >= 0 && m.ntri >= 1 &&
                static_cast<size_t>(m.vert_off + m.nvert) <= t.mesh_vertices_.size() &&
                static_cast<size_t>(m.tri_off + m.ntri) <= t.mesh_tris_.size() &&
                m.material >= 0 && m.material < static_cast<int>(t.materials_.size());
    for (const MeshContact& c : t.mesh_contacts_)
      mesh_ok = mesh_ok && c.body >= 0 && static_cast<size_t>(c.body) < nb && c.wall >= 0 &&
                static_cast<size_t>(c.wall) < t.mesh_walls_.size();
    for (int e : t.mesh_cand_tri_)
      mesh_ok = mesh_ok && e >= 0 && static_cast<size_t>(e) < t.mesh_tris_.size();
    for (const auto& tri : t.mesh_tris_)
      for (int i : tri) mesh_ok = mesh_ok && i >= 0;
    for (int e : t.mesh_adj_)
      mesh_ok = mesh_ok && e >= 0 && static_cast<size_t>(e) < t.mesh_contacts_.size();
    if (!(t.mesh_adj_off_.empty() || t.mesh_adj_off_.size() == nb + 1)) mesh_ok = false;
    if (!mesh_ok) throw ParameterError("checkpoint: corrupt mesh walls");
    // The triangles' normals (not saved): this scene's, computed when its meshes were added,
    // where they are the loaded mesh's (a mesh moves by translation: the saved run computed
    // the same from the same file, to the bit); else computed from the loaded vertices.
    t.frame_mesh_triangles(0);
    bool same_frames = s.mesh_tri_n_.size() == t.mesh_tri_n_.size();
    for (size_t k = 0; k < t.mesh_tri_n_.size() && same_frames; ++k) {
      same_frames = (s.mesh_tri_n_[k] - t.mesh_tri_n_[k]).norm() <= 1e-9;
      for (int i = 0; i < 3 && same_frames; ++i)
        same_frames = (s.mesh_tri_e_[k][i] - t.mesh_tri_e_[k][i]).norm() <= 1e-9;
    }
    if (same_frames) {
      t.mesh_tri_n_ = s.mesh_tri_n_;
      t.mesh_tri_e_ = s.mesh_tri_e_;
    }
    t.index_mesh_contacts();
  }
  const auto nc = r.get<std::uint64_t>();
  if (nc != s.controllers_.size())
    throw ParameterError("checkpoint: the saved scene had " + std::to_string(nc) +
                         " controllers, this scene has " + std::to_string(s.controllers_.size()) +
                         "; add the same controllers, in the same order, before loading");
  struct Ctl {
    std::vector<char> kind;
    int period;
    bool enabled;
    bool stateful;
    std::vector<Real> state;
  };
  std::vector<Ctl> ctl(nc);
  for (std::uint64_t k = 0; k < nc; ++k) {
    if (version >= 12) r.vec(ctl[k].kind);
    r.get(ctl[k].period);
    r.get(ctl[k].enabled);
    ctl[k].stateful = r.get<std::uint8_t>() != 0;
    if (ctl[k].stateful) r.vec(ctl[k].state);
    const Controller& here = *s.controllers_[k];
    const bool same = version >= 12
                          ? ctl[k].kind == controller_kind(here)
                          : (dynamic_cast<const StatefulController*>(&here) != nullptr) ==
                                ctl[k].stateful;
    if (!same)
      throw ParameterError(
          "checkpoint: controller " + std::to_string(k) + " is a " +
          kind_name(controller_kind(here)) + " in this scene, " +
          (version >= 12 ? "a " + kind_name(ctl[k].kind) : std::string("of another kind")) +
          " in the saved one; add the same controllers, in the same order, before loading");
  }
  if (r.at != blob.size())
    throw ParameterError("checkpoint: " + std::to_string(blob.size() - r.at) +
                         " unexpected trailing bytes");
  if (!kGeogridBuilt && (t.num_nodes_ > 0 || !t.links_.empty()))
    throw ParameterError("checkpoint: the saved scene has a geogrid; this build has no geogrid "
                         "support (built with -DCPP_DEM_GEOGRID=OFF)");
  if (!replace) check_same_scene(s, t);
  check_values(t);
  Scene probes;  // scratch: the periods go through Scene::add_controller's check
  for (std::uint64_t k = 0; k < nc; ++k)
    try {
      auto probe = std::make_shared<PeriodProbe>();
      probe->period = ctl[k].period;
      probes.add_controller(probe);
    } catch (const ParameterError& e) {
      throw ParameterError("checkpoint: stored controller " + std::to_string(k) + ": " +
                           e.what() + " (the API refuses this value; the file is corrupt or "
                           "was edited)");
    }
  // The controllers' states last, all or none: a state its controller refuses puts back the
  // ones loaded before it.
  std::vector<std::vector<Real>> before(nc);
  std::uint64_t k = 0;
  try {
    for (; k < nc; ++k) {
      if (!ctl[k].stateful) continue;
      auto* st = dynamic_cast<StatefulController*>(s.controllers_[k].get());
      before[k] = st->save_state();
      st->load_state(ctl[k].state);
    }
  } catch (const ParameterError& e) {
    for (std::uint64_t j = 0; j < k; ++j)
      if (ctl[j].stateful)
        dynamic_cast<StatefulController*>(s.controllers_[j].get())->load_state(before[j]);
    throw ParameterError("checkpoint: stored controller " + std::to_string(k) + ": " + e.what());
  }
  for (std::uint64_t j = 0; j < nc; ++j) {
    s.controllers_[j]->period = ctl[j].period;
    s.controllers_[j]->enabled = ctl[j].enabled;
  }
  t.controllers_ = std::move(s.controllers_);
  // Arrays made at their first use are dropped where they hold what their absence stands
  // for: no body wrapped, every inertia factor 1, no radius changed since the build.
  BodyStore& tb = t.bodies_;
  if (std::all_of(tb.image.begin(), tb.image.end(),
                  [](const std::array<int, 3>& a) { return a[0] == 0 && a[1] == 0 && a[2] == 0; }))
    std::vector<std::array<int, 3>>().swap(tb.image);
  if (std::all_of(tb.inertia_scale.begin(), tb.inertia_scale.end(), [](Real f) { return f == 1.0; }))
    std::vector<Real>().swap(tb.inertia_scale);
  if (t.radius_at_build_.size() <= tb.radius.size() &&
      std::equal(t.radius_at_build_.begin(), t.radius_at_build_.end(), tb.radius.begin()))
    std::vector<Real>().swap(t.radius_at_build_);
  // The cell grid is scratch of the broad phase (rebuilt from scratch at every build).
  s = std::move(t);
}

}  // namespace cpp_dem
