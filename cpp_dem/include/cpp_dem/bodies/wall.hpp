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

/// An opening in a wall (Scene::set_wall_opening): a body whose centre's coordinate along
/// `axis` lies strictly between `lo` and `hi` (m), or whose centre is beyond the plane (it
/// left through the opening), meets the wall only at the opening's nearer edge, a line across
/// the wall (opening_edge, geometry/sphere_wall.hpp), as a pull-out box's slot lets the
/// geogrid and the grains next to it leave through the front wall. axis = -1: closed (the
/// plain one-sided wall).
struct WallOpening {
  int axis = -1;  ///< 0, 1 or 2 (not the wall's own axis); -1: the wall has no opening
  int pad_ = 0;   ///< zero (explicit padding: checkpoints are byte-identical)
  Real lo = 0;    ///< lower bound of the opening along axis, m
  Real hi = 0;    ///< upper bound of the opening along axis, m
};

}  // namespace cpp_dem
