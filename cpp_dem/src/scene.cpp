#include "cpp_dem/scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>
#include <type_traits>

#ifdef _OPENMP
#include <omp.h>
#endif

// V4 below is a 32-byte vector type; GCC notes that passing one by value has an ABI that
// depends on AVX. Its helpers are always inlined and no V4 crosses a function boundary.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace cpp_dem {

namespace {
constexpr Real kInf = std::numeric_limits<Real>::infinity();
/// Below this many items a loop runs serially: a parallel region costs more than it saves
/// (measured: at 1000 spheres a threshold of 1000 cost a third of the 2-thread speed).
/// (Results do not depend on it: every item is computed independently.)
constexpr long kParallelMin = 128;

Real sphere_mass(Real density, Real r) { return density * 4.0 / 3.0 * M_PI * r * r * r; }

#define ALWAYS_INLINE __attribute__((always_inline)) inline

/// 3-vectors in 4-lane registers (lane 3 zero) for the pair pass: one instruction per
/// operation where Eigen's Vector3d takes a 2-lane packet plus a scalar. GCC lowers the type
/// to the widest registers of each clone (two SSE2 registers in the baseline one).
typedef double V4 __attribute__((vector_size(32)));
typedef long long V4i __attribute__((vector_size(32)));
ALWAYS_INLINE V4 v4(const Vec3& a) { return V4{a[0], a[1], a[2], 0.0}; }
ALWAYS_INLINE Vec3 vec3(const V4& a) { return Vec3(a[0], a[1], a[2]); }
ALWAYS_INLINE void store3(Vec3& a, const V4& v) {
  a[0] = v[0];
  a[1] = v[1];
  a[2] = v[2];
}
/// Four doubles from / to memory laid out for it (a padded record: PairOutput, pair_fi_).
ALWAYS_INLINE V4 load4(const Real* p) {
  V4 r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
ALWAYS_INLINE void store4(Real* p, const V4& v) {
  std::memcpy(p, &v, sizeof v);
}
/// v with lane 3 set to zero, and v with lane 3 set to s.
ALWAYS_INLINE V4 zero_lane3(const V4& v) {
  return __builtin_shuffle(v, V4{}, V4i{0, 1, 2, 4});
}
ALWAYS_INLINE V4 with_lane3(const V4& v, Real s) {
  return __builtin_shuffle(v, V4{s, s, s, s}, V4i{0, 1, 2, 7});
}
ALWAYS_INLINE Real dot3(const V4& a, const V4& b) {
  const V4 p = a * b;
  return (p[0] + p[1]) + p[2];
}
ALWAYS_INLINE V4 cross3(const V4& a, const V4& b) {
  const V4i yzx = {1, 2, 0, 3}, zxy = {2, 0, 1, 3};
  return __builtin_shuffle(a, yzx) * __builtin_shuffle(b, zxy) -
         __builtin_shuffle(a, zxy) * __builtin_shuffle(b, yzx);
}

/// The 3-vector operations of the pair pass and the reduction, in two forms with the same
/// arithmetic. WideOps keeps a 3-vector in one 4-lane register (lane 3 zero), which pays where
/// the CPU has 256-bit registers (AVX2, AVX-512). NarrowOps is Eigen's Vector3d: without AVX,
/// GCC lowers the 4-lane type through the stack and the wide pass ran 5x slower (measured
/// with CPP_DEM_CLONES=OFF). The hot functions pick one per call (use_wide_ops()).
struct WideOps {
  using V = V4;
  ALWAYS_INLINE static V zero() { return V4{}; }
  ALWAYS_INLINE static V unit_z() { return V4{0, 0, 1, 0}; }
  ALWAYS_INLINE static V load(const Vec3& a) { return v4(a); }
  /// Three doubles and a zero pad (PairOutput, pair_fi_).
  ALWAYS_INLINE static V load_padded(const Real* p) { return load4(p); }
  /// Three doubles followed by another value (PairContact's fs, overlap and normal, fn).
  ALWAYS_INLINE static V load_head(const Real* p) { return zero_lane3(load4(p)); }
  ALWAYS_INLINE static void store(Vec3& a, const V& v) { store3(a, v); }
  ALWAYS_INLINE static void store_padded(Real* p, const V& v) { store4(p, v); }  // lane 3: 0
  ALWAYS_INLINE static void store_with(Real* p, const V& v, Real s) {
    store4(p, with_lane3(v, s));
  }
  ALWAYS_INLINE static Real dot(const V& a, const V& b) { return dot3(a, b); }
  ALWAYS_INLINE static V cross(const V& a, const V& b) { return cross3(a, b); }
  ALWAYS_INLINE static Vec3 vec(const V& a) { return vec3(a); }
};
struct NarrowOps {
  using V = Vec3;
  ALWAYS_INLINE static V zero() { return Vec3::Zero(); }
  ALWAYS_INLINE static V unit_z() { return Vec3::UnitZ(); }
  ALWAYS_INLINE static V load(const Vec3& a) { return a; }
  ALWAYS_INLINE static V load_padded(const Real* p) { return Vec3(p[0], p[1], p[2]); }
  ALWAYS_INLINE static V load_head(const Real* p) { return Vec3(p[0], p[1], p[2]); }
  ALWAYS_INLINE static void store(Vec3& a, const V& v) { a = v; }
  ALWAYS_INLINE static void store_padded(Real* p, const V& v) {  // the pad stays zero
    p[0] = v[0];
    p[1] = v[1];
    p[2] = v[2];
  }
  ALWAYS_INLINE static void store_with(Real* p, const V& v, Real s) {
    store_padded(p, v);
    p[3] = s;
  }
  ALWAYS_INLINE static Real dot(const V& a, const V& b) { return a.dot(b); }
  ALWAYS_INLINE static V cross(const V& a, const V& b) { return a.cross(b); }
  ALWAYS_INLINE static Vec3 vec(const V& a) { return a; }
};

/// Whether the hot loops run WideOps: in the x86-64-v3/v4 variants of a multiversioned build
/// (the loader picked one, so the CPU has AVX2), or in a build for AVX; never with the
/// environment variable CPP_DEM_NARROW=1 set when the module loads (tests run both forms).
inline bool use_wide_ops() {
  static const bool narrow_asked = [] {
    const char* v = std::getenv("CPP_DEM_NARROW");
    return v != nullptr && std::string(v) == "1";
  }();
#if defined(CPP_DEM_CLONES)
  static const bool wide = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return wide && !narrow_asked;
#elif defined(__AVX__)
  return !narrow_asked;
#else
  return false;
#endif
}

// The 4-double loads and stores of the pair pass rely on these layouts.
static_assert(sizeof(Vec3) == 3 * sizeof(Real), "Vec3 must be three packed doubles");
static_assert(sizeof(Quat) == 4 * sizeof(Real), "Quat must be four packed doubles (x, y, z, w)");
static_assert(offsetof(PairContact, overlap) == offsetof(PairContact, fs) + sizeof(Vec3) &&
                  offsetof(PairContact, fn) == offsetof(PairContact, normal) + sizeof(Vec3),
              "PairContact: fs, overlap and normal, fn must be adjacent");
static_assert(offsetof(PairOutput, pad_force) == offsetof(PairOutput, force) + sizeof(Vec3) &&
                  offsetof(PairOutput, pad_torque) == offsetof(PairOutput, torque_j) + sizeof(Vec3),
              "PairOutput: each vector must be followed by its padding");

/// Bodies per block of the integration pass; the wall pass visits its contacts by the same
/// blocks, and both give thread t the blocks thread_share(nblocks, t, nt), so a thread's wall
/// contacts belong to the bodies it integrates (their records stay in its cache).
constexpr int kBodyBlock = 64;
inline std::pair<long, long> thread_share(long total, long t, long nt) {
  return {t * total / nt, (t + 1) * total / nt};
}
/// This thread's number and the number of threads in the team.
inline std::pair<long, long> thread_and_team() {
#ifdef _OPENMP
  return {omp_get_thread_num(), omp_get_num_threads()};
#else
  return {0, 1};
#endif
}

/// Steps between two renormalisations of the orientation quaternions (rotate_orientation).
constexpr long kRenormalizePeriod = 64;

/// The contact's law is linear without viscous damping and rolling resistance: the pair and
/// wall passes run their short kernels, which are apply_law with these parts off.
bool short_kernel_applies(const ContactPhys& p) {
  return p.model == ContactModel::Linear && !(p.beta_n > 0) && !(p.beta_s > 0) && !(p.kr > 0);
}

template <class T>
void require_size(const std::vector<T>& v, size_t n, const char* field) {
  if (v.size() != n)
    throw ParameterError(std::string(field) + ": has " + std::to_string(v.size()) +
                         " rows, the scene has " + std::to_string(n) + " bodies");
}
}  // namespace

Scene::Scene() = default;

// ---- materials, bodies, walls ---------------------------------------------------------------

int Scene::add_material(const Material& m) {
  m.validate();
  materials_.push_back(m);
  ++phys_version_;
  return static_cast<int>(materials_.size()) - 1;
}

const Material& Scene::material(int id) const {
  if (id < 0 || id >= num_materials())
    throw ParameterError("material=" + std::to_string(id) + ": no such material (the scene has " +
                         std::to_string(num_materials()) + ")");
  return materials_[id];
}

int Scene::add_spheres(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                       int material) {
  const Material& mat = this->material(material);
  if (pos.size() != radius.size())
    throw ParameterError("radius: has " + std::to_string(radius.size()) +
                         " values for " + std::to_string(pos.size()) + " centres");
  for (size_t k = 0; k < pos.size(); ++k) {
    require(std::isfinite(radius[k]) && radius[k] > 0, "radius", radius[k], "must be > 0 (m)");
    if (!pos[k].allFinite())
      throw ParameterError("position of sphere " + std::to_string(k) + ": must be finite");
  }
  const int first = num_bodies();
  for (size_t k = 0; k < pos.size(); ++k) {
    const Real r = radius[k];
    const Real m = sphere_mass(mat.density, r);
    push_body(pos[k], r, m, 0.4 * m * r * r, material, 0);
  }
  dirty_ = true;
  return first;
}

void Scene::push_body(const Vec3& x, Real radius, Real mass, Real inertia, int material,
                      std::uint8_t kind) {
  if (!id_of_slot_.empty()) {
    // A new body is stored at the end, under its own id.
    id_of_slot_.push_back(num_bodies());
    slot_of_id_.push_back(num_bodies());
  }
  pos_.push_back(x);
  vel_.push_back(Vec3::Zero());
  angvel_.push_back(Vec3::Zero());
  force_.push_back(Vec3::Zero());
  torque_.push_back(Vec3::Zero());
  ext_force_.push_back(Vec3::Zero());
  ext_torque_.push_back(Vec3::Zero());
  ori_.push_back(Quat::Identity());
  radius_.push_back(radius);
  mass_.push_back(mass);
  inertia_.push_back(inertia);
  body_mat_.push_back(material);
  blocked_.push_back(DOF_NONE);
  kind_.push_back(kind);
  ke_.push_back(0);
  damp_dissip_.push_back(0);
  ext_work_.push_back(0);
  pos_at_energy_reset_.push_back(x);
}

int Scene::add_wall(int axis, Real position, int sense, int material) {
  if (axis < 0 || axis > 2)
    throw ParameterError("axis=" + std::to_string(axis) + ": must be 0 (x), 1 (y) or 2 (z)");
  if (sense != 1 && sense != -1)
    throw ParameterError("sense=" + std::to_string(sense) +
                         ": must be +1 (spheres on the +axis side) or -1");
  require(std::isfinite(position), "position", position, "must be finite (m)");
  this->material(material);
  Wall w;
  w.axis = axis;
  w.sense = sense;
  w.position = position;
  w.material = material;
  walls_.push_back(w);
  dirty_ = true;
  return num_walls() - 1;
}

Wall& Scene::wall(int id) {
  if (id < 0 || id >= num_walls())
    throw ParameterError("wall=" + std::to_string(id) + ": no such wall (the scene has " +
                         std::to_string(num_walls()) + ")");
  return walls_[id];
}
const Wall& Scene::wall(int id) const { return const_cast<Scene*>(this)->wall(id); }

void Scene::set_positions(const std::vector<Vec3>& v) {
  require_size(v, pos_.size(), "positions");
  for (const auto& x : v)
    if (!x.allFinite()) throw ParameterError("positions: must be finite (m)");
  pos_ = v;
  dirty_ = true;
}
void Scene::set_velocities(const std::vector<Vec3>& v) {
  require_size(v, pos_.size(), "velocities");
  vel_ = v;
}
void Scene::set_angular_velocities(const std::vector<Vec3>& v) {
  require_size(v, pos_.size(), "angular_velocities");
  angvel_ = v;
}
void Scene::set_radii(const std::vector<Real>& r) {
  require_size(r, pos_.size(), "radii");
  for (Real x : r) require(std::isfinite(x) && x > 0, "radius", x, "must be > 0 (m)");
  for (size_t b = 0; b < r.size(); ++b) {
    if (kind_[b] != 0) {
      // Grid nodes keep their lumped mass; their radius is the geogrid's R_c.
      if (r[b] != radius_[b])
        throw ParameterError("radius[" + std::to_string(id_of(b)) + "]=" + std::to_string(r[b]) +
                             ": body " + std::to_string(id_of(b)) +
                             " is a grid node; its radius (the geogrid's R_c) cannot change");
      continue;
    }
    radius_[b] = r[b];
    mass_[b] = sphere_mass(materials_[body_mat_[b]].density, r[b]);
    inertia_[b] = 0.4 * mass_[b] * r[b] * r[b];
  }
  disp_valid_ = false;  // grown radii count in the broad phase's check
  ++phys_version_;
}
void Scene::set_blocked(int body, std::uint8_t mask) {
  check_body(body);
  if (mask > DOF_ALL)
    throw ParameterError("blocked=" + std::to_string(mask) + ": must be a mask of x y z rx ry rz");
  blocked_[slot_of(body)] = mask;
}
void Scene::set_external_forces(const std::vector<Vec3>& f) {
  require_size(f, pos_.size(), "external_forces");
  ext_force_ = f;
}
void Scene::set_external_torques(const std::vector<Vec3>& t) {
  require_size(t, pos_.size(), "external_torques");
  ext_torque_ = t;
}
void Scene::set_body_material(int body, int material) {
  check_body(body);
  this->material(material);
  body = slot_of(body);
  body_mat_[body] = material;
  mass_[body] = sphere_mass(materials_[material].density, radius_[body]);
  inertia_[body] = 0.4 * mass_[body] * radius_[body] * radius_[body];
  ++phys_version_;
}
void Scene::set_mass_inertia(int body, Real mass, Real inertia) {
  check_body(body);
  require(std::isfinite(mass) && mass > 0, "mass", mass, "must be > 0 (kg)");
  require(std::isfinite(inertia) && inertia > 0, "inertia", inertia, "must be > 0 (kg m^2)");
  body = slot_of(body);
  mass_[body] = mass;
  inertia_[body] = inertia;
  ++phys_version_;
}
void Scene::check_body(int b) const {
  if (b < 0 || b >= num_bodies())
    throw ParameterError("body=" + std::to_string(b) + ": no such body (the scene has " +
                         std::to_string(num_bodies()) + ")");
}

// ---- parameters -----------------------------------------------------------------------------

void Scene::set_dt(Real dt) {
  require(std::isfinite(dt) && dt > 0, "dt", dt, "must be > 0 (s)");
  dt_ = dt;
}
void Scene::set_gravity(const Vec3& g) {
  if (!g.allFinite()) throw ParameterError("gravity: must be finite (m/s^2)");
  gravity_ = g;
}
void Scene::set_local_damping(Real d) {
  require(std::isfinite(d) && d >= 0 && d < 1, "local_damping", d, "must be in [0, 1)");
  local_damping_ = d;
}
void Scene::set_verlet_margin(Real m) {
  require(std::isfinite(m), "verlet_margin", m, "must be finite (m); <= 0 selects the default");
  margin_ = m;
  dirty_ = true;
}
void Scene::set_max_overlap_ratio(Real r) {
  require(std::isfinite(r) && r > 0 && r <= 2, "max_overlap_ratio", r, "must be in (0, 2]");
  max_overlap_ratio_ = r;
}
void Scene::set_track_energy(bool on) {
  if (on && !track_energy_) {
    track_energy_ = true;
    reset_energy();
  }
  track_energy_ = on;
}
void Scene::set_auto_timestep(Real safety, int period) {
  require(std::isfinite(safety) && safety > 0 && safety <= 1, "timestep_safety", safety,
          "must be in (0, 1]: above 1 the step exceeds the critical estimate and leapfrog can "
          "go unstable");
  if (period < 0)
    throw ParameterError("timestep_period=" + std::to_string(period) + ": must be >= 0 (0 = off)");
  ts_safety_ = safety;
  ts_period_ = period;
  const Real est = critical_dt();
  if (period > 0 && std::isfinite(est)) set_dt(safety * est);
}

void Scene::set_dt_check_period(int period) {
  if (period < 0)
    throw ParameterError("dt_check_period=" + std::to_string(period) + ": must be >= 0 (0 = off)");
  dt_check_period_ = period;
}

Real Scene::default_margin() const {
  if (radius_.empty()) return 0;
  Real s = 0;
  for (Real r : radius_) s += r;
  return 0.2 * s / radius_.size();
}

// ---- broad phase ----------------------------------------------------------------------------

bool Scene::need_rebuild() const {
  if (dirty_) return true;
  const Real half = 0.5 * (margin_ > 0 ? margin_ : default_margin());
  for (const Wall& w : walls_)
    if (w.moved_since_build > half) return true;
  // The last integration pass measured the displacements already (nothing moved since).
  if (disp_valid_) return max_disp_ > half;
  const int n = num_bodies();
  Real worst = 0;
#pragma omp parallel for reduction(max : worst) schedule(static) if (n > kParallelMin)
  for (int b = 0; b < n; ++b) {
    const Real d = (pos_[b] - pos_at_build_[b]).norm() + std::max(0.0, radius_[b] - radius_at_build_[b]);
    worst = std::max(worst, d);
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
    if (kind_[b] != 0) continue;
    if (!pos_[b].allFinite()) return;
    slots.push_back(b);
    lo = lo.cwiseMin(pos_[b]);
    hi = hi.cwiseMax(pos_[b]);
    rsum += radius_[b];
  }
  if (slots.size() < 2) return;
  // Cells one mean diameter wide (at most 2^21 per axis), in Morton (Z) order: a body's
  // neighbours are mostly within a few hundred slots of it.
  const Real cell = std::max(2.0 * rsum / static_cast<Real>(slots.size()),
                             (hi - lo).maxCoeff() / 2097151.0);
  if (!(cell > 0)) return;
  std::vector<std::pair<std::uint64_t, int>> key(slots.size());
  for (size_t k = 0; k < slots.size(); ++k) {
    const Vec3 c = (pos_[slots[k]] - lo) / cell;
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
  const auto permute = [&](auto& v) {
    if (static_cast<int>(v.size()) != n) return;  // not in use (energy arrays)
    auto old = v;
    for (int b = 0; b < n; ++b) v[b] = old[perm[b]];
  };
  permute(pos_);
  permute(vel_);
  permute(angvel_);
  permute(force_);
  permute(torque_);
  permute(ext_force_);
  permute(ext_torque_);
  permute(ori_);
  permute(radius_);
  permute(mass_);
  permute(inertia_);
  permute(body_mat_);
  permute(blocked_);
  permute(kind_);
  permute(ke_);
  permute(damp_dissip_);
  permute(ext_work_);
  permute(pos_at_energy_reset_);
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
  // Spatial order while no contact (and so no contact history) exists yet.
  if (spatial_sort_ && pairs_.empty() && wall_contacts_.empty() && grid_contacts_.empty())
    sort_bodies_spatially();
  const Real margin = margin_ > 0 ? margin_ : default_margin();
  const int n = num_bodies();
  grid_.build(pos_, radius_, kind_, margin);
  grid_.find_pairs(pos_, radius_, margin, candidates_);
  // Merge the new candidate list with the old contacts, keeping history (both sorted).
  std::vector<PairContact> next;
  std::vector<PairContactCold> next_cold;
  next.reserve(candidates_.size());
  next_cold.reserve(candidates_.size());
  size_t k = 0;
  for (const auto& ij : candidates_) {
    while (k < pairs_.size() && std::make_pair(pairs_[k].i, pairs_[k].j) < ij) {
      drop_dissipation(pair_cold_[k]);
      ++k;
    }
    if (k < pairs_.size() && pairs_[k].i == ij.first && pairs_[k].j == ij.second) {
      next.push_back(pairs_[k]);
      next_cold.push_back(pair_cold_[k++]);
    } else {
      PairContact c;
      c.i = ij.first;
      c.j = ij.second;
      next.push_back(c);
      next_cold.emplace_back();
    }
  }
  for (; k < pairs_.size(); ++k) {
    drop_dissipation(pair_cold_[k]);
  }
  pairs_.swap(next);
  pair_cold_.swap(next_cold);
  pair_out_.assign(pairs_.size(), PairOutput());
  // Sphere–wall candidates: signed distance to the plane below r + margin, and the centre
  // not beyond the plane by more than r (one-sided walls ignore what is behind them).
  std::vector<WallContact> wnext;
  size_t kw = 0;
  for (int b = 0; b < n; ++b) {
    if (kind_[b] != 0 && !grid_wall_contacts_) continue;  // grid nodes: only if asked for
    for (int w = 0; w < num_walls(); ++w) {
      const Wall& wl = walls_[w];
      const Real s = wl.sense * (pos_[b][wl.axis] - wl.position);
      if (!(s < radius_[b] + margin && s > -radius_[b])) continue;
      while (kw < wall_contacts_.size() &&
             std::make_pair(wall_contacts_[kw].body, wall_contacts_[kw].wall) < std::make_pair(b, w)) {
        drop_dissipation(wall_contacts_[kw].state);
        ++kw;
      }
      if (kw < wall_contacts_.size() && wall_contacts_[kw].body == b && wall_contacts_[kw].wall == w) {
        wnext.push_back(wall_contacts_[kw++]);
      } else {
        WallContact c;
        c.body = b;
        c.wall = w;
        wnext.push_back(c);
      }
    }
  }
  for (; kw < wall_contacts_.size(); ++kw) {
    drop_dissipation(wall_contacts_[kw].state);
  }
  wall_contacts_.swap(wnext);
  // Adjacency (CSR) in contact order, so reductions into bodies have a fixed order.
  pair_jadj_off_.assign(n + 1, 0);
  pair_ioff_.assign(n + 1, 0);
  for (const auto& c : pairs_) {
    pair_ioff_[c.i + 1]++;
    pair_jadj_off_[c.j + 1]++;
  }
  for (int b = 0; b < n; ++b) {
    pair_ioff_[b + 1] += pair_ioff_[b];
    pair_jadj_off_[b + 1] += pair_jadj_off_[b];
  }
  pair_jslot_.resize(pairs_.size());
  {
    std::vector<int> fill(pair_jadj_off_.begin(), pair_jadj_off_.end() - 1);
    for (int c = 0; c < static_cast<int>(pairs_.size()); ++c)
      pair_jslot_[c] = fill[pairs_[c].j]++;
  }
  wall_adj_off_.assign(n + 1, 0);
  for (const auto& c : wall_contacts_) wall_adj_off_[c.body + 1]++;
  for (int b = 0; b < n; ++b) wall_adj_off_[b + 1] += wall_adj_off_[b];
  wall_adj_.resize(wall_adj_off_[n]);
  {
    std::vector<int> fill(wall_adj_off_.begin(), wall_adj_off_.end() - 1);
    for (int c = 0; c < static_cast<int>(wall_contacts_.size()); ++c)
      wall_adj_[fill[wall_contacts_[c].body]++] = c;
  }
  if constexpr (kGeogridBuilt) {
    if (has_grid()) rebuild_grid_contacts(margin);
  }
  pos_at_build_ = pos_;
  radius_at_build_ = radius_;
  for (Wall& w : walls_) w.moved_since_build = 0;
  dirty_ = false;
  ++builds_;
}

ColliderStats Scene::collider_stats() const {
  ColliderStats s;
  s.builds = builds_;
  s.pair_candidates = static_cast<long>(pairs_.size());
  s.wall_candidates = static_cast<long>(wall_contacts_.size());
  s.grid_candidates = static_cast<long>(grid_contacts_.size());
  return s;
}

// ---- contacts -------------------------------------------------------------------------------

void Scene::update_phys(PairContact& c, PairContactCold& cold) const {
  const ContactPhys& p = cold.phys =
      mix_materials(materials_[body_mat_[c.i]], materials_[body_mat_[c.j]], radius_[c.i],
                    radius_[c.j], mass_[c.i], mass_[c.j]);
  c.kn = p.kn;
  c.ks = p.ks;
  c.tan_phi = p.tan_phi;
  c.simple = short_kernel_applies(p);
  c.phys_version = phys_version_;
}

void Scene::update_phys(WallContact& c) const {
  // The wall has infinite radius and mass (see mix_materials).
  c.phys = mix_materials(materials_[walls_[c.wall].material], materials_[body_mat_[c.body]],
                         kInf, radius_[c.body], kInf, mass_[c.body]);
  c.simple = short_kernel_applies(c.phys);
  c.phys_version = phys_version_;
}

LawOutput Scene::apply_pair_law(size_t k, const ContactGeometry& g, Real dt) {
  PairContact& c = pairs_[k];
  PairContactCold& cold = pair_cold_[k];
  ContactState s = pair_state(k);
  const LawOutput out = apply_law(cold.phys, g, dt, s);
  c.fs = s.fs;
  c.normal = s.normal;
  c.overlap = s.overlap;
  c.fn = s.fn;
  cold.mr = s.mr;
  cold.dissip_friction = s.dissip_friction;
  cold.dissip_viscous = s.dissip_viscous;
  return out;
}

/// Pair contact k has opened: forget its springs' history (ContactState::clear_history) and
/// its output o.
void Scene::open_pair(long k, PairOutput& o) {
  PairContact& c = pairs_[k];
  c.active = false;
  c.fs.setZero();
  c.normal.setZero();
  c.overlap = 0;
  c.fn = 0;
  pair_cold_[k].mr.setZero();
  o = PairOutput();
}

/// Pair contact k with a law other than the short kernel's: normal n, overlap (m), branch
/// lengths li, lj (m), relative velocity (m/s), sum and difference of the spins (rad/s).
/// Writes j's force and torque into o; returns i's force (N) and torque (N m).
std::pair<Vec3, Vec3> Scene::general_pair(long k, PairOutput& o, const Vec3& n, Real overlap,
                                          Real li, Real lj, const Vec3& rel_vel,
                                          const Vec3& angvel_sum, const Vec3& rel_angvel) {
  const Vec3 b1 = li * n;
  const Vec3 b2 = -lj * n;
  ContactGeometry g;
  g.normal = n;
  g.overlap = overlap;
  g.branch1 = b1;
  g.branch2 = b2;
  g.rel_vel = rel_vel;
  g.angvel_sum = angvel_sum;
  g.rel_angvel = rel_angvel;
  const LawOutput out = apply_pair_law(k, g, dt_);
  o.force = out.force2;
  // Moments, 000 eq (6): tau = (R - delta/2) n x F, plus rolling resistance.
  o.torque_j = b2.cross(out.force2) + out.moment2;
  return {-out.force2, b1.cross(-out.force2) - out.moment2};
}

/// The bodies [first, second) whose contacts fall in thread t's equal share of the contact
/// list (of nt threads): a body owns its contacts with larger slots, so equal body counts
/// would give some threads much more work than others.
std::pair<int, int> Scene::pair_bodies_of_thread(long t, long nt) const {
  const int n = num_bodies();
  const long nc = static_cast<long>(pairs_.size());
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
/// written twice.
void Scene::pair_bodies_narrow(int b0, int b1, long& err_out) {
  using Ops = NarrowOps;
  using V = Ops::V;
  const Ops ops;
  long err = err_out;
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  const int version = phys_version_;
  // Local pointers: the loop's stores of bools could alias the vectors' own pointers, so
  // through the members the compiler reloaded them for every access.
  const Vec3* const pos = pos_.data();
  const Vec3* const vel = vel_.data();
  const Vec3* const angvel = angvel_.data();
  const Real* const radius = radius_.data();
  const int* const ioff = pair_ioff_.data();
  const int* const jslot = pair_jslot_.data();
  PairContact* const pairs = pairs_.data();
  PairOutput* const out_j = pair_out_.data();
  Real* const out_fi = pair_fi_.data()->data();
  Real* const out_ti = pair_ti_.data()->data();
  for (int i = b0; i < b1; ++i) {
    const int k0 = ioff[i], k1 = ioff[i + 1];
    // i's share: -force and torque_i summed over its contacts.
    V fi = ops.zero(), ti = ops.zero();
    if (k0 < k1) {
      const V xi = ops.load(pos[i]), vi = ops.load(vel[i]), wi = ops.load(angvel[i]);
      const Real ri = radius[i];
      for (int k = k0; k < k1; ++k) {
        PairContact& c = pairs[k];
        PairOutput& o = out_j[jslot[k]];
        const int j = c.j;
        const V d = ops.load(pos[j]) - xi;
        const Real dist2 = ops.dot(d, d);
        const Real rj = radius[j];
        const Real rsum = ri + rj;
        if (dist2 >= rsum * rsum) {
          if (c.active) open_pair(k, o);  // the contact opened
          continue;
        }
        const Real dist = std::sqrt(dist2);
        const Real overlap = rsum - dist;
        if (!(overlap <= max_ratio * std::min(ri, rj))) {
          err = std::min(err, static_cast<long>(k));
          continue;
        }
        if (!c.active || c.phys_version != version) update_phys(c, pair_cold_[k]);
        c.active = true;
        const V n = dist > 0 ? V(d * (1.0 / dist)) : ops.unit_z();
        // Contact point in the middle of the overlap: branch vectors l_i n and -l_j n,
        // lengths R - delta/2 (000 eq 6).
        const Real li = ri - 0.5 * overlap, lj = rj - 0.5 * overlap;
        const V wj = ops.load(angvel[j]);
        // v_j + w_j x (-l_j n) - (v_i + w_i x l_i n), with one cross product.
        const V rel_vel = (ops.load(vel[j]) - vi) - ops.cross(lj * wj + li * wi, n);
        if (!c.simple) {
          const auto on_i = general_pair(k, o, ops.vec(n), overlap, li, lj, ops.vec(rel_vel),
                                         ops.vec(wi + wj), ops.vec(wj - wi));
          fi += ops.load(on_i.first);
          ti += ops.load(on_i.second);
          continue;
        }
        // The short kernel: apply_law for a linear law without viscous damping and rolling
        // resistance (000 eqs 1-3), on the hot record.
        const Real fn = c.kn * overlap;
        const Real vn = ops.dot(rel_vel, n);
        const V vt = rel_vel - vn * n;
        V fs = ops.load_head(c.fs.data());  // (fs, overlap) in the record
        const V n_old = ops.load_head(c.normal.data());  // (normal, fn)
        if (ops.dot(n_old, n_old) > 0) {
          // Keep the stored shear force in the tangent plane of the rotated contact frame.
          const V axis = ops.cross(n_old, n);
          const V twist = (0.5 * dt * ops.dot(n, wi + wj)) * n;
          fs -= ops.cross(fs, axis);
          fs -= ops.cross(fs, twist);
          fs -= ops.dot(fs, n) * n;
        }
        fs -= (c.ks * dt) * vt;
        const Real cap = c.tan_phi * (fn > 0 ? fn : 0.0);
        const Real fs2 = ops.dot(fs, fs);
        if (fs2 > cap * cap) {
          const Real norm = std::sqrt(fs2);
          const V capped = norm > 0 ? V(fs * (cap / norm)) : ops.zero();
          if (c.ks > 0) pair_cold_[k].dissip_friction += ops.dot(fs - capped, capped) / c.ks;
          fs = capped;
        }
        ops.store_with(c.fs.data(), fs, overlap);  // fs, overlap
        ops.store_with(c.normal.data(), n, fn);    // normal, fn
        const V f = fn * n + fs;
        ops.store_padded(o.force.data(), f);
        // Moments (000 eq 6): -l_j n x F on j, l_i n x (-F) on i; n x F = n x fs.
        const V nxf = ops.cross(n, fs);
        ops.store_padded(o.torque_j.data(), V(-lj * nxf));
        fi -= f;
        ti -= li * nxf;
      }
    }
    ops.store_padded(out_fi + 4L * i, fi);
    ops.store_padded(out_ti + 4L * i, ti);
  }
  err_out = err;
}

void Scene::compute_pair_forces(long& err_contact) {
  // Body-major: body i and its contacts (i, j), j > i, which are contiguous in pairs_ (sorted
  // by (i, j)). i's position, velocities and radius are loaded once; i's share of the forces
  // and torques is summed in registers, in contact order, into pair_fi_/pair_ti_; j's share
  // goes to its slot in pair_out_, which holds the contacts grouped by j (in contact order
  // within a body), so reduce_and_integrate reads them contiguously. Both orders are fixed,
  // so the sums do not depend on the number of threads. 3-vectors in 4-lane registers
  // (WideOps) where the CPU has AVX2; otherwise the same loop with Eigen's Vector3d.
  const int n = num_bodies();
  pair_fi_.resize(n);
  pair_ti_.resize(n);
  if (!use_wide_ops()) {
    compute_pair_forces_narrow(err_contact);
    return;
  }
  const long nc = static_cast<long>(pairs_.size());
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  const int version = phys_version_;
  long err = std::numeric_limits<long>::max();
  // The loop works through local pointers: its stores of bools could alias the vectors'
  // own pointers, so through the members the compiler reloads them for every access.
  const Vec3* const pos = pos_.data();
  const Vec3* const vel = vel_.data();
  const Vec3* const angvel = angvel_.data();
  const Real* const radius = radius_.data();
  const int* const ioff = pair_ioff_.data();
  const int* const jslot = pair_jslot_.data();
  PairContact* const pairs = pairs_.data();
  PairOutput* const out_j = pair_out_.data();
  Real* const out_fi = pair_fi_.data()->data();
  Real* const out_ti = pair_ti_.data()->data();
#pragma omp parallel reduction(min : err) if (nc > kParallelMin)
  {
    const auto [t, nt] = thread_and_team();
    const auto [b0, b1] = pair_bodies_of_thread(t, nt);
    for (int i = b0; i < b1; ++i) {
      const int k0 = ioff[i], k1 = ioff[i + 1];
      // i's share: -force and torque_i summed over its contacts.
      V4 fi = V4{}, ti = V4{};
      if (k0 < k1) {
        const V4 xi = v4(pos[i]), vi = v4(vel[i]), wi = v4(angvel[i]);
        const Real ri = radius[i];
        for (int k = k0; k < k1; ++k) {
          PairContact& c = pairs[k];
          PairOutput& o = out_j[jslot[k]];
          const int j = c.j;
          const V4 d = v4(pos[j]) - xi;
          const Real dist2 = dot3(d, d);
          const Real rj = radius[j];
          const Real rsum = ri + rj;
          if (dist2 >= rsum * rsum) {
            if (c.active) open_pair(k, o);  // the contact opened
            continue;
          }
          const Real dist = std::sqrt(dist2);
          const Real overlap = rsum - dist;
          if (!(overlap <= max_ratio * std::min(ri, rj))) {
            err = std::min(err, static_cast<long>(k));
            continue;
          }
          if (!c.active || c.phys_version != version) update_phys(c, pair_cold_[k]);
          c.active = true;
          const V4 n = dist > 0 ? d * (1.0 / dist) : V4{0, 0, 1, 0};
          // Contact point in the middle of the overlap: branch vectors l_i n and -l_j n,
          // lengths R - delta/2 (000 eq 6).
          const Real li = ri - 0.5 * overlap, lj = rj - 0.5 * overlap;
          const V4 wj = v4(angvel[j]);
          // v_j + w_j x (-l_j n) - (v_i + w_i x l_i n), with one cross product.
          const V4 rel_vel = (v4(vel[j]) - vi) - cross3(lj * wj + li * wi, n);
          if (!c.simple) {
            const auto on_i = general_pair(k, o, vec3(n), overlap, li, lj, vec3(rel_vel),
                                           vec3(wi + wj), vec3(wj - wi));
            fi += v4(on_i.first);
            ti += v4(on_i.second);
            continue;
          }
          // The short kernel: apply_law for a linear law without viscous damping and rolling
          // resistance (000 eqs 1-3), on the hot record, with 3-vectors in 4-lane registers.
          const Real fn = c.kn * overlap;
          const Real vn = dot3(rel_vel, n);
          const V4 vt = rel_vel - vn * n;
          V4 fs = zero_lane3(load4(c.fs.data()));  // (fs, overlap) in the record
          const V4 n_old = zero_lane3(load4(c.normal.data()));  // (normal, fn)
          if (dot3(n_old, n_old) > 0) {
            // Keep the stored shear force in the tangent plane of the rotated contact frame.
            const V4 axis = cross3(n_old, n);
            const V4 twist = (0.5 * dt * dot3(n, wi + wj)) * n;
            fs -= cross3(fs, axis);
            fs -= cross3(fs, twist);
            fs -= dot3(fs, n) * n;
          }
          fs -= (c.ks * dt) * vt;
          const Real cap = c.tan_phi * (fn > 0 ? fn : 0.0);
          const Real fs2 = dot3(fs, fs);
          if (fs2 > cap * cap) {
            const Real norm = std::sqrt(fs2);
            const V4 capped = norm > 0 ? fs * (cap / norm) : V4{};
            if (c.ks > 0) pair_cold_[k].dissip_friction += dot3(fs - capped, capped) / c.ks;
            fs = capped;
          }
          store4(c.fs.data(), with_lane3(fs, overlap));  // fs, overlap
          store4(c.normal.data(), with_lane3(n, fn));    // normal, fn
          const V4 f = fn * n + fs;
          store4(o.force.data(), f);  // with its padding (lane 3, zero)
          // Moments (000 eq 6): -l_j n x F on j, l_i n x (-F) on i; n x F = n x fs.
          const V4 nxf = cross3(n, fs);
          store4(o.torque_j.data(), -lj * nxf);
          fi -= f;
          ti -= li * nxf;
        }
      }
      store4(out_fi + 4L * i, fi);  // lane 3 is zero: every term had a zero lane 3
      store4(out_ti + 4L * i, ti);
    }
  }
  err_contact = err;
}

void Scene::compute_pair_forces_narrow(long& err_contact) {
  // (compute_pair_forces has sized pair_fi_ and pair_ti_.)
  long err = std::numeric_limits<long>::max();
#pragma omp parallel reduction(min : err) if (static_cast<long>(pairs_.size()) > kParallelMin)
  {
    const auto [t, nt] = thread_and_team();
    const auto bodies = pair_bodies_of_thread(t, nt);
    pair_bodies_narrow(bodies.first, bodies.second, err);
  }
  err_contact = err;
}

namespace {
/// The short kernel of a wall contact: apply_law for a linear law without viscous damping and
/// rolling resistance. The wall's normal n = sense e_AX never turns, so the frame rotation of
/// the stored shear force is the twist about n alone (000 eqs 1-3, 6). v, om: the sphere's
/// velocity (m/s) and spin (rad/s); r: its radius, overlap (m); dt (s).
template <int AX>
__attribute__((always_inline)) inline void wall_short_kernel(WallContact& c, const Wall& w,
                                                             const Vec3& v, const Vec3& om,
                                                             Real r, Real overlap, Real dt) {
  constexpr int A1 = (AX + 1) % 3, A2 = (AX + 2) % 3;
  const Real sense = w.sense;
  const Real ls = (r - 0.5 * overlap) * sense;  // branch vector -l n, times sense
  // Relative velocity at the contact point, v + om x (-l n) - v_wall, tangential part
  // (the AX component drops out).
  const Real v1 = (v[A1] - w.velocity[A1]) - ls * om[A2];
  const Real v2 = (v[A2] - w.velocity[A2]) + ls * om[A1];
  ContactState& st = c.state;
  const Real fn = c.phys.kn * overlap;
  Real f1 = st.fs[A1], f2 = st.fs[A2];
  if (st.normal.squaredNorm() > 0) {
    // fs -= fs x (tw n), tw = dt/2 n . om.
    const Real tws = 0.5 * dt * (sense * om[AX]) * sense;
    const Real g1 = f1 - f2 * tws;
    f2 = f2 + f1 * tws;
    f1 = g1;
  }
  const Real kdt = c.phys.ks * dt;
  f1 -= kdt * v1;
  f2 -= kdt * v2;
  const Real cap = c.phys.tan_phi * (fn > 0 ? fn : 0.0);
  const Real fs2 = f1 * f1 + f2 * f2;
  if (fs2 > cap * cap) {
    const Real norm = std::sqrt(fs2);
    const Real sc = norm > 0 ? cap / norm : 0.0;
    const Real c1 = f1 * sc, c2 = f2 * sc;
    if (c.phys.ks > 0) st.dissip_friction += ((f1 - c1) * c1 + (f2 - c2) * c2) / c.phys.ks;
    f1 = c1;
    f2 = c2;
  }
  // Component by component into the record (Vec3 temporaries went through the stack).
  st.fs[AX] = 0;
  st.fs[A1] = f1;
  st.fs[A2] = f2;
  st.normal[AX] = sense;  // w.normal()
  st.normal[A1] = 0;
  st.normal[A2] = 0;
  st.overlap = overlap;
  st.fn = fn;
  c.force[AX] = fn * sense;
  c.force[A1] = f1;
  c.force[A2] = f2;
  // Torque (-l n) x f.
  c.torque[AX] = 0;
  c.torque[A1] = ls * f2;
  c.torque[A2] = -ls * f1;
}
}  // namespace

void Scene::compute_wall_forces(long& err_contact) {
  const long nc = static_cast<long>(wall_contacts_.size());
  const Real dt = dt_;
  const Real max_ratio = max_overlap_ratio_;
  const int version = phys_version_;
  // The contacts by blocks of bodies (those of the integration pass) and, within a block, by
  // wall axis (contact order within an axis): the kernel's axis is a compile-time constant and
  // the branch to it changes at most three times per block, where in contact order (by body)
  // it changed at random and missed (perf, N = 1e3). Each contact is computed independently,
  // so the order does not change any result.
  const int nblocks = (num_bodies() + kBodyBlock - 1) / kBodyBlock;
  if (wall_order_builds_ != builds_ || static_cast<long>(wall_order_.size()) != nc ||
      static_cast<int>(wall_block_off_.size()) != nblocks + 1) {
    std::vector<int> start(3 * nblocks + 1, 0);
    const auto key = [&](long k) {
      return 3 * (wall_contacts_[k].body / kBodyBlock) + walls_[wall_contacts_[k].wall].axis;
    };
    for (long k = 0; k < nc; ++k) ++start[key(k) + 1];
    for (int q = 0; q < 3 * nblocks; ++q) start[q + 1] += start[q];
    wall_block_off_.resize(nblocks + 1);
    for (int blk = 0; blk <= nblocks; ++blk) wall_block_off_[blk] = start[3 * blk];
    wall_order_.resize(nc);
    for (long k = 0; k < nc; ++k) wall_order_[start[key(k)]++] = static_cast<int>(k);
    wall_order_builds_ = builds_;
  }
  const int* const order = wall_order_.data();
  const int* const block_off = wall_block_off_.data();
  WallContact* const contacts = wall_contacts_.data();
  const Wall* const walls = walls_.data();
  const Vec3* const pos = pos_.data();
  const Vec3* const vel = vel_.data();
  const Vec3* const angvel = angvel_.data();
  const Real* const radius = radius_.data();
  long err = std::numeric_limits<long>::max();
  // (err is an argument: inside the parallel loop it is the thread's reduction copy.)
  const auto one = [&](long k, long& err, auto axis) __attribute__((always_inline)) {
    constexpr int AX = decltype(axis)::value;
    WallContact& c = contacts[k];
    const Wall& w = walls[c.wall];
    const int b = c.body;
    const Real r = radius[b];
    const Real s = w.sense * (pos[b][AX] - w.position);
    if (s >= r || s <= -r) {
      if (c.active) {
        c.active = false;
        c.state.clear_history();
        c.force.setZero();
        c.torque.setZero();
      }
      return;
    }
    const Real overlap = r - s;
    if (!(overlap <= max_ratio * r)) {
      err = std::min(err, k);
      return;
    }
    if (!c.active || c.phys_version != version) update_phys(c);
    c.active = true;
    if (c.simple) {
      wall_short_kernel<AX>(c, w, vel[b], angvel[b], r, overlap, dt);
      return;
    }
    // (The general law's geometry only here: its zero-initialised fields cost the short
    // kernel a stack fill per contact.)
    ContactGeometry g;
    g.overlap = overlap;
    g.normal = w.normal();
    g.branch2 = -(r - 0.5 * g.overlap) * g.normal;
    g.branch1 = pos[b] + g.branch2;  // unused by the law (the wall does not rotate)
    g.rel_vel = (vel[b] + angvel[b].cross(g.branch2)) - w.velocity;
    g.angvel_sum = angvel[b];
    g.rel_angvel = angvel[b];
    const LawOutput out = apply_law(c.phys, g, dt, c.state);
    c.force = out.force2;
    c.torque = g.branch2.cross(out.force2) + out.moment2;
  };
#pragma omp parallel reduction(min : err) if (nc > kParallelMin)
  {
    const auto [t, nt] = thread_and_team();
    const auto blocks = thread_share(nblocks, t, nt);
    for (long p = block_off[blocks.first]; p < block_off[blocks.second]; ++p) {
      const long k = order[p];
      switch (walls[contacts[k].wall].axis) {
        case 0: one(k, err, std::integral_constant<int, 0>()); break;
        case 1: one(k, err, std::integral_constant<int, 1>()); break;
        default: one(k, err, std::integral_constant<int, 2>());
      }
    }
  }
  err_contact = err;
}

void Scene::raise_overlap(long k, bool wall) const {
  std::ostringstream os;
  os.precision(4);
  // Before the first step nothing has moved: the overlap was in the input.
  const char* why = step_ == 0
                        ? "); the initial configuration overlaps this much: move the bodies "
                          "apart or relax the overlaps first (cpp_dem.prep.relax_overlaps)"
                        : "); the time step may be too large or the contact too soft";
  if (wall) {
    const WallContact& c = wall_contacts_[k];
    const Wall& w = walls_[c.wall];
    const Real s = w.sense * (pos_[c.body][w.axis] - w.position);
    os << "blow-up at step " << step_ << ": body " << id_of(c.body) << " overlaps wall " << c.wall
       << " by " << (radius_[c.body] - s) / radius_[c.body]
       << " of its radius (max_overlap_ratio=" << max_overlap_ratio_ << why;
  } else {
    const PairContact& c = pairs_[k];
    const Real ov = radius_[c.i] + radius_[c.j] - (pos_[c.j] - pos_[c.i]).norm();
    os << "blow-up at step " << step_ << ": bodies " << id_of(c.i) << " and " << id_of(c.j)
       << " overlap by " << ov / std::min(radius_[c.i], radius_[c.j])
       << " of the smaller radius (max_overlap_ratio=" << max_overlap_ratio_ << why;
    if (!std::isfinite(ov)) os << " (non-finite position)";
  }
  throw BlowUpError(os.str());
}

// ---- integration ----------------------------------------------------------------------------

namespace {
/// Cundall local damping of one component of an acceleration (Yade's 2nd-order form).
inline Real damp_component(Real a, Real v, Real dt, Real lambda) {
  const Real vm = v + 0.5 * dt * a;
  // sign(a vm) without a branch: in a quasi-static packing the signs are noise, and a
  // mispredicted branch per component cost a fifth of the integration (perf, N = 1e3).
  const Real p = a * vm;
  const Real s = p != 0 ? std::copysign(1.0, p) : 0.0;  // a mask, not a jump
  return a * (1.0 - lambda * s);
}

/// Turns q by the rotation |w| dt about w (w in rad/s, dt in s): q <- (cos h, sin h w/|w|) q
/// with h = |w| dt / 2. For the small angles of a stable step, series in h^2 replace sin/cos
/// and the division by |w| (truncation < h^6/720: below 2e-11 for h < 0.05), so the step
/// needs no square root and no division. The rotation is a unit quaternion to round-off, so
/// |q| drifts by about one ulp per step; with `renormalize` (every kRenormalizePeriod steps)
/// one Newton step for 1/|q| brings it back (|q|^2 = 1 + e, the step leaves O(e^2)).
/// The rotation quaternion r and the Hamilton product r q of rotate_orientation, written
/// for one body's doubles: q = (x, y, z, w) in Eigen's storage order, w = spin (rad/s).
/// `series`: h^2 < 0.0025 (the caller checked), so no sin/cos.
template <bool kRenormalize>
__attribute__((always_inline)) inline void rotate_quat(Real* q, Real wx, Real wy, Real wz,
                                                        Real dt, Real w2, bool series) {
  const Real h2 = 0.25 * dt * dt * w2;
  Real ch, sh_over_wn;
  if (series) {
    ch = 1 - h2 * (0.5 - h2 * (1.0 / 24));
    sh_over_wn = 0.5 * dt * (1 - h2 * (1.0 / 6 - h2 * (1.0 / 120)));
  } else {
    const Real wn = std::sqrt(w2);
    const Real h = 0.5 * wn * dt;
    ch = std::cos(h);
    sh_over_wn = std::sin(h) / wn;
  }
  const Real rw = ch, rx = sh_over_wn * wx, ry = sh_over_wn * wy, rz = sh_over_wn * wz;
  const Real qx = q[0], qy = q[1], qz = q[2], qw = q[3];
  // Hamilton product r q.
  Real nw = rw * qw - rx * qx - ry * qy - rz * qz;
  Real nx = rw * qx + rx * qw + ry * qz - rz * qy;
  Real ny = rw * qy - rx * qz + ry * qw + rz * qx;
  Real nz = rw * qz + rx * qy - ry * qx + rz * qw;
  if (kRenormalize) {
    const Real k = 1.5 - 0.5 * (nw * nw + nx * nx + ny * ny + nz * nz);
    nw *= k;
    nx *= k;
    ny *= k;
    nz *= k;
  }
  q[0] = nx;
  q[1] = ny;
  q[2] = nz;
  q[3] = nw;
}

/// h^2 = (|w| dt / 2)^2 below which rotate_quat uses its series.
constexpr Real kSeriesH2 = 0.0025;

inline void rotate_orientation(Quat& q, const Vec3& w, Real dt, bool renormalize) {
  const Real w2 = w.squaredNorm();
  const bool series = 0.25 * dt * dt * w2 < kSeriesH2;
  if (renormalize) rotate_quat<true>(q.coeffs().data(), w[0], w[1], w[2], dt, w2, series);
  else rotate_quat<false>(q.coeffs().data(), w[0], w[1], w[2], dt, w2, series);
}

/// rotate_orientation for `count` bodies: q, 4 doubles per body (x, y, z, w); w, 3 per body.
/// Every |w| dt / 2 must be in the series range (the caller checked); the loop vectorises
/// across bodies.
template <bool kRenormalize>
inline void rotate_orientations(Real* __restrict q, const Real* __restrict w, long count,
                                Real dt) {
#pragma omp simd
  for (long b = 0; b < count; ++b) {
    const Real wx = w[3 * b], wy = w[3 * b + 1], wz = w[3 * b + 2];
    const Real w2 = wx * wx + wy * wy + wz * wz;
    rotate_quat<kRenormalize>(q + 4 * b, wx, wy, wz, dt, w2, true);
  }
}

/// One leapfrog half of the update for a run of degrees of freedom [k0, k1) of flat arrays:
/// the accelerations acc (m/s^2 or rad/s^2, zero for a blocked DOF) are damped (Cundall local
/// damping, lambda) and give the new velocities vel; with pos (not null) the positions follow,
/// pos += vel dt. Returns the sum of the new positions and velocities, which is finite unless
/// one of them is not (or the sum overflows; the caller then tests each body). The loop is
/// elementwise, so the compiler vectorises it across bodies.
template <bool kDamp>
inline Real leapfrog_dofs(Real* __restrict vel, const Real* __restrict acc, Real* __restrict pos,
                          long k0, long k1, Real dt, Real lambda) {
  Real check = 0;
  if (pos) {
#pragma omp simd reduction(+ : check)
    for (long k = k0; k < k1; ++k) {
      const Real v = vel[k] + (kDamp ? damp_component(acc[k], vel[k], dt, lambda) : acc[k]) * dt;
      vel[k] = v;
      pos[k] += v * dt;
      check += pos[k] + v;
    }
  } else {
#pragma omp simd reduction(+ : check)
    for (long k = k0; k < k1; ++k) {
      const Real v = vel[k] + (kDamp ? damp_component(acc[k], vel[k], dt, lambda) : acc[k]) * dt;
      vel[k] = v;
      check += v;
    }
  }
  return check;
}
}  // namespace

void Scene::reduce_and_integrate(long& err_body) {
  const int n = num_bodies();
  const Real dt = dt_;
  const Real lambda = local_damping_;
  const bool energy = track_energy_;
  const bool grid = has_grid();  // constant false without the geogrid: the branch vanishes
  const bool renormalize = step_ % kRenormalizePeriod == 0;
  long err = std::numeric_limits<long>::max();
  Real worst = 0;

  // Reduce the contact forces into body b in a fixed order: the contacts where b is j (in
  // contact order, contiguous in pair_out_), the sum over the contacts where b is i (which
  // the pair pass formed in contact order), walls, then the geogrid's contacts and links.
  const Real* const fi = pair_fi_.data()->data();
  const Real* const ti = pair_ti_.data()->data();
  // (With the 3-vector operations of `ops`, WideOps or NarrowOps: see the pair pass.)
  const auto sum_forces = [&](int b, auto& f, auto& t, auto ops) __attribute__((always_inline)) {
    f = ops.load(ext_force_[b]) + mass_[b] * ops.load(gravity_);
    t = ops.load(ext_torque_[b]);
    for (int e = pair_jadj_off_[b]; e < pair_jadj_off_[b + 1]; ++e) {
      const PairOutput& o = pair_out_[e];  // zero when inactive
      f += ops.load_padded(o.force.data());
      t += ops.load_padded(o.torque_j.data());
    }
    f += ops.load_padded(fi + 4L * b);
    t += ops.load_padded(ti + 4L * b);
    for (int e = wall_adj_off_[b]; e < wall_adj_off_[b + 1]; ++e) {
      const WallContact& c = wall_contacts_[wall_adj_[e]];
      if (!c.active) continue;
      f += ops.load(c.force);
      t += ops.load(c.torque);
    }
    if (grid) {
      // Grain side of grain–geogrid contacts.
      for (int e = sphere_gc_off_[b]; e < sphere_gc_off_[b + 1]; ++e) {
        const GridContact& c = grid_contacts_[sphere_gc_[e]];
        if (!c.active) continue;
        f += ops.load(c.force);
        t += ops.load(c.torque_sphere);
      }
      // Node side: the virtual sphere's force and torque split by the weights (000 eq 19).
      for (int e = node_gc_off_[b]; e < node_gc_off_[b + 1]; ++e) {
        const GridContact& c = grid_contacts_[node_gc_[e] / 3];
        if (!c.active) continue;
        const Real w = c.w[node_gc_[e] % 3];
        f -= w * ops.load(c.force);
        t += w * ops.load(c.torque_virtual);
      }
      // Cohesive links.
      for (int e = node_link_off_[b]; e < node_link_off_[b + 1]; ++e) {
        const GridLink& l = links_[node_link_[e]];
        if (l.broken) continue;
        if (l.b == b) {
          f += ops.load(l.force_b);
          t += ops.load(l.torque_b);
        } else {
          f -= ops.load(l.force_b);
          t += ops.load(l.torque_a);
        }
      }
    }
    ops.store(force_[b], f);
    ops.store(torque_[b], t);
  };
  const auto forces_finite = [&](int b) { return force_[b].allFinite() && torque_[b].allFinite(); };
  // Forces and accelerations of bodies [b0, b1) (inverse masses and inertias from b0 on);
  // false if a force or torque may be non-finite.
  const auto block_forces = [&](int b0, int b1, const Real* inv_m, const Real* inv_i,
                                auto ops) __attribute__((always_inline)) {
    using V = typename decltype(ops)::V;
    V fcheck = ops.zero();  // sum of every force and torque: finite unless one of them is not
    for (int b = b0; b < b1; ++b) {
      V f, t;
      sum_forces(b, f, t, ops);
      fcheck += f + t;
      V al = f * inv_m[b - b0], aa = t * inv_i[b - b0];
      if (const std::uint8_t dofs = blocked_[b]) {
        // A blocked DOF keeps its imposed velocity: zero acceleration, nothing to damp.
        for (int a = 0; a < 3; ++a) {
          if (dofs & (DOF_X << a)) al[a] = 0;
          if (dofs & (DOF_RX << a)) aa[a] = 0;
        }
      }
      ops.store(acc_lin_[b], al);
      ops.store(acc_ang_[b], aa);
    }
    return std::isfinite(fcheck[0] + fcheck[1] + fcheck[2]);
  };
  const bool wide = use_wide_ops();
  // The broad phase's displacement check (need_rebuild) for the next step, in this pass.
  const auto displacement = [&](int b) __attribute__((always_inline)) {
    return (pos_[b] - pos_at_build_[b]).norm() +
           std::max(0.0, radius_[b] - radius_at_build_[b]);
  };

  if (!energy) {
    // Blocks of bodies, each in three passes while it stays in the L1 cache: forces and
    // accelerations per body, then the velocities and positions as flat arrays of degrees of
    // freedom (vectorised across bodies), then orientations and checks. Every body's
    // update is the same arithmetic whatever the blocks or threads.
    acc_lin_.resize(n);
    acc_ang_.resize(n);
    Real* const vel = vel_.data()->data();
    Real* const angvel = angvel_.data()->data();
    Real* const pos = pos_.data()->data();
    const Real* const acc_lin = acc_lin_.data()->data();
    const Real* const acc_ang = acc_ang_.data()->data();
    const Real* const mass = mass_.data();
    const Real* const inertia = inertia_.data();
    constexpr int kBlock = kBodyBlock;
    const int nblocks = (n + kBlock - 1) / kBlock;
#pragma omp parallel reduction(min : err) reduction(max : worst) if (n > kParallelMin)
    {
      const auto [t, nt] = thread_and_team();
      const auto blocks = thread_share(nblocks, t, nt);
      for (long blk = blocks.first; blk < blocks.second; ++blk) {
        const int b0 = static_cast<int>(blk) * kBlock, b1 = std::min(n, b0 + kBlock);
        const int count = b1 - b0;
        // Inverse masses and inertias of the block (vectorised divisions).
        Real inv_m[kBlock], inv_i[kBlock];
#pragma omp simd
        for (int q = 0; q < count; ++q) {
          inv_m[q] = 1.0 / mass[b0 + q];
          inv_i[q] = 1.0 / inertia[b0 + q];
        }
        const bool forces_ok =
            wide ? block_forces(b0, b1, inv_m, inv_i, WideOps())
                 : block_forces(b0, b1, inv_m, inv_i, NarrowOps());
        if (!forces_ok) {
          // Only now the exact test; a body with a non-finite force or torque does not move.
          for (int b = b0; b < b1; ++b) {
            if (!forces_finite(b)) {
              err = std::min(err, static_cast<long>(b));
              acc_lin_[b].setZero();
              acc_ang_[b].setZero();
            }
          }
        }
        const long k0 = 3L * b0, k1 = 3L * b1;
        Real check;
        if (lambda > 0) {
          check = leapfrog_dofs<true>(vel, acc_lin, pos, k0, k1, dt, lambda) +
                  leapfrog_dofs<true>(angvel, acc_ang, nullptr, k0, k1, dt, lambda);
        } else {
          check = leapfrog_dofs<false>(vel, acc_lin, pos, k0, k1, dt, lambda) +
                  leapfrog_dofs<false>(angvel, acc_ang, nullptr, k0, k1, dt, lambda);
        }
        // Orientations: vectorised across the block when every spin is in the series range.
        Real w2max = 0;
#pragma omp simd reduction(max : w2max)
        for (long k = k0; k < k1; ++k) w2max = std::max(w2max, angvel[k] * angvel[k]);
        if (3 * 0.25 * dt * dt * w2max < kSeriesH2) {  // |w|^2 <= 3 max_a w_a^2
          Real* const q = ori_[b0].coeffs().data();
          if (renormalize) rotate_orientations<true>(q, angvel + k0, count, dt);
          else rotate_orientations<false>(q, angvel + k0, count, dt);
        } else {
          for (int b = b0; b < b1; ++b) rotate_orientation(ori_[b], angvel_[b], dt, renormalize);
        }
        const bool finite = std::isfinite(check);
        for (int b = b0; b < b1; ++b) {
          if (!finite && (!pos_[b].allFinite() || !vel_[b].allFinite() || !angvel_[b].allFinite())) {
            err = std::min(err, static_cast<long>(b));
            continue;
          }
          worst = std::max(worst, displacement(b));
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
      // A NaN or inf in any component makes the sum non-finite; only then the exact test.
      if (!std::isfinite((f[0] + f[1] + f[2]) + (t[0] + t[1] + t[2])) && !forces_finite(b)) {
        err = std::min(err, static_cast<long>(b));
        continue;
      }
      const std::uint8_t dofs = blocked_[b];
      const Vec3 v_old = vel_[b], w_old = angvel_[b];
      const Real m = mass_[b], inertia = inertia_[b];
      const Real inv_m = 1.0 / m, inv_i = 1.0 / inertia;
      Vec3 v = v_old, w = w_old;
      Real dissip = 0, work = 0;
      for (int a = 0; a < 3; ++a) {
        if (dofs & (DOF_X << a)) {
          // Imposed velocity: the constraint supplies -f[a]; its work is -f[a] v dt.
          work += -f[a] * v_old[a] * dt;
          continue;
        }
        Real acc = f[a] * inv_m;
        if (lambda > 0) {
          const Real damped = damp_component(acc, v_old[a], dt, lambda);
          dissip += -(damped - acc) * m * (v_old[a] + 0.5 * dt * damped) * dt;
          acc = damped;
        }
        v[a] = v_old[a] + acc * dt;
        work += ext_force_[b][a] * 0.5 * (v_old[a] + v[a]) * dt;
      }
      for (int a = 0; a < 3; ++a) {
        if (dofs & (DOF_RX << a)) {
          work += -t[a] * w_old[a] * dt;
          continue;
        }
        Real acc = t[a] * inv_i;
        if (lambda > 0) {
          const Real damped = damp_component(acc, w_old[a], dt, lambda);
          dissip += -(damped - acc) * inertia * (w_old[a] + 0.5 * dt * damped) * dt;
          acc = damped;
        }
        w[a] = w_old[a] + acc * dt;
        work += ext_torque_[b][a] * 0.5 * (w_old[a] + w[a]) * dt;
      }
      const Vec3 vm = 0.5 * (v_old + v);
      const Vec3 wm = 0.5 * (w_old + w);
      ke_[b] = 0.5 * m * vm.squaredNorm() + 0.5 * inertia * wm.squaredNorm();
      damp_dissip_[b] += dissip;
      ext_work_[b] += work;
      vel_[b] = v;
      angvel_[b] = w;
      const Vec3 x = pos_[b] + v * dt;
      pos_[b] = x;
      rotate_orientation(ori_[b], w, dt, renormalize);
      if (!std::isfinite((x[0] + x[1] + x[2]) + (v[0] + v[1] + v[2]) + (w[0] + w[1] + w[2])) &&
          (!x.allFinite() || !v.allFinite() || !w.allFinite())) {
        err = std::min(err, static_cast<long>(b));
        continue;
      }
      worst = std::max(worst, displacement(b));
    }
  }
  err_body = err;
  if (err == std::numeric_limits<long>::max()) {
    max_disp_ = worst;
    disp_valid_ = true;
  }
}

int Scene::add_controller(std::shared_ptr<Controller> c) {
  if (!c) throw ParameterError("controller: must not be None");
  if (c->period < 1)
    throw ParameterError("period=" + std::to_string(c->period) + ": must be >= 1 step");
  controllers_.push_back(std::move(c));
  return static_cast<int>(controllers_.size()) - 1;
}

std::shared_ptr<Controller> Scene::controller(int id) const {
  if (id < 0 || id >= num_controllers())
    throw ParameterError("controller=" + std::to_string(id) + ": no such controller");
  return controllers_[id];
}

void Scene::step() {
  if (ts_period_ > 0 && step_ % ts_period_ == 0 && step_ > 0) {
    const Real est = critical_dt();
    if (std::isfinite(est)) dt_ = ts_safety_ * est;  // nothing free: keep dt
  }
  if (ts_period_ == 0 && dt_check_period_ > 0 && step_ > 0 && step_ % dt_check_period_ == 0) {
    int body = -1;
    const Real est = critical_dt_body(&body);
    if (body >= 0 && dt_ > est * (1 + 1e-12)) {
      std::ostringstream os;
      os.precision(4);
      os << "blow-up at step " << step_ << ": the time step dt=" << dt_
         << " s exceeds the critical estimate " << est << " s (set by body " << body
         << "); leapfrog may be unstable and results would be wrong: lower dt or use "
            "set_auto_timestep(safety <= 1)";
      throw BlowUpError(os.str());
    }
  }
  for (const auto& c : controllers_)
    if (c->enabled && step_ % c->period == 0) c->apply(*this);
  if (need_rebuild()) rebuild();
  disp_valid_ = false;  // until this step's integration measures them again
  long err_pair, err_wall, err_body;
  compute_pair_forces(err_pair);
  if (err_pair != std::numeric_limits<long>::max()) raise_overlap(err_pair, false);
  compute_wall_forces(err_wall);
  if (err_wall != std::numeric_limits<long>::max()) raise_overlap(err_wall, true);
  if constexpr (kGeogridBuilt) {
    if (has_grid()) {
      long err_grid;
      compute_grid_contacts(err_grid);
      if (err_grid != std::numeric_limits<long>::max()) {
        const GridContact& c = grid_contacts_[err_grid];
        std::ostringstream os;
        os.precision(4);
        os << "blow-up at step " << step_ << ": sphere " << id_of(c.sphere)
           << " overlaps the geogrid ("
           << (c.kind == GridPrimitive::Node         ? "node "
               : c.kind == GridPrimitive::Connection ? "connection "
                                                     : "pfacet ")
           << c.prim << ") by " << c.geom.overlap / radius_[c.sphere]
           << " of the grain radius (max_overlap_ratio=" << max_overlap_ratio_
           << "); the time step may be too large or the contact too soft";
        throw BlowUpError(os.str());
      }
      compute_links();
    }
  }
  // Wall forces and work, summed in contact order.
  for (Wall& w : walls_) w.force.setZero();
  for (const WallContact& c : wall_contacts_)
    if (c.active) walls_[c.wall].force -= c.force;
  if (track_energy_ && !energy_reference_set_) set_energy_reference();
  reduce_and_integrate(err_body);
  if (err_body != std::numeric_limits<long>::max()) {
    const int b = static_cast<int>(err_body);
    std::ostringstream os;
    os << "blow-up at step " << step_ << ": body " << id_of(b) << " has a non-finite ";
    if (!force_[b].allFinite()) os << "force " << force_[b].transpose();
    else if (!torque_[b].allFinite()) os << "torque " << torque_[b].transpose();
    else if (!vel_[b].allFinite()) os << "velocity " << vel_[b].transpose();
    else if (!angvel_[b].allFinite()) os << "angular velocity " << angvel_[b].transpose();
    else os << "position " << pos_[b].transpose();
    throw BlowUpError(os.str());
  }
  for (Wall& w : walls_) {
    // Work done by the wall on the spheres: -(force on wall) . v dt.
    w.work += -w.force.dot(w.velocity) * dt_;
    const Real dx = w.velocity[w.axis] * dt_;
    w.position += dx;
    w.moved_since_build += std::abs(dx);
  }
  ++step_;
  time_ += dt_;
}

void Scene::run(long n) {
  if (n < 0) throw ParameterError("n=" + std::to_string(n) + ": must be >= 0 steps");
  if (num_bodies() > 0 && margin_ <= 0 && default_margin() <= 0)
    throw ParameterError("verlet_margin: could not derive a default");
  for (long k = 0; k < n; ++k) step();
}

int Scene::num_active_contacts() const {
  int n = 0;
  for (const auto& c : pairs_) n += c.active;
  for (const auto& c : wall_contacts_) n += c.active;
  return n;
}

}  // namespace cpp_dem
