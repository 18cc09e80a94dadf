// Building the geogrid (grid nodes, cohesive links, PFacets; 000 §2.2) and the broad phase of
// its contacts with grains.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <tuple>

#include "cpp_dem/geometry/sphere_grid.hpp"
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
  if (cell_.on)
    throw ParameterError("grid nodes: the scene has a periodic cell; a geogrid in a periodic "
                         "cell is not supported yet");
  require(std::isfinite(radius) && radius > 0, "radius", radius, "must be > 0 (m)");
  if (mass.size() != pos.size() || inertia.size() != pos.size())
    throw ParameterError("mass, inertia: need one value per node (" +
                         std::to_string(pos.size()) + ")");
  for (size_t k = 0; k < pos.size(); ++k) {
    // The position first: a non-finite node also makes its lumped mass non-finite.
    if (!pos[k].allFinite()) {
      std::ostringstream os;
      os << "positions[" << k << "]=(" << pos[k][0] << ", " << pos[k][1] << ", " << pos[k][2]
         << ") of a grid node: must be 3 finite numbers (m)";
      throw ParameterError(os.str());
    }
    require(std::isfinite(mass[k]) && mass[k] > 0, "mass", mass[k], "must be > 0 (kg)");
    require(std::isfinite(inertia[k]) && inertia[k] > 0, "inertia", inertia[k],
            "must be > 0 (kg m^2)");
  }
  const int first = num_bodies();
  for (size_t k = 0; k < pos.size(); ++k) push_body(pos[k], radius, mass[k], inertia[k], material, BODY_GRID_NODE);
  num_nodes_ += static_cast<int>(pos.size());
  dirty_ = true;
  grid_topology_dirty_ = true;
  return first;
}

int Scene::add_grid_link(int a, int b, const BeamParams& params, int material) {
  check_body(a);
  check_body(b);
  if (bodies_.kind[a] != BODY_GRID_NODE || bodies_.kind[b] != BODY_GRID_NODE)
    throw ParameterError("link " + std::to_string(a) + "-" + std::to_string(b) +
                         ": both bodies must be grid nodes");
  if (a == b) throw ParameterError("link: nodes a and b must differ (got " + std::to_string(a) + ")");
  this->material(material);
  params.validate();
  const Vec3 d = bodies_.pos[b] - bodies_.pos[a];
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
  if (((bodies_.pos[n1] - bodies_.pos[n0]).cross(bodies_.pos[n2] - bodies_.pos[n0])).norm() <= 0)
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

Real Scene::skeleton_distance(const int* nodes, int nn, const Vec3& x) const {
  if (nn == 1) return (x - bodies_.pos[nodes[0]]).norm();
  if (nn == 2) return segment_distance(bodies_.pos[nodes[0]], bodies_.pos[nodes[1]], x);
  const Vec3 &a = bodies_.pos[nodes[0]], &b = bodies_.pos[nodes[1]], &c = bodies_.pos[nodes[2]];
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
    Vec3 lo = bodies_.pos[nodes[0]], hi = bodies_.pos[nodes[0]];
    for (int k = 1; k < nn; ++k) {
      lo = lo.cwiseMin(bodies_.pos[nodes[k]]);
      hi = hi.cwiseMax(bodies_.pos[nodes[k]]);
    }
    found.clear();
    grid_.query_box(lo - Vec3::Constant(rc), hi + Vec3::Constant(rc), bodies_.pos, bodies_.radius, margin, found);
    // Keep only the grains within reach of the primitive itself (not just of its box).
    for (int s : found) {
      const Real reach = bodies_.radius[s] + rc + margin;
      if (skeleton_distance(nodes, nn, bodies_.pos[s]) < reach)
        keys.emplace_back(s, static_cast<int>(kind), prim);
    }
  };
  for (int b = 0; b < num_bodies(); ++b)
    if (bodies_.kind[b] == BODY_GRID_NODE && node_link_off_[b + 1] > node_link_off_[b])
      collect(GridPrimitive::Node, b, &b, 1, bodies_.radius[b]);
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
      c.rc = bodies_.radius[c.prim];
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
  index_grid_contacts();
}

}  // namespace cpp_dem
