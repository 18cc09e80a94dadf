// Triangle-mesh walls (bodies/mesh_wall.hpp): adding them, their candidates at a build (the
// triangles binned in a grid), the contact pass (faces, edges and vertices without double
// counting, history carried across the mesh's edges), and their motion after the integration.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/laws/linear.hpp"
#include "cpp_dem/laws/registry.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr Real kInf = std::numeric_limits<Real>::infinity();

/// A touching feature of a mesh found for one sphere: its key, closest point, unit normal
/// (from the mesh to the centre) and distance.
struct Touch {
  std::int32_t kind, a, b;
  Vec3 p, n;
  Real dist;
};

/// A sphere at x over the face of a triangle of unit normal n through v0: its contact with
/// the face's plane (the closest point x - s n, s = n . (x - v0); the normal +-n towards x;
/// the distance |s|), keyed by the triangle tri (its number in its mesh).
Touch face_touch(const Vec3& x, const Vec3& n, const Vec3& v0, std::int32_t tri) {
  const Real s = n.dot(x - v0);
  return Touch{kFace, tri, -1, x - s * n, s < 0 ? Vec3(-n) : n, std::abs(s)};
}

/// The distance from x to triangle t of the scene's arrays (its closest point in p).
Real triangle_distance(const Vec3& x, const Vec3& a, const Vec3& b, const Vec3& c, Vec3& p) {
  int e0, e1;
  closest_on_triangle(x, a, b, c, p, e0, e1);
  return (x - p).norm();
}
}  // namespace

int Scene::add_mesh_wall(const std::vector<Vec3>& vertices,
                         const std::vector<std::array<int, 3>>& triangles, int material) {
  if (vertices.size() < 3)
    throw ParameterError("vertices: " + std::to_string(vertices.size()) +
                         " given; a mesh needs at least 3 (m)");
  if (triangles.empty()) throw ParameterError("triangles: none given");
  for (size_t k = 0; k < vertices.size(); ++k)
    if (!vertices[k].allFinite())
      throw ParameterError("vertices[" + std::to_string(k) + "]: must be finite (m)");
  const int nv = static_cast<int>(vertices.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const auto& tri = triangles[t];
    for (int i : tri)
      if (i < 0 || i >= nv)
        throw ParameterError("triangles[" + std::to_string(t) + "]: vertex " + std::to_string(i) +
                             " is not one of the " + std::to_string(nv) + " vertices");
    const Vec3 ab = vertices[tri[1]] - vertices[tri[0]], ac = vertices[tri[2]] - vertices[tri[0]];
    const Real scale = std::max(ab.squaredNorm(), ac.squaredNorm());
    if (!(ab.cross(ac).norm() > 1e-12 * scale))
      throw ParameterError("triangles[" + std::to_string(t) + "]: degenerate (its vertices " +
                           std::to_string(tri[0]) + ", " + std::to_string(tri[1]) + ", " +
                           std::to_string(tri[2]) + " are collinear or repeated)");
  }
  this->material(material);
  if (cell_.on)
    throw ParameterError("add_mesh_wall: the scene is a periodic cell; mesh walls are not "
                         "supported in one");
  MeshWall w;
  w.vert_off = static_cast<int>(mesh_vertices_.size());
  w.nvert = nv;
  w.tri_off = static_cast<int>(mesh_tris_.size());
  w.ntri = static_cast<int>(triangles.size());
  w.material = material;
  Vec3 mean = Vec3::Zero();
  for (const Vec3& v : vertices) mean += v;
  w.ref = mean / nv;
  mesh_vertices_.insert(mesh_vertices_.end(), vertices.begin(), vertices.end());
  mesh_tris_.insert(mesh_tris_.end(), triangles.begin(), triangles.end());
  mesh_walls_.push_back(w);
  frame_mesh_triangles(w.tri_off);
  dirty_ = true;
  return num_mesh_walls() - 1;
}

void Scene::frame_mesh_triangles(size_t t0) {
  mesh_tri_n_.resize(t0);
  mesh_tri_e_.resize(t0);
  for (const MeshWall& w : mesh_walls_)
    for (long t = std::max(0L, static_cast<long>(t0) - w.tri_off); t < w.ntri; ++t) {
      const auto& tri = mesh_tris_[w.tri_off + t];
      const Vec3* v[3] = {&mesh_vertices_[w.vert_off + tri[0]],
                          &mesh_vertices_[w.vert_off + tri[1]],
                          &mesh_vertices_[w.vert_off + tri[2]]};
      const Vec3 n = (*v[1] - *v[0]).cross(*v[2] - *v[0]).normalized();
      std::array<Vec3, 3> e;
      for (int i = 0; i < 3; ++i) e[i] = n.cross(*v[(i + 1) % 3] - *v[i]).normalized();
      mesh_tri_n_.push_back(n);
      mesh_tri_e_.push_back(e);
    }
}

MeshWall& Scene::mesh_wall(int id) {
  if (id < 0 || id >= num_mesh_walls())
    throw ParameterError("mesh=" + std::to_string(id) + ": no such mesh wall (the scene has " +
                         std::to_string(num_mesh_walls()) + ")");
  return mesh_walls_[id];
}
const MeshWall& Scene::mesh_wall(int id) const { return const_cast<Scene*>(this)->mesh_wall(id); }

std::vector<Vec3> Scene::mesh_vertices(int id) const {
  const MeshWall& w = mesh_wall(id);
  return std::vector<Vec3>(mesh_vertices_.begin() + w.vert_off,
                           mesh_vertices_.begin() + w.vert_off + w.nvert);
}

void Scene::rebuild_mesh_contacts(Real margin) {
  // Each mesh's triangles binned in a grid of cells 2 (r_max + margin) wide (by their
  // bounding boxes); a sphere looks in the cells its box of reach r + margin overlaps, and
  // keeps the triangles within that reach. A sphere with at least one is a candidate of the
  // mesh, with that list.
  const int n = num_bodies();
  Real rmax = 0;
  for (int b = 0; b < n; ++b) rmax = std::max(rmax, bodies_.radius[b]);
  const Real h = 2 * (rmax + margin);
  // A triangle whose box spans more than kMaxCells cells (a mesh of large triangles among
  // small grains) is binned instead in a coarse grid whose cells are a quarter of the largest
  // such box (at most 5 x 5 x 5 cells a triangle): the memory stays bounded by 125 entries a
  // triangle, whatever the mesh's size. Either way a sphere's candidates are exactly the
  // triangles within its reach (sorted), so where they are binned changes only the cost.
  // (Cell keys wrap in 64 bits: two cells that share a key only add triangles that the exact
  // test below drops.)
  constexpr double kMaxCells = 64;
  struct Grid {
    Vec3 lo = Vec3::Zero();
    Real h = 0;
    std::array<long, 3> dims{1, 1, 1};
    std::unordered_map<std::uint64_t, std::vector<int>> cells;
    void size(const Vec3& lo_, const Vec3& hi, Real h_) {
      lo = lo_;
      h = h_;
      for (int d = 0; d < 3; ++d)
        dims[d] = static_cast<long>(std::min((hi[d] - lo[d]) / h, 1e15)) + 1;
    }
    std::uint64_t key(long i, long j, long k) const {
      return (static_cast<std::uint64_t>(i) * static_cast<std::uint64_t>(dims[1]) +
              static_cast<std::uint64_t>(j)) * static_cast<std::uint64_t>(dims[2]) +
             static_cast<std::uint64_t>(k);
    }
    /// The cells that the box [a, b] overlaps (clamped to the grid), as index ranges; the
    /// number of cells.
    double range(const Vec3& a, const Vec3& b, std::array<long, 3>& c0,
                 std::array<long, 3>& c1) const {
      double count = 1;
      for (int d = 0; d < 3; ++d) {
        const auto at = [&](Real v) {
          return static_cast<long>(std::clamp(std::floor((v - lo[d]) / h), 0.0,
                                              static_cast<double>(dims[d] - 1)));
        };
        c0[d] = at(a[d]);
        c1[d] = at(b[d]);
        count *= double(c1[d] - c0[d] + 1);
      }
      return count;
    }
    void add(const std::array<long, 3>& c0, const std::array<long, 3>& c1, int t) {
      for (long i = c0[0]; i <= c1[0]; ++i)
        for (long j = c0[1]; j <= c1[1]; ++j)
          for (long k = c0[2]; k <= c1[2]; ++k) cells[key(i, j, k)].push_back(t);
    }
    void gather(const Vec3& a, const Vec3& b, std::vector<int>& out) const {
      if (cells.empty()) return;
      std::array<long, 3> c0, c1;
      range(a, b, c0, c1);
      for (long i = c0[0]; i <= c1[0]; ++i)
        for (long j = c0[1]; j <= c1[1]; ++j)
          for (long k = c0[2]; k <= c1[2]; ++k) {
            const auto it = cells.find(key(i, j, k));
            if (it != cells.end()) out.insert(out.end(), it->second.begin(), it->second.end());
          }
    }
  };
  struct Bins {
    Vec3 lo, hi;
    Grid fine, coarse;
  };
  const auto box_of = [this](const MeshWall& w, int t, Vec3& tlo, Vec3& thi) {
    tlo = Vec3::Constant(kInf);
    thi = Vec3::Constant(-kInf);
    for (int i : mesh_tris_[t]) {
      tlo = tlo.cwiseMin(mesh_vertices_[w.vert_off + i]);
      thi = thi.cwiseMax(mesh_vertices_[w.vert_off + i]);
    }
  };
  std::vector<Bins> bins(mesh_walls_.size());
  std::vector<int> large;
  for (size_t m = 0; m < mesh_walls_.size(); ++m) {
    const MeshWall& w = mesh_walls_[m];
    Bins& B = bins[m];
    B.lo = Vec3::Constant(kInf);
    B.hi = Vec3::Constant(-kInf);
    for (int v = 0; v < w.nvert; ++v) {
      B.lo = B.lo.cwiseMin(mesh_vertices_[w.vert_off + v]);
      B.hi = B.hi.cwiseMax(mesh_vertices_[w.vert_off + v]);
    }
    B.fine.size(B.lo, B.hi, h);
    large.clear();
    Real coarse_h = h;
    for (int t = w.tri_off; t < w.tri_off + w.ntri; ++t) {
      Vec3 tlo, thi;
      box_of(w, t, tlo, thi);
      std::array<long, 3> c0, c1;
      if (B.fine.range(tlo, thi, c0, c1) > kMaxCells) {
        large.push_back(t);
        coarse_h = std::max(coarse_h, 0.25 * (thi - tlo).maxCoeff());
        continue;
      }
      B.fine.add(c0, c1, t);
    }
    if (large.empty()) continue;
    B.coarse.size(B.lo, B.hi, coarse_h);
    for (int t : large) {
      Vec3 tlo, thi;
      box_of(w, t, tlo, thi);
      std::array<long, 3> c0, c1;
      B.coarse.range(tlo, thi, c0, c1);
      B.coarse.add(c0, c1, t);
    }
  }
  WallContactMerge merge(mesh_contacts_, [this](const MeshContact& c) {
    for (const MeshSub& s : c.subs) drop_dissipation(s.state);
  });
  std::vector<int> off{0}, tris, found;
  for (int b = 0; b < n; ++b) {
    if (bodies_.kind[b] != BODY_SPHERE && !grid_wall_contacts_) continue;
    const Vec3& x = bodies_.pos[b];
    const Real reach = bodies_.radius[b] + margin;
    for (int m = 0; m < num_mesh_walls(); ++m) {
      const MeshWall& w = mesh_walls_[m];
      const Bins& B = bins[m];
      if (((x.array() + reach) < B.lo.array()).any() || ((x.array() - reach) > B.hi.array()).any())
        continue;
      found.clear();
      const Vec3 a = x.array() - reach, bb = x.array() + reach;
      B.fine.gather(a, bb, found);
      B.coarse.gather(a, bb, found);
      std::sort(found.begin(), found.end());
      found.erase(std::unique(found.begin(), found.end()), found.end());
      const size_t before = tris.size();
      for (int t : found) {
        const auto& tri = mesh_tris_[t];
        Vec3 p;
        if (triangle_distance(x, mesh_vertices_[w.vert_off + tri[0]],
                              mesh_vertices_[w.vert_off + tri[1]],
                              mesh_vertices_[w.vert_off + tri[2]], p) < reach)
          tris.push_back(t);
      }
      if (tris.size() == before) continue;
      merge.add(b, m);
      off.push_back(static_cast<int>(tris.size()));
    }
  }
  mesh_contacts_ = merge.finish();
  mesh_cand_off_.swap(off);
  mesh_cand_tri_.swap(tris);
  contacts_by_body(mesh_contacts_, n, mesh_adj_off_, mesh_adj_);
  for (MeshWall& w : mesh_walls_) w.moved_since_build = 0;
  index_mesh_contacts();
}

void Scene::index_mesh_contacts() {
  // A contact's candidates are a flat patch when every vertex of them lies within 1e-10 of
  // the sphere's radius of its first triangle's plane: a point of them is then on the plane
  // of any face contact among them far inside the tolerance (1e-9 r) with which step 2 of
  // the pass takes it as part of that face's surface. A mesh moves by translation only, so
  // this holds until the next build.
  const size_t nc = mesh_contacts_.size();
  mesh_flat_.assign(nc, 0);
  if (mesh_cand_off_.size() != nc + 1) return;
  for (size_t k = 0; k < nc; ++k) {
    const int e0 = mesh_cand_off_[k], e1 = mesh_cand_off_[k + 1];
    if (e0 == e1) continue;
    const MeshContact& c = mesh_contacts_[k];
    const MeshWall& w = mesh_walls_[c.wall];
    const auto vert = [&](int t, int i) -> const Vec3& {
      return mesh_vertices_[w.vert_off + mesh_tris_[t][i]];
    };
    const int t0 = mesh_cand_tri_[e0];
    const Vec3 a = vert(t0, 0);
    const Vec3 nrm = (vert(t0, 1) - a).cross(vert(t0, 2) - a);
    const Real len = nrm.norm();
    if (!(len > 0)) continue;
    const Real tol = 1e-10 * bodies_.radius[c.body] * len;  // (on the unnormalised normal)
    bool flat = true;
    for (int e = e0; e < e1 && flat; ++e)
      for (int i = 0; i < 3 && flat; ++i)
        flat = std::abs(nrm.dot(vert(mesh_cand_tri_[e], i) - a)) <= tol;
    mesh_flat_[k] = flat;
  }
}

void Scene::compute_mesh_forces(long& err_contact) {
  const long nc = static_cast<long>(mesh_contacts_.size());
  if (mesh_flat_.size() != mesh_contacts_.size())
    throw std::logic_error("mesh contacts not indexed: " + std::to_string(nc) + " contacts, " +
                           std::to_string(mesh_flat_.size()) + " indexed");
  long err = std::numeric_limits<long>::max();
  long dropped = 0;
  const Real dt = dt_;
  mesh_sum_code_.resize(nc);
  mesh_sum_f_.resize(MeshContact::kMaxSubs * nc);
  mesh_sum_t_.resize(MeshContact::kMaxSubs * nc);
  mesh_sum_m_.resize(MeshContact::kMaxSubs * nc);
#pragma omp parallel reduction(min : err) reduction(+ : dropped) if (nc > kParallelMin)
  {
  std::vector<Touch> found;  // (one list per thread, kept between contacts)
  std::array<MeshSub, MeshContact::kMaxSubs> old;  // (a pair's records of the last step)
#pragma omp for schedule(static)
  for (long k = 0; k < nc; ++k) {
    MeshContact& c = mesh_contacts_[k];
    const MeshWall& w = mesh_walls_[c.wall];
    const int b = c.body;
    const Vec3& x = bodies_.pos[b];
    const Real r = bodies_.radius[b];
    mesh_sum_code_[k] = 0;  // (none, until its contacts are computed below)
    // 1. The touching features: each candidate triangle's closest point within r, keyed by
    // its face, edge (the mesh's vertex numbers, sorted) or vertex. Where it is the face's,
    // the contact is the plane's: the centre projected along the face's unit normal (its
    // distance and normal as an analytic plane's, not through the closest point's
    // barycentric coordinates).
    found.clear();
    // A flat patch whose sphere touched one face alone at the last step, and whose centre is
    // still over that face, farther than 1e-9 r inside each of its edges (measured along
    // their normals in its plane): that face is the pair's one contact. The patch's other
    // triangles' points lie on its plane (step 2 would take them as part of its surface), and
    // none of them has the centre over it where no two of them overlap (the same contact as
    // the full walk finds, to the bit: a face's contact is computed from its plane on both
    // paths; where two overlap, as a triangle given twice, the walk may key the contact to
    // the other one).
    bool one_face = false;
    Touch keep[MeshContact::kMaxSubs];  // (the contacts kept, step 2; the fast path's in 0)
    int nk = 0;
    if (mesh_flat_[k] && c.active && c.subs[0].kind == kFace && c.subs[1].kind < 0) {
      const int t = w.tri_off + c.subs[0].a;
      bool candidate = false;
      for (int e = mesh_cand_off_[k]; e < mesh_cand_off_[k + 1] && !candidate; ++e)
        candidate = mesh_cand_tri_[e] == t;
      if (candidate) {
        const auto& tri = mesh_tris_[t];
        const Vec3& v0 = mesh_vertices_[w.vert_off + tri[0]];
        const Vec3& v1 = mesh_vertices_[w.vert_off + tri[1]];
        const Vec3& v2 = mesh_vertices_[w.vert_off + tri[2]];
        const std::array<Vec3, 3>& e = mesh_tri_e_[t];
        const Real m = 1e-9 * r;
        if (e[0].dot(x - v0) > m && e[1].dot(x - v1) > m && e[2].dot(x - v2) > m) {
          const Touch h = face_touch(x, mesh_tri_n_[t], v0, t - w.tri_off);
          if (h.dist < r && h.dist > 0) {
            keep[nk++] = h;
            one_face = true;
          }
        }
      }
    }
    const Real reach2 = r * r * (1 + 1e-9);
    for (int e = mesh_cand_off_[k]; e < mesh_cand_off_[k + 1] && !one_face; ++e) {
      const int t = mesh_cand_tri_[e];
      const auto& tri = mesh_tris_[t];
      const Vec3& v0 = mesh_vertices_[w.vert_off + tri[0]];
      const Vec3& v1 = mesh_vertices_[w.vert_off + tri[1]];
      const Vec3& v2 = mesh_vertices_[w.vert_off + tri[2]];
      // A triangle whose bounding box is farther than r cannot touch: skipped before its
      // closest point (a sphere resting on a face is about r above its neighbours' boxes;
      // the 1e-9 slack leaves every borderline case to the exact test below).
      const Vec3 gap = ((v0.cwiseMin(v1).cwiseMin(v2) - x).cwiseMax(x - v0.cwiseMax(v1)
                        .cwiseMax(v2))).cwiseMax(Real(0));
      if (gap.squaredNorm() > reach2) continue;
      Vec3 p;
      int e0, e1;
      const MeshFeature f = closest_on_triangle(x, v0, v1, v2, p, e0, e1);
      if (f == kFace) {
        // (a face's contact from its plane: the fast path above computes it the same way)
        const Touch h = face_touch(x, mesh_tri_n_[t], v0, t - w.tri_off);
        if (h.dist < r && h.dist > 0) found.push_back(h);
        continue;
      }
      const Vec3 d = x - p;
      const Real dist = d.norm();
      if (!(dist < r) || !(dist > 0)) continue;
      Touch h{f, -1, -1, p, d / dist, dist};
      if (f == kEdge) {
        h.a = std::min(tri[e0], tri[e1]);
        h.b = std::max(tri[e0], tri[e1]);
      } else {
        h.a = tri[e0];
      }
      found.push_back(h);
    }
    // (0 on the fast path, whose one contact is in keep: a pair that touched at the last step)
    const int nf = static_cast<int>(found.size());
    if (nf == 0 && !c.active) continue;  // (nothing touches, nothing did: nothing to do)
    // 2. Without double counting: faces first, then edges and vertices, deepest first; a point that coincides with one kept (an
    // edge or vertex that several triangles share) is the same contact; an edge or vertex
    // point on or behind the plane of a kept face contact is part of that surface (a flat or
    // convex neighbour of the face): only a face's own contact counts there.
    bool in_place;
    bool used[MeshContact::kMaxSubs] = {false, false, false};
    int from[MeshContact::kMaxSubs];
    Real lost_f = 0, lost_v = 0;
    if (one_face) {
      // Steps 2 and 3's result for the one face (above, kept), without their work: the
      // pair's one contact, in place in slot 0; the empty slots carry no dissipation.
      in_place = true;
      from[0] = 0;
      used[0] = true;
    } else {
      if (nf > 1)
        std::sort(found.begin(), found.end(), [](const Touch& p, const Touch& q) {
          return std::make_tuple(p.kind != kFace, p.dist, p.kind, p.a, p.b) <
                 std::make_tuple(q.kind != kFace, q.dist, q.kind, q.a, q.b);
        });
      const Real tol = 1e-9 * r;
      for (int i = 0; i < nf; ++i) {
        const Touch& h = found[i];
        bool same = false;
        for (int j = 0; j < nk && !same; ++j) {
          same = (h.p - keep[j].p).norm() <= tol;
          if (!same && h.kind != kFace && keep[j].kind == kFace)
            same = (h.p - keep[j].p).dot(keep[j].n) <= tol;
        }
        if (same) continue;
        if (nk < MeshContact::kMaxSubs) keep[nk++] = h;
        else ++dropped;
      }
      // 3. Each kept contact takes its own history from the last step, or, new, that of a
      // contact of this pair which ended now with a normal within 25 degrees (the sphere went
      // from one face to its neighbour across an edge); else it starts fresh.
      // The common case, a pair touching the features it touched at the last step in the same
      // order (a feature's key is unique among the kept ones), keeps every contact in its slot:
      // the records are updated in place, as the matching below would leave them.
      in_place = c.active;
      for (int j = 0; j < MeshContact::kMaxSubs && in_place; ++j) {
        const MeshSub& s = c.subs[j];
        in_place = j < nk ? s.kind == keep[j].kind && s.a == keep[j].a && s.b == keep[j].b
                          : s.kind < 0;
      }
      if (!in_place) old = c.subs;
      const std::array<MeshSub, MeshContact::kMaxSubs>& last = in_place ? c.subs : old;
      for (int j = 0; j < nk; ++j) {
        from[j] = in_place ? j : -1;
        for (int s = 0; s < MeshContact::kMaxSubs && from[j] < 0; ++s)
          if (!used[s] && old[s].kind == keep[j].kind && old[s].a == keep[j].a &&
              old[s].b == keep[j].b)
            from[j] = s;
        if (from[j] >= 0) used[from[j]] = true;
      }
      for (int j = 0; j < nk && !in_place; ++j) {
        if (from[j] >= 0) continue;
        Real best = std::cos(25.0 * 3.14159265358979323846 / 180);
        for (int s = 0; s < MeshContact::kMaxSubs; ++s) {
          if (used[s] || old[s].kind < 0) continue;
          const Real cosang = old[s].state.normal.dot(keep[j].n);
          if (cosang > best) {
            best = cosang;
            from[j] = s;
          }
        }
        if (from[j] >= 0) used[from[j]] = true;
      }
      // What the slots not carried on dissipated stays in the totals: slot 0 keeps it.
      for (int s = 0; s < MeshContact::kMaxSubs; ++s)
        if (!used[s]) {
          lost_f += last[s].state.dissip_friction;
          lost_v += last[s].state.dissip_viscous;
        }
    }
    if (nk == 0) {
      if (c.active) {
        c.active = false;
        for (MeshSub& s : c.subs) s = MeshSub{};
        c.subs[0].state.dissip_friction = lost_f;
        c.subs[0].state.dissip_viscous = lost_v;
      }
      continue;
    }
    Real worst = 0;
    for (int j = 0; j < nk; ++j) worst = std::max(worst, r - keep[j].dist);
    if (!(worst <= max_overlap_ratio_ * r)) {
      err = std::min(err, k);
      continue;
    }
    if (!c.active || c.phys_version != phys_version_) {
      c.phys = mix_materials(materials_[w.material], materials_[bodies_.material[b]], kInf,
                             stiffness_radius(b), kInf, bodies_.mass[b],
                             pair_law(w.material, bodies_.material[b]));
      c.phys_version = phys_version_;
      note_formed_contact(c.phys, b, -1);
    }
    c.active = true;
    const bool simple = short_kernel_applies(c.phys);
    for (int j = 0; j < MeshContact::kMaxSubs; ++j) {
      MeshSub& s = c.subs[j];
      if (j >= nk) {
        // (in place, the slots beyond nk are empty already: reset at the last step)
        if (!in_place) s = MeshSub{};
        continue;
      }
      const Touch& h = keep[j];
      if (!in_place) {
        s = MeshSub{};
        if (from[j] >= 0) s.state = old[from[j]].state;
        s.kind = h.kind;
        s.a = h.a;
        s.b = h.b;
      }
      Vec3 rolling = Vec3::Zero();  // (the law's moment on the sphere beyond its branch's)
      if (simple) {
        // The short kernel (laws/linear.hpp): apply_law's lines for a linear law without
        // dashpots or rolling resistance, without its geometry record or its dispatch. The
        // zero terms it adds (the shear dashpot's force, the rolling moment) are added here
        // too, so a -0 component comes out as apply_law's +0: the same bits.
        const Real overlap = r - h.dist;
        const Vec3 branch2 = -(r - 0.5 * overlap) * h.n;
        const Vec3 rel_vel = (bodies_.vel[b] + bodies_.angvel[b].cross(branch2)) - w.velocity;
        ContactState& st = s.state;
        const Real fn = linear_frictional<NarrowOps>(st.fs, st.normal, h.n, overlap, rel_vel,
                                                     bodies_.angvel[b], c.phys.kn, c.phys.ks,
                                                     c.phys.tan_phi, dt, st.dissip_friction);
        st.normal = h.n;
        st.overlap = overlap;
        st.fn = fn;
        s.force = fn * h.n + st.fs + Vec3::Zero();
        s.torque = branch2.cross(s.force) + Vec3::Zero();
        s.point = x + branch2;
      } else {
      ContactGeometry g;
      g.overlap = r - h.dist;
      g.normal = h.n;
      g.branch2 = -(r - 0.5 * g.overlap) * h.n;
      g.branch1 = x + g.branch2;
      g.rel_vel = (bodies_.vel[b] + bodies_.angvel[b].cross(g.branch2)) - w.velocity;
      g.angvel_sum = bodies_.angvel[b];
      g.rel_angvel = bodies_.angvel[b];
      const LawOutput out = apply_law(c.phys, g, dt, s.state);
      s.force = out.force2;
      s.torque = g.branch2.cross(out.force2) + out.moment2;
      s.point = x + g.branch2;
      rolling = out.moment2;
      }
      // The mesh's share (the totals below and the reduction into bodies): the force and the
      // torque on the sphere, and their moment about the mesh's ref, the law's rolling moment
      // included.
      mesh_sum_f_[MeshContact::kMaxSubs * k + j] = s.force;
      mesh_sum_t_[MeshContact::kMaxSubs * k + j] = s.torque;
      mesh_sum_m_[MeshContact::kMaxSubs * k + j] = (s.point - w.ref).cross(s.force) + rolling;
    }
    mesh_sum_code_[k] = 4 * c.wall + nk;
    c.subs[0].state.dissip_friction += lost_f;
    c.subs[0].state.dissip_viscous += lost_v;
  }
  }
  err_contact = err;
  mesh_dropped_ += dropped;
  if (err != std::numeric_limits<long>::max()) return;
  // The meshes' force, moment (about ref) and work, summed in contact order (from the pass's
  // shares: a touching pair's contacts are its first nk slots, in slot order).
  for (MeshWall& w : mesh_walls_) {
    w.force.setZero();
    w.moment.setZero();
  }
  for (long k = 0; k < nc; ++k) {
    const int code = mesh_sum_code_[k];
    if (code == 0) continue;
    MeshWall& w = mesh_walls_[code / 4];
    for (long q = MeshContact::kMaxSubs * k, e = q + code % 4; q < e; ++q) {
      const Vec3& f = mesh_sum_f_[q];
      w.force -= f;
      w.moment -= mesh_sum_m_[q];
      w.work += f.dot(w.velocity) * dt;
    }
  }
}

void Scene::raise_mesh_overlap(long k) const {
  const MeshContact& c = mesh_contacts_[k];
  std::ostringstream os;
  os.precision(4);
  os << "blow-up at step " << step_ << ": body " << id_of(c.body) << " overlaps mesh wall "
     << c.wall << " by more than max_overlap_ratio=" << max_overlap_ratio_ << " of its radius"
     << (step_ == 0 ? " (the initial configuration overlaps this much: move the bodies apart)"
                    : " (the time step may be too large, the contact too soft or the mesh too "
                      "fast)")
     << blow_up_hint(c.body);
  throw BlowUpError(os.str());
}

void Scene::move_mesh_walls() {
  for (MeshWall& w : mesh_walls_) {
    if (w.velocity.isZero(0)) continue;
    const Vec3 dx = w.velocity * dt_;
    for (int v = 0; v < w.nvert; ++v) mesh_vertices_[w.vert_off + v] += dx;
    w.ref += dx;
    w.moved_since_build += dx.norm();
  }
}

}  // namespace cpp_dem
