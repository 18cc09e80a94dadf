// Triangle-mesh walls: a rigid surface of triangles (read from STL/OBJ in Python), moved as a
// whole, met by spheres at faces, edges and vertices without double counting.
#pragma once

#include <array>
#include <cstdint>

#include "cpp_dem/core/types.hpp"
#include "cpp_dem/laws/contact_law.hpp"

namespace cpp_dem {

/// A rigid triangle mesh (Scene::add_mesh_wall). Its vertices are Scene::mesh_vertices_
/// [vert_off, vert_off + nvert), its triangles Scene::mesh_tris_[tri_off, tri_off + ntri)
/// (indices into its own vertices). Two-sided: a sphere meets it from either side.
struct MeshWall {
  int vert_off = 0, nvert = 0, tri_off = 0, ntri = 0;
  int material = 0;
  int pad_ = 0;                  ///< zero (explicit padding: checkpoints are byte-identical)
  Vec3 velocity = Vec3::Zero();  ///< imposed velocity of the whole mesh, m/s
  Vec3 ref = Vec3::Zero();       ///< the point its moment is taken about (moves with it), m
  Vec3 force = Vec3::Zero();     ///< force exerted by the spheres on it (last step), N
  Vec3 moment = Vec3::Zero();    ///< their moment about `ref` (last step), N m
  Real work = 0;                 ///< work done by it on the spheres, cumulative, J
  Real moved_since_build = 0;    ///< its displacement since the last build, m
};

/// Where on a triangle a closest point lies: its interior, an edge, or a vertex.
enum MeshFeature : std::int32_t { kFace = 0, kEdge = 1, kVertex = 2 };

/// The closest point p of triangle (a, b, c) to x, and where it lies: kFace, kEdge with the
/// edge's two vertex numbers (0, 1, 2 of the triangle) in e0 < e1, or kVertex with its number
/// in e0 (Ericson, Real-Time Collision Detection, 5.1.5).
inline MeshFeature closest_on_triangle(const Vec3& x, const Vec3& a, const Vec3& b, const Vec3& c,
                                       Vec3& p, int& e0, int& e1) {
  const Vec3 ab = b - a, ac = c - a, ax = x - a;
  const Real d1 = ab.dot(ax), d2 = ac.dot(ax);
  e1 = -1;
  if (d1 <= 0 && d2 <= 0) { p = a; e0 = 0; return kVertex; }
  const Vec3 bx = x - b;
  const Real d3 = ab.dot(bx), d4 = ac.dot(bx);
  if (d3 >= 0 && d4 <= d3) { p = b; e0 = 1; return kVertex; }
  const Real vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    p = a + (d1 / (d1 - d3)) * ab; e0 = 0; e1 = 1; return kEdge;
  }
  const Vec3 cx = x - c;
  const Real d5 = ab.dot(cx), d6 = ac.dot(cx);
  if (d6 >= 0 && d5 <= d6) { p = c; e0 = 2; return kVertex; }
  const Real vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    p = a + (d2 / (d2 - d6)) * ac; e0 = 0; e1 = 2; return kEdge;
  }
  const Real va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    p = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b); e0 = 1; e1 = 2; return kEdge;
  }
  const Real den = 1 / (va + vb + vc);
  p = a + ab * (vb * den) + ac * (vc * den);
  e0 = -1;
  return kFace;
}

/// One contact of a sphere with a mesh: at a face, an edge or a vertex of the mesh, keyed by
/// `kind` and (a, b): the triangle (kFace), the edge's mesh vertices a < b (kEdge), the
/// vertex a (kVertex), all numbered within the mesh.
struct MeshSub {
  std::int32_t kind = -1;  ///< MeshFeature; -1: unused slot
  std::int32_t a = -1, b = -1;
  std::int32_t pad_ = 0;   ///< zero (explicit padding)
  ContactState state;
  Vec3 force = Vec3::Zero();   ///< force on the sphere, N
  Vec3 torque = Vec3::Zero();  ///< torque on the sphere, N m
  Vec3 point = Vec3::Zero();   ///< the contact point on the mesh, m
};

/// A sphere–mesh pair within reach: up to kMaxSubs contacts (a sphere in a concave corner
/// meets up to three faces; more are said: Scene::mesh_dropped_contacts).
struct MeshContact {
  static constexpr int kMaxSubs = 3;
  int body = 0, wall = 0;
  bool active = false;
  std::uint8_t pad_[3] = {};
  int phys_version = -1;
  ContactPhys phys;
  std::array<MeshSub, kMaxSubs> subs{};
};

}  // namespace cpp_dem
