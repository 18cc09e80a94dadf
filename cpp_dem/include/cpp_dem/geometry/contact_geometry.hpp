// The one record every shape-pair unit of geometry/ fills and every contact law reads.
#pragma once

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// Geometry of one contact, filled by a shape-pair function. Side 1 and side 2; the normal
/// points from side 1 to side 2.
struct ContactGeometry {
  Vec3 normal;      ///< unit normal, from side 1 to side 2
  Real overlap;     ///< penetration depth, m (> 0 in contact)
  Vec3 branch1;     ///< contact point minus centre of side 1, m
  Vec3 branch2;     ///< contact point minus centre of side 2, m
  Vec3 rel_vel;     ///< velocity of side 2 minus side 1 at the contact point, m/s
  Vec3 angvel_sum;  ///< omega1 + omega2, rad/s (for the twist of the shear frame)
  Vec3 rel_angvel;  ///< omega2 - omega1, rad/s (for rolling resistance)
};

}  // namespace cpp_dem
