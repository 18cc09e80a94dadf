// Walls: infinite planes normal to a coordinate axis, with imposed velocities.
#pragma once

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// An infinite plane normal to a coordinate axis. One-sided: spheres interact with it from
/// the side its normal points to (sense = +1: the +axis side; -1: the -axis side).
struct Wall {
  int axis = 2;                 ///< 0 = x, 1 = y, 2 = z
  int sense = 1;                ///< +1 or -1: side of the plane where spheres are
  Real position = 0;            ///< plane coordinate along axis, m
  Vec3 velocity = Vec3::Zero(); ///< imposed velocity, m/s (the axis component moves it)
  int material = 0;             ///< material index
  int pad_ = 0;                 ///< zero (explicit padding: checkpoints are byte-identical)
  Vec3 force = Vec3::Zero();    ///< force exerted by the spheres on the wall (last step), N
  Real work = 0;                ///< work done by the wall on the spheres, cumulative, J
  Real moved_since_build = 0;   ///< |displacement| since the last broad-phase build, m
  Vec3 normal() const {
    Vec3 n = Vec3::Zero();
    n[axis] = sense;
    return n;
  }
};

/// An opening in a wall: the wall is open (no contact) for a body whose centre's coordinate
/// along `axis` lies strictly between `lo` and `hi` (m), as a pull-out box's slot lets the
/// geogrid and the grains next to it leave through the front wall; and for a body whose
/// centre is beyond the plane (it left through the opening: it is outside the box, which
/// the wall no longer bounds). A body reaches the plane elsewhere only with an overlap of
/// its radius, which the overlap check stops. axis = -1: closed (the plain one-sided wall).
struct WallOpening {
  int axis = -1;  ///< 0, 1 or 2 (not the wall's own axis); -1: the wall has no opening
  int pad_ = 0;   ///< zero (explicit padding: checkpoints are byte-identical)
  Real lo = 0;    ///< lower bound of the opening along axis, m
  Real hi = 0;    ///< upper bound of the opening along axis, m
};

/// Whether a body centred at x (m) meets wall w, whose opening is o, at an edge of the
/// opening rather than on its plane: so when o is open and the centre lies in the opening
/// or beyond the plane. Then d is the vector from the nearer edge (a line across the wall,
/// at w.position along w.axis and lo or hi along o.axis) to x, m.
inline bool opening_edge(const Wall& w, const WallOpening& o, const Vec3& x, Vec3& d) {
  if (o.axis < 0) return false;
  const Real z = x[o.axis];
  const bool in_band = z > o.lo && z < o.hi;
  if (!in_band && w.sense * (x[w.axis] - w.position) > 0) return false;
  const Real edge = in_band ? (z - o.lo < o.hi - z ? o.lo : o.hi) : (z <= o.lo ? o.lo : o.hi);
  d = Vec3::Zero();
  d[w.axis] = x[w.axis] - w.position;
  d[o.axis] = z - edge;
  return true;
}

}  // namespace cpp_dem
