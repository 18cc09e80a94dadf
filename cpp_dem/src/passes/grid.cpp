// The grain–geogrid pass: geometry through the virtual sphere (000 eqs 13–19), the hand-over
// of a contact between adjacent primitives, and the composed law.
#include <algorithm>
#include <cmath>
#include <limits>

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
    const Vec3& x = bodies_.pos[c.sphere];
    const Real reach = bodies_.radius[c.sphere] + c.rc;
    Vec3 q;
    bool own = false;
    if (c.kind == GridPrimitive::Node) {
      q = bodies_.pos[c.prim];
      own = (x - q).squaredNorm() < reach * reach;
      for (int e = node_link_off_[c.prim]; own && e < node_link_off_[c.prim + 1]; ++e) {
        const GridLink& l = links_[node_link_[e]];
        if (l.broken) continue;
        const Vec3 u = bodies_.pos[l.a == c.prim ? l.b : l.a] - q;  // outward along the link
        own = (x - q).dot(u) <= 0;
      }
      c.w[0] = 1;
    } else if (c.kind == GridPrimitive::Connection) {
      const GridLink& l = links_[c.prim];
      const Real t = segment_parameter(bodies_.pos[l.a], bodies_.pos[l.b], x);
      q = (1 - t) * bodies_.pos[l.a] + t * bodies_.pos[l.b];
      own = !l.broken && t > 0 && t < 1 && (x - q).squaredNorm() < reach * reach;
      for (int side = 0; own && side < 2; ++side) {
        const int f = link_facet_[2 * c.prim + side];
        if (f < 0 || !facet_alive(f)) continue;
        int third = facets_[f].n[0];
        for (int i = 0; i < 3; ++i)
          if (facets_[f].n[i] != l.a && facets_[f].n[i] != l.b) third = facets_[f].n[i];
        const Vec3 edge = bodies_.pos[l.b] - bodies_.pos[l.a];
        Vec3 inward = bodies_.pos[third] - bodies_.pos[l.a];
        inward -= inward.dot(edge) / edge.squaredNorm() * edge;  // in-plane, towards third
        own = (x - q).dot(inward) <= 0;
      }
      c.w[0] = 1 - t;
      c.w[1] = t;
    } else {
      const PFacet& f = facets_[c.prim];
      const Eigen::Vector3d p = barycentric(bodies_.pos[f.n[0]], bodies_.pos[f.n[1]], bodies_.pos[f.n[2]], x);
      q = p[0] * bodies_.pos[f.n[0]] + p[1] * bodies_.pos[f.n[1]] + p[2] * bodies_.pos[f.n[2]];
      own = facet_alive(c.prim) && p[0] > 0 && p[1] > 0 && p[2] > 0 &&
            (x - q).squaredNorm() < reach * reach;  // 000 eq (14)
      for (int i = 0; i < 3; ++i) c.w[i] = p[i];    // 000 eqs (13), (15), (16)
    }
    c.owner = own;
    if (!own) continue;
    // Virtual-sphere velocities interpolated from the nodes, 000 eqs (17), (18).
    Vec3 vq = Vec3::Zero(), wq = Vec3::Zero();
    for (int i = 0; i < c.nnodes; ++i) {
      vq += c.w[i] * bodies_.vel[c.node[i]];
      wq += c.w[i] * bodies_.angvel[c.node[i]];
    }
    const int s = c.sphere;
    c.geom = virtual_sphere_geometry(x, bodies_.radius[s], bodies_.vel[s], bodies_.angvel[s], q, c.rc, vq, wq);
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
    if (!(c.geom.overlap <= max_ratio * bodies_.radius[c.sphere])) {
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

}  // namespace cpp_dem
