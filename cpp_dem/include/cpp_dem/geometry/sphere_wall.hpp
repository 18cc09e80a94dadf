// Shape pair sphere–wall: a sphere against an axis-aligned, one-sided plane (bodies/wall.hpp).
#pragma once

#include "cpp_dem/bodies/wall.hpp"
#include "cpp_dem/geometry/contact_geometry.hpp"

namespace cpp_dem {

/// Signed distance of the centre x (m) from wall w, positive on the wall's side.
inline Real wall_distance(const Wall& w, const Vec3& x) {
  return w.sense * (x[w.axis] - w.position);
}

/// Whether a body centred at x (m) meets wall w, whose opening is o, at an edge of the
/// opening rather than on its plane: so when o is open and the centre lies in the opening
/// or beyond the plane. Then d is the vector from the nearer edge (a line across the wall,
/// at w.position along w.axis and lo or hi along o.axis) to x, m.
inline bool opening_edge(const Wall& w, const WallOpening& o, const Vec3& x, Vec3& d) {
  if (o.axis < 0) return false;
  const Real z = x[o.axis];
  const bool in_band = z > o.lo && z < o.hi;
  if (!in_band && wall_distance(w, x) > 0) return false;
  const Real edge = in_band ? (z - o.lo < o.hi - z ? o.lo : o.hi) : (z <= o.lo ? o.lo : o.hi);
  d = Vec3::Zero();
  d[w.axis] = x[w.axis] - w.position;
  d[o.axis] = z - edge;
  return true;
}

/// The ContactGeometry record of a sphere (centre x, radius r, m; velocity v, m/s; spin om,
/// rad/s) overlapping wall w by `overlap` (m), along the unit normal n (from the wall to the
/// sphere: the wall's own, or an edge's of its opening, WallOpening). Side 1 is the wall (it
/// does not rotate), side 2 the sphere; the contact point sits in the middle of the overlap.
inline ContactGeometry sphere_wall_geometry(const Wall& w, const Vec3& n, const Vec3& x, Real r,
                                            const Vec3& v, const Vec3& om, Real overlap) {
  ContactGeometry g;
  g.overlap = overlap;
  g.normal = n;
  g.branch2 = -(r - 0.5 * g.overlap) * g.normal;
  g.branch1 = x + g.branch2;  // unused by the law (the wall does not rotate)
  g.rel_vel = (v + om.cross(g.branch2)) - w.velocity;
  g.angvel_sum = om;
  g.rel_angvel = om;
  return g;
}

/// The same against the wall's plane (its normal).
inline ContactGeometry sphere_wall_geometry(const Wall& w, const Vec3& x, Real r, const Vec3& v,
                                            const Vec3& om, Real overlap) {
  return sphere_wall_geometry(w, w.normal(), x, r, v, om, overlap);
}

}  // namespace cpp_dem
