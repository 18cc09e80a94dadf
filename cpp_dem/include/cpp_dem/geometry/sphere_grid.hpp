// Shape pair sphere–geogrid primitive (grid node, connection cylinder, PFacet), through the
// virtual sphere of 000 eqs 13–19: closest skeleton points and the nodes' weights.
#pragma once

#include <algorithm>

#include "cpp_dem/geometry/contact_geometry.hpp"

namespace cpp_dem {

/// Closest point of segment [a, b] to c: returns the parameter t (unclamped).
inline Real segment_parameter(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a;
  const Real l2 = ab.squaredNorm();
  return l2 > 0 ? (c - a).dot(ab) / l2 : 0.0;
}

/// Barycentric coordinates (p1, p2, p3) of the projection of c on the plane of triangle
/// (x1, x2, x3) (000 eqs 13–16, computed with dot products instead of areas).
inline Eigen::Vector3d barycentric(const Vec3& x1, const Vec3& x2, const Vec3& x3,
                                   const Vec3& c) {
  const Vec3 e0 = x2 - x1, e1 = x3 - x1, d = c - x1;
  const Real d00 = e0.dot(e0), d01 = e0.dot(e1), d11 = e1.dot(e1);
  const Real d20 = d.dot(e0), d21 = d.dot(e1);
  const Real den = d00 * d11 - d01 * d01;
  if (!(den > 0)) return Eigen::Vector3d(-1, -1, -1);
  const Real v = (d11 * d20 - d01 * d21) / den;
  const Real w = (d00 * d21 - d01 * d20) / den;
  return Eigen::Vector3d(1.0 - v - w, v, w);
}

/// Distance from x to the segment [a, b], m.
inline Real segment_distance(const Vec3& a, const Vec3& b, const Vec3& x) {
  const Real t = std::min(std::max(segment_parameter(a, b, x), 0.0), 1.0);
  return (x - ((1 - t) * a + t * b)).norm();
}

/// The contact of a grain (centre x, radius r, m; velocity v, m/s; spin w, rad/s) with the
/// virtual sphere of radius rc (m) centred at the closest skeleton point q, which moves with
/// the weighted velocity vq and spin wq of the primitive's nodes (000 eqs 17, 18). Side 1 is
/// the virtual sphere, side 2 the grain.
inline ContactGeometry virtual_sphere_geometry(const Vec3& x, Real r, const Vec3& v,
                                               const Vec3& w, const Vec3& q, Real rc,
                                               const Vec3& vq, const Vec3& wq) {
  ContactGeometry g;
  const Real dist = (x - q).norm();
  g.normal = dist > 0 ? Vec3((x - q) / dist) : Vec3(Vec3::UnitZ());
  g.overlap = (r + rc) - dist;
  g.branch1 = (rc - 0.5 * g.overlap) * g.normal;
  g.branch2 = -(r - 0.5 * g.overlap) * g.normal;
  g.rel_vel = (v + w.cross(g.branch2)) - (vq + wq.cross(g.branch1));
  g.angvel_sum = wq + w;
  g.rel_angvel = w - wq;
  return g;
}

}  // namespace cpp_dem
