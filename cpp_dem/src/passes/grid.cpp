// The grain–geogrid pass: geometry through the virtual sphere (000 eqs 13–19), the hand-over
// of a contact between adjacent primitives, and the composed law.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "cpp_dem/geometry/sphere_grid.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr long kParallelMinGrid = 128;
}

void Scene::update_phys(GridContact& c) const {
  // The virtual sphere: radius R_c, mass interpolated from the nodes.
  Real m_virtual = 0;
  for (int i = 0; i < c.nnodes; ++i) m_virtual += c.w[i] * bodies_.mass[c.node[i]];
  c.phys = mix_materials(materials_[bodies_.material[c.node[0]]], materials_[bodies_.material[c.sphere]], c.rc,
                         stiffness_radius(c.sphere), m_virtual, bodies_.mass[c.sphere],
                         pair_law(bodies_.material[c.node[0]], bodies_.material[c.sphere]));
  c.phys_version = phys_version_;
  note_formed_contact(c.phys, c.sphere, -1);  // (the nodes' links bound their own step)
}

// ---- grain–geogrid contacts -------------------------------------------------------------------

void Scene::index_grid_contacts() {
  const size_t nc = grid_contacts_.size();
  grid_hot_.resize(nc);
  grid_live_.resize(nc);
  for (size_t k = 0; k < nc; ++k) {
    const GridContact& c = grid_contacts_[k];
    GridHot& h = grid_hot_[k];
    h.sphere = c.sphere;
    h.prim = c.prim;
    for (int i = 0; i < 3; ++i) h.node[i] = c.node[i];
    h.kind = c.kind;
    h.nnodes = static_cast<std::uint8_t>(c.nnodes);
    h.rc = c.rc;
    grid_live_[k] = static_cast<std::uint8_t>((c.owner ? kGridOwner : 0) |
                                              (c.active ? kGridActive : 0));
  }
}

void Scene::compute_grid_contacts(long& err_contact) {
  if (grid_topology_dirty_) rebuild_grid_adjacency();
  if (grid_hot_.size() != grid_contacts_.size())  // (a rebuild or a load indexes them)
    throw std::logic_error("grid contacts not indexed: " + std::to_string(grid_contacts_.size()) +
                           " contacts, " + std::to_string(grid_hot_.size()) + " indexed");
  const long nc = static_cast<long>(grid_contacts_.size());
  const Real dt = dt_;
  auto facet_alive = [&](int f) {
    for (int k = 0; k < 3; ++k)
      if (links_[facets_[f].link[k]].broken) return false;
    return true;
  };
  // Each grain's candidates in turn (they are contiguous in contact order), all three
  // parts while its contacts are in the cache; a grain's parts read no other grain's
  // contacts.
  // A. Geometry and ownership: only the primitive whose relative interior holds a local
  //    minimum of the distance from the grain centre to the skeleton owns the contact. The
  //    packed fields (grid_hot_) decide it; the contact itself is read and written only
  //    where it owns, or owned at the last step.
  const auto own_geometry = [&](long k) {
    const GridHot& h = grid_hot_[k];
    const Vec3& x = bodies_.pos[h.sphere];
    const Real reach = bodies_.radius[h.sphere] + h.rc;
    Vec3 q;
    Real w[3] = {0, 0, 0};
    bool own = false;
    if (h.kind == GridPrimitive::Node) {
      q = bodies_.pos[h.prim];
      own = (x - q).squaredNorm() < reach * reach;
      for (int e = node_link_off_[h.prim]; own && e < node_link_off_[h.prim + 1]; ++e) {
        const GridLink& l = links_[node_link_[e]];
        if (l.broken) continue;
        const Vec3 u = bodies_.pos[l.a == h.prim ? l.b : l.a] - q;  // outward along the link
        own = (x - q).dot(u) <= 0;
      }
      w[0] = 1;
    } else if (h.kind == GridPrimitive::Connection) {
      const Vec3 &a = bodies_.pos[h.node[0]], &b = bodies_.pos[h.node[1]];  // the link's a, b
      const Real t = segment_parameter(a, b, x);
      q = (1 - t) * a + t * b;
      own = t > 0 && t < 1 && (x - q).squaredNorm() < reach * reach && !links_[h.prim].broken;
      for (int side = 0; own && side < 2; ++side) {
        const int f = link_facet_[2 * h.prim + side];
        if (f < 0 || !facet_alive(f)) continue;
        int third = facets_[f].n[0];
        for (int i = 0; i < 3; ++i)
          if (facets_[f].n[i] != h.node[0] && facets_[f].n[i] != h.node[1]) third = facets_[f].n[i];
        const Vec3 edge = b - a;
        Vec3 inward = bodies_.pos[third] - a;
        inward -= inward.dot(edge) / edge.squaredNorm() * edge;  // in-plane, towards third
        own = (x - q).dot(inward) <= 0;
      }
      w[0] = 1 - t;
      w[1] = t;
    } else {
      const Vec3 &n0 = bodies_.pos[h.node[0]], &n1 = bodies_.pos[h.node[1]],
                 &n2 = bodies_.pos[h.node[2]];  // the facet's nodes
      const Eigen::Vector3d p = barycentric(n0, n1, n2, x);
      q = p[0] * n0 + p[1] * n1 + p[2] * n2;
      own = p[0] > 0 && p[1] > 0 && p[2] > 0 && (x - q).squaredNorm() < reach * reach &&
            facet_alive(h.prim);  // 000 eq (14)
      for (int i = 0; i < 3; ++i) w[i] = p[i];  // 000 eqs (13), (15), (16)
    }
    const std::uint8_t live = grid_live_[k];
    if (!own) {
      if (live & kGridOwner) {
        grid_contacts_[k].owner = false;
        grid_live_[k] = live & ~kGridOwner;
      }
      return;
    }
    GridContact& c = grid_contacts_[k];
    for (int i = 0; i < 3; ++i) c.w[i] = w[i];
    c.owner = true;
    grid_live_[k] = live | kGridOwner;
    // Virtual-sphere velocities interpolated from the nodes, 000 eqs (17), (18).
    Vec3 vq = Vec3::Zero(), wq = Vec3::Zero();
    for (int i = 0; i < h.nnodes; ++i) {
      vq += w[i] * bodies_.vel[h.node[i]];
      wq += w[i] * bodies_.angvel[h.node[i]];
    }
    const int s = h.sphere;
    c.geom = virtual_sphere_geometry(x, bodies_.radius[s], bodies_.vel[s], bodies_.angvel[s], q, h.rc, vq, wq);
  };
  // B. Hand-over: a grain whose contact moved to an adjacent primitive (across a node or an
  //    edge) keeps its shear history, so it has one continuous contact.
  const auto hand_over = [&](int e0, int e1) {
    for (int e = e0; e < e1; ++e) {
      const int gk = sphere_gc_[e];
      if (grid_live_[gk] != kGridOwner) continue;  // (owns, not active)
      const GridHot& g = grid_hot_[gk];
      for (int f = e0; f < e1; ++f) {
        const int lk = sphere_gc_[f];
        if (grid_live_[lk] != kGridActive) continue;  // (active, owns no more)
        const GridHot& l = grid_hot_[lk];
        bool shares = false;
        for (int i = 0; i < g.nnodes && !shares; ++i)
          for (int j = 0; j < l.nnodes; ++j) shares = shares || g.node[i] == l.node[j];
        if (!shares) continue;
        GridContact &gc = grid_contacts_[gk], &lc = grid_contacts_[lk];
        gc.state.fs = lc.state.fs;
        gc.state.mr = lc.state.mr;
        gc.state.normal = lc.state.normal;
        lc.state.fs.setZero();
        lc.state.mr.setZero();
        lc.active = false;  // its history now lives in g
        grid_live_[lk] = 0;
        lc.force.setZero();
        lc.torque_sphere.setZero();
        lc.torque_virtual.setZero();
        break;
      }
    }
  };
  // C. The law on every owned, overlapping contact; a contact that owns no more is closed
  //    (its force zero, its history cleared). err: the first contact that overlaps too far.
  const Real max_ratio = max_overlap_ratio_;
  const auto law = [&](long k, long& err) {
    const std::uint8_t live = grid_live_[k];
    if (!(live & kGridOwner)) {
      if (live & kGridActive) {
        GridContact& c = grid_contacts_[k];
        c.active = false;
        grid_live_[k] = 0;
        c.state.clear_history();
        c.force.setZero();
        c.torque_sphere.setZero();
        c.torque_virtual.setZero();
      }
      return;
    }
    GridContact& c = grid_contacts_[k];
    if (!(c.geom.overlap <= max_ratio * bodies_.radius[c.sphere])) {
      err = std::min(err, k);
      return;
    }
    if (!c.active || c.phys_version != phys_version_) update_phys(c);
    c.active = true;
    grid_live_[k] = kGridOwner | kGridActive;
    const LawOutput out = apply_law(c.phys, c.geom, dt, c.state);
    c.force = out.force2;
    c.torque_sphere = c.geom.branch2.cross(out.force2) + out.moment2;
    c.torque_virtual = c.geom.branch1.cross(-out.force2) - out.moment2;
  };
  const int n = num_bodies();
  long err = std::numeric_limits<long>::max();
  // (dynamic: the grains that have candidates can sit in one part of the body range)
#pragma omp parallel for schedule(dynamic, 32) reduction(min : err) if (nc > kParallelMinGrid)
  for (int s = 0; s < n; ++s) {
    const int e0 = sphere_gc_off_[s], e1 = sphere_gc_off_[s + 1];
    if (e0 == e1) continue;
    for (int e = e0; e < e1; ++e) own_geometry(sphere_gc_[e]);
    if (e1 - e0 >= 2) hand_over(e0, e1);
    for (int e = e0; e < e1; ++e) law(sphere_gc_[e], err);
  }
  err_contact = err;
}

}  // namespace cpp_dem
