// Geogrid: grid nodes, cohesive links, grain–geogrid contacts (000 §2.2, eqs 7–19).
#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr long kParallelMinGrid = 128;
}

// ---- building -------------------------------------------------------------------------------

int Scene::add_grid_nodes(const std::vector<Vec3>& pos, Real radius,
                          const std::vector<Real>& mass, const std::vector<Real>& inertia,
                          int material) {
  this->material(material);
  require(std::isfinite(radius) && radius > 0, "radius", radius, "must be > 0 (m)");
  if (mass.size() != pos.size() || inertia.size() != pos.size())
    throw ParameterError("mass, inertia: need one value per node (" +
                         std::to_string(pos.size()) + ")");
  for (size_t k = 0; k < pos.size(); ++k) {
    require(std::isfinite(mass[k]) && mass[k] > 0, "mass", mass[k], "must be > 0 (kg)");
    require(std::isfinite(inertia[k]) && inertia[k] > 0, "inertia", inertia[k],
            "must be > 0 (kg m^2)");
    if (!pos[k].allFinite())
      throw ParameterError("position of node " + std::to_string(k) + ": must be finite");
  }
  const int first = num_bodies();
  for (size_t k = 0; k < pos.size(); ++k) push_body(pos[k], radius, mass[k], inertia[k], material, 1);
  num_nodes_ += static_cast<int>(pos.size());
  dirty_ = true;
  grid_topology_dirty_ = true;
  return first;
}

int Scene::add_grid_link(int a, int b, const BeamParams& params, int material) {
  check_body(a);
  check_body(b);
  if (kind_[a] != 1 || kind_[b] != 1)
    throw ParameterError("link " + std::to_string(a) + "-" + std::to_string(b) +
                         ": both bodies must be grid nodes");
  if (a == b) throw ParameterError("link: nodes a and b must differ (got " + std::to_string(a) + ")");
  this->material(material);
  params.validate();
  const Vec3 d = pos_[b] - pos_[a];
  const Real length = d.norm();
  if (!(length > 0))
    throw ParameterError("link " + std::to_string(a) + "-" + std::to_string(b) +
                         ": nodes coincide (length 0)");
  GridLink l;
  l.a = a;
  l.b = b;
  l.material = material;
  beam_stiffness(params, length, l);
  l.normal = d / length;
  links_.push_back(l);
  dirty_ = true;
  grid_topology_dirty_ = true;
  return static_cast<int>(links_.size()) - 1;
}

int Scene::add_pfacet(int n0, int n1, int n2, int l01, int l12, int l20, int material) {
  const int nodes[3] = {n0, n1, n2};
  const int lk[3] = {l01, l12, l20};
  this->material(material);
  for (int k = 0; k < 3; ++k) {
    check_body(nodes[k]);
    if (lk[k] < 0 || lk[k] >= num_grid_links())
      throw ParameterError("link=" + std::to_string(lk[k]) + ": no such grid link");
    const GridLink& l = links_[lk[k]];
    const int p = nodes[k], q = nodes[(k + 1) % 3];
    if (!((l.a == p && l.b == q) || (l.a == q && l.b == p)))
      throw ParameterError("pfacet: link " + std::to_string(lk[k]) + " does not join nodes " +
                           std::to_string(p) + " and " + std::to_string(q));
    if (links_[lk[k]].radius != links_[l01].radius)
      throw ParameterError("pfacet: its three links must have the same radius");
  }
  if (((pos_[n1] - pos_[n0]).cross(pos_[n2] - pos_[n0])).norm() <= 0)
    throw ParameterError("pfacet: nodes are collinear");
  PFacet f;
  for (int k = 0; k < 3; ++k) {
    f.n[k] = nodes[k];
    f.link[k] = lk[k];
  }
  f.material = material;
  f.radius = links_[l01].radius;
  facets_.push_back(f);
  dirty_ = true;
  grid_topology_dirty_ = true;
  return static_cast<int>(facets_.size()) - 1;
}

void Scene::rebuild_grid_adjacency() {
  const int n = num_bodies();
  node_link_off_.assign(n + 1, 0);
  for (const GridLink& l : links_) {
    node_link_off_[l.a + 1]++;
    node_link_off_[l.b + 1]++;
  }
  for (int b = 0; b < n; ++b) node_link_off_[b + 1] += node_link_off_[b];
  node_link_.resize(node_link_off_[n]);
  std::vector<int> fill(node_link_off_.begin(), node_link_off_.end() - 1);
  for (int k = 0; k < num_grid_links(); ++k) {
    node_link_[fill[links_[k].a]++] = k;
    node_link_[fill[links_[k].b]++] = k;
  }
  link_facet_.assign(2 * links_.size(), -1);
  for (int f = 0; f < num_pfacets(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int l = facets_[f].link[k];
      if (link_facet_[2 * l] < 0) link_facet_[2 * l] = f;
      else if (link_facet_[2 * l + 1] < 0) link_facet_[2 * l + 1] = f;
      else throw ParameterError("link " + std::to_string(l) + ": has more than two pfacets");
    }
  grid_topology_dirty_ = false;
}

// ---- broad phase for grain–geogrid contacts ----------------------------------------------------

namespace {
/// Distance from x to the segment [a, b], m.
Real segment_distance(const Vec3& a, const Vec3& b, const Vec3& x) {
  const Real t = std::min(std::max(segment_parameter(a, b, x), 0.0), 1.0);
  return (x - ((1 - t) * a + t * b)).norm();
}
}  // namespace

Real Scene::skeleton_distance(const int* nodes, int nn, const Vec3& x) const {
  if (nn == 1) return (x - pos_[nodes[0]]).norm();
  if (nn == 2) return segment_distance(pos_[nodes[0]], pos_[nodes[1]], x);
  const Vec3 &a = pos_[nodes[0]], &b = pos_[nodes[1]], &c = pos_[nodes[2]];
  const Eigen::Vector3d p = barycentric(a, b, c, x);
  if (p.minCoeff() >= 0) return (x - (p[0] * a + p[1] * b + p[2] * c)).norm();
  return std::min({segment_distance(a, b, x), segment_distance(b, c, x),
                   segment_distance(c, a, x)});
}

void Scene::rebuild_grid_contacts(Real margin) {
  if (grid_topology_dirty_) rebuild_grid_adjacency();
  using Key = std::tuple<int, int, int>;  // sphere, kind, primitive
  std::vector<Key> keys;
  std::vector<int> found;
  auto collect = [&](GridPrimitive kind, int prim, const int* nodes, int nn, Real rc) {
    Vec3 lo = pos_[nodes[0]], hi = pos_[nodes[0]];
    for (int k = 1; k < nn; ++k) {
      lo = lo.cwiseMin(pos_[nodes[k]]);
      hi = hi.cwiseMax(pos_[nodes[k]]);
    }
    found.clear();
    grid_.query_box(lo - Vec3::Constant(rc), hi + Vec3::Constant(rc), pos_, radius_, margin, found);
    // Keep only the grains within reach of the primitive itself (not just of its box).
    for (int s : found) {
      const Real reach = radius_[s] + rc + margin;
      if (skeleton_distance(nodes, nn, pos_[s]) < reach)
        keys.emplace_back(s, static_cast<int>(kind), prim);
    }
  };
  for (int b = 0; b < num_bodies(); ++b)
    if (kind_[b] == 1 && node_link_off_[b + 1] > node_link_off_[b])
      collect(GridPrimitive::Node, b, &b, 1, radius_[b]);
  for (int k = 0; k < num_grid_links(); ++k) {
    if (links_[k].broken) continue;
    const int nn[2] = {links_[k].a, links_[k].b};
    collect(GridPrimitive::Connection, k, nn, 2, links_[k].radius);
  }
  for (int f = 0; f < num_pfacets(); ++f)
    collect(GridPrimitive::Facet, f, facets_[f].n, 3, facets_[f].radius);
  std::sort(keys.begin(), keys.end());
  // Merge with the existing contacts (both sorted), keeping history.
  std::vector<GridContact> next;
  next.reserve(keys.size());
  size_t k = 0;
  auto key_of = [](const GridContact& c) {
    return Key(c.sphere, static_cast<int>(c.kind), c.prim);
  };
  for (const Key& key : keys) {
    while (k < grid_contacts_.size() && key_of(grid_contacts_[k]) < key) {
      drop_dissipation(grid_contacts_[k].state);
      ++k;
    }
    if (k < grid_contacts_.size() && key_of(grid_contacts_[k]) == key) {
      next.push_back(grid_contacts_[k++]);
      continue;
    }
    GridContact c;
    c.sphere = std::get<0>(key);
    c.kind = static_cast<GridPrimitive>(std::get<1>(key));
    c.prim = std::get<2>(key);
    if (c.kind == GridPrimitive::Node) {
      c.nnodes = 1;
      c.node[0] = c.prim;
      c.rc = radius_[c.prim];
    } else if (c.kind == GridPrimitive::Connection) {
      c.nnodes = 2;
      c.node[0] = links_[c.prim].a;
      c.node[1] = links_[c.prim].b;
      c.rc = links_[c.prim].radius;
    } else {
      c.nnodes = 3;
      for (int i = 0; i < 3; ++i) c.node[i] = facets_[c.prim].n[i];
      c.rc = facets_[c.prim].radius;
    }
    next.push_back(c);
  }
  for (; k < grid_contacts_.size(); ++k) {
    drop_dissipation(grid_contacts_[k].state);
  }
  grid_contacts_.swap(next);
  // Adjacency for the reductions: sphere -> contacts, node -> (contact, slot).
  const int n = num_bodies();
  sphere_gc_off_.assign(n + 1, 0);
  node_gc_off_.assign(n + 1, 0);
  for (const GridContact& c : grid_contacts_) {
    sphere_gc_off_[c.sphere + 1]++;
    for (int i = 0; i < c.nnodes; ++i) node_gc_off_[c.node[i] + 1]++;
  }
  for (int b = 0; b < n; ++b) {
    sphere_gc_off_[b + 1] += sphere_gc_off_[b];
    node_gc_off_[b + 1] += node_gc_off_[b];
  }
  sphere_gc_.resize(sphere_gc_off_[n]);
  node_gc_.resize(node_gc_off_[n]);
  std::vector<int> fs(sphere_gc_off_.begin(), sphere_gc_off_.end() - 1);
  std::vector<int> fn(node_gc_off_.begin(), node_gc_off_.end() - 1);
  for (int c = 0; c < static_cast<int>(grid_contacts_.size()); ++c) {
    const GridContact& gc = grid_contacts_[c];
    sphere_gc_[fs[gc.sphere]++] = c;
    for (int i = 0; i < gc.nnodes; ++i) node_gc_[fn[gc.node[i]]++] = 3 * c + i;
  }
}

void Scene::update_phys(GridContact& c) const {
  // The virtual sphere: radius R_c, mass interpolated from the nodes.
  Real m_virtual = 0;
  for (int i = 0; i < c.nnodes; ++i) m_virtual += c.w[i] * mass_[c.node[i]];
  c.phys = mix_materials(materials_[body_mat_[c.node[0]]], materials_[body_mat_[c.sphere]], c.rc,
                         radius_[c.sphere], m_virtual, mass_[c.sphere]);
  c.phys_version = phys_version_;
}

// ---- grain–geogrid contacts -------------------------------------------------------------------

void Scene::compute_grid_contacts(long& err_contact) {
  if (grid_topology_dirty_) rebuild_grid_adjacency();
  const long nc = static_cast<long>(grid_contacts_.size());
  const Real dt = dt_;
  auto facet_alive = [&](int f) {
    for (int k = 0; k < 3; ++k)
      if (links_[facets_[f].link[k]].broken) return false;
    return true;
  };
  // A. Geometry and ownership: only the primitive whose relative interior holds a local
  //    minimum of the distance from the grain centre to the skeleton owns the contact.
#pragma omp parallel for schedule(static) if (nc > kParallelMinGrid)
  for (long k = 0; k < nc; ++k) {
    GridContact& c = grid_contacts_[k];
    const Vec3& x = pos_[c.sphere];
    const Real reach = radius_[c.sphere] + c.rc;
    Vec3 q;
    bool own = false;
    if (c.kind == GridPrimitive::Node) {
      q = pos_[c.prim];
      own = (x - q).squaredNorm() < reach * reach;
      for (int e = node_link_off_[c.prim]; own && e < node_link_off_[c.prim + 1]; ++e) {
        const GridLink& l = links_[node_link_[e]];
        if (l.broken) continue;
        const Vec3 u = pos_[l.a == c.prim ? l.b : l.a] - q;  // outward along the link
        own = (x - q).dot(u) <= 0;
      }
      c.w[0] = 1;
    } else if (c.kind == GridPrimitive::Connection) {
      const GridLink& l = links_[c.prim];
      const Real t = segment_parameter(pos_[l.a], pos_[l.b], x);
      q = (1 - t) * pos_[l.a] + t * pos_[l.b];
      own = !l.broken && t > 0 && t < 1 && (x - q).squaredNorm() < reach * reach;
      for (int side = 0; own && side < 2; ++side) {
        const int f = link_facet_[2 * c.prim + side];
        if (f < 0 || !facet_alive(f)) continue;
        int third = facets_[f].n[0];
        for (int i = 0; i < 3; ++i)
          if (facets_[f].n[i] != l.a && facets_[f].n[i] != l.b) third = facets_[f].n[i];
        const Vec3 edge = pos_[l.b] - pos_[l.a];
        Vec3 inward = pos_[third] - pos_[l.a];
        inward -= inward.dot(edge) / edge.squaredNorm() * edge;  // in-plane, towards third
        own = (x - q).dot(inward) <= 0;
      }
      c.w[0] = 1 - t;
      c.w[1] = t;
    } else {
      const PFacet& f = facets_[c.prim];
      const Eigen::Vector3d p = barycentric(pos_[f.n[0]], pos_[f.n[1]], pos_[f.n[2]], x);
      q = p[0] * pos_[f.n[0]] + p[1] * pos_[f.n[1]] + p[2] * pos_[f.n[2]];
      own = facet_alive(c.prim) && p[0] > 0 && p[1] > 0 && p[2] > 0 &&
            (x - q).squaredNorm() < reach * reach;  // 000 eq (14)
      for (int i = 0; i < 3; ++i) c.w[i] = p[i];    // 000 eqs (13), (15), (16)
    }
    c.owner = own;
    if (!own) continue;
    ContactGeometry& g = c.geom;
    const Real dist = (x - q).norm();
    g.normal = dist > 0 ? Vec3((x - q) / dist) : Vec3(Vec3::UnitZ());
    g.overlap = reach - dist;
    g.branch1 = (c.rc - 0.5 * g.overlap) * g.normal;
    g.branch2 = -(radius_[c.sphere] - 0.5 * g.overlap) * g.normal;
    // Virtual-sphere velocities interpolated from the nodes, 000 eqs (17), (18).
    Vec3 vq = Vec3::Zero(), wq = Vec3::Zero();
    for (int i = 0; i < c.nnodes; ++i) {
      vq += c.w[i] * vel_[c.node[i]];
      wq += c.w[i] * angvel_[c.node[i]];
    }
    const int s = c.sphere;
    g.rel_vel = (vel_[s] + angvel_[s].cross(g.branch2)) - (vq + wq.cross(g.branch1));
    g.angvel_sum = wq + angvel_[s];
    g.rel_angvel = angvel_[s] - wq;
  }
  // B. Hand-over: a grain whose contact moved to an adjacent primitive (across a node or an
  //    edge) keeps its shear history, so it has one continuous contact.
  const int n = num_bodies();
#pragma omp parallel for schedule(static) if (n > kParallelMinGrid)
  for (int s = 0; s < n; ++s) {
    const int e0 = sphere_gc_off_[s], e1 = sphere_gc_off_[s + 1];
    if (e1 - e0 < 2) continue;
    for (int e = e0; e < e1; ++e) {
      GridContact& g = grid_contacts_[sphere_gc_[e]];
      if (g.active || !g.owner) continue;
      for (int f = e0; f < e1; ++f) {
        GridContact& l = grid_contacts_[sphere_gc_[f]];
        if (!l.active || l.owner) continue;
        bool shares = false;
        for (int i = 0; i < g.nnodes && !shares; ++i)
          for (int j = 0; j < l.nnodes; ++j) shares = shares || g.node[i] == l.node[j];
        if (!shares) continue;
        g.state.fs = l.state.fs;
        g.state.mr = l.state.mr;
        g.state.normal = l.state.normal;
        l.state.fs.setZero();
        l.state.mr.setZero();
        l.active = false;  // its history now lives in g
        l.force.setZero();
        break;
      }
    }
  }
  // C. The law on every owned, overlapping contact.
  const Real max_ratio = max_overlap_ratio_;
  long err = std::numeric_limits<long>::max();
#pragma omp parallel for schedule(static) reduction(min : err) if (nc > kParallelMinGrid)
  for (long k = 0; k < nc; ++k) {
    GridContact& c = grid_contacts_[k];
    if (!c.owner) {
      if (c.active) {
        c.active = false;
        c.state.clear_history();
      }
      c.force.setZero();
      c.torque_sphere.setZero();
      c.torque_virtual.setZero();
      continue;
    }
    if (!(c.geom.overlap <= max_ratio * radius_[c.sphere])) {
      err = std::min(err, k);
      continue;
    }
    if (!c.active || c.phys_version != phys_version_) update_phys(c);
    c.active = true;
    const LawOutput out = apply_law(c.phys, c.geom, dt, c.state);
    c.force = out.force2;
    c.torque_sphere = c.geom.branch2.cross(out.force2) + out.moment2;
    c.torque_virtual = c.geom.branch1.cross(-out.force2) - out.moment2;
  }
  err_contact = err;
}

// ---- cohesive links (000 eqs 7–12) ------------------------------------------------------------

void Scene::compute_links() {
  const long nl = static_cast<long>(links_.size());
  const Real dt = dt_;
#pragma omp parallel for schedule(static) if (nl > kParallelMinGrid)
  for (long k = 0; k < nl; ++k) {
    GridLink& l = links_[k];
    if (l.broken) continue;
    const Vec3 d = pos_[l.b] - pos_[l.a];
    const Real len = d.norm();
    const Vec3 n = d / len;
    // Keep the shear force and bending moment in the rotated frame of the link.
    const Vec3 axis = l.normal.cross(n);
    const Vec3 twist = (0.5 * dt * n.dot(angvel_[l.a] + angvel_[l.b])) * n;
    l.fs -= l.fs.cross(axis);
    l.fs -= l.fs.cross(twist);
    l.fs -= l.fs.dot(n) * n;
    l.mb -= l.mb.cross(axis);
    l.mb -= l.mb.cross(twist);
    l.mb -= l.mb.dot(n) * n;
    l.normal = n;
    // Axial force, tension positive: k_n (L - L0), eq (7).
    l.fn = l.kn * (len - l.length0);
    // Shear at the middle of the link, eq (8); this with eq (9) gives the Euler–Bernoulli
    // beam element exactly for small rotations.
    const Vec3 ba = 0.5 * len * n, bb = -0.5 * len * n;
    const Vec3 vrel = (vel_[l.b] + angvel_[l.b].cross(bb)) - (vel_[l.a] + angvel_[l.a].cross(ba));
    l.fs -= l.ks * dt * (vrel - vrel.dot(n) * n);
    // Bending, eq (9), and twisting, eq (10).
    const Vec3 wrel = angvel_[l.b] - angvel_[l.a];
    const Real wtw = wrel.dot(n);
    l.mb -= l.kr * dt * (wrel - wtw * n);
    l.mt -= l.ktw * dt * wtw;
    // Elastic limits of the moments, eqs (11), (12): perfectly plastic beyond.
    if (l.mr_max > 0 && l.mb.norm() > l.mr_max) {
      const Vec3 trial = l.mb;
      l.mb *= l.mr_max / l.mb.norm();
      l.dissip_plastic += (trial - l.mb).dot(l.mb) / l.kr;
    }
    if (l.mtw_max > 0 && std::abs(l.mt) > l.mtw_max) {
      const Real trial = l.mt;
      l.mt = std::copysign(l.mtw_max, l.mt);
      l.dissip_plastic += (trial - l.mt) * l.mt / l.ktw;
    }
    // Breakage at the tensile or shear strength (the normal and shear cohesion).
    l.pending_break = -1;
    if (l.fn_max > 0 && l.fn >= l.fn_max) l.pending_break = 0;
    else if (l.fs_max > 0 && l.fs.norm() >= l.fs_max) l.pending_break = 1;
    l.force_b = -l.fn * n + l.fs;
    const Vec3 m = l.mb + l.mt * n;
    l.torque_b = bb.cross(l.force_b) + m;
    l.torque_a = ba.cross(-l.force_b) - m;
  }
  // Breakage events, in link order: the link is removed and the event recorded.
  for (long k = 0; k < nl; ++k) {
    GridLink& l = links_[k];
    if (l.broken || l.pending_break < 0) continue;
    BreakEvent ev;
    ev.step = step_;
    ev.time = time_;
    ev.link = static_cast<int>(k);
    ev.reason = l.pending_break;
    ev.force = l.pending_break == 0 ? l.fn : l.fs.norm();
    breaks_.push_back(ev);
    dropped_plastic_ += l.elastic_energy();
    l.broken = true;
    l.pending_break = -1;
    l.force_b.setZero();
    l.torque_a.setZero();
    l.torque_b.setZero();
  }
}

}  // namespace cpp_dem
