// Cylindrical walls: the lateral surface of a circular cylinder of any axis, with spheres
// inside it (a triaxial cell's rigid side, a container) or outside it (a pile, a rod),
// infinite or cut at two ends (open: the ends are rims, circles a sphere meets as an edge).
#pragma once

#include <cmath>
#include <limits>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// A rigid cylindrical wall (Scene::add_cylinder_wall). Its radius and its axis's position
/// move with imposed velocities; spheres meet its lateral surface from one side only.
struct CylinderWall {
  Vec3 centre = Vec3::Zero();   ///< a point on the axis, m (the axial origin of lo and hi)
  Vec3 axis = Vec3::UnitZ();    ///< unit vector along the axis
  Real radius = 1;              ///< m
  Real lo = -std::numeric_limits<Real>::infinity();  ///< lower end, m along axis from centre
  Real hi = std::numeric_limits<Real>::infinity();   ///< upper end, m along axis from centre
  Vec3 velocity = Vec3::Zero(); ///< imposed velocity of the whole cylinder, m/s
  Real radial_velocity = 0;     ///< imposed rate of the radius, m/s (> 0: it widens)
  int inside = 1;               ///< 1: spheres inside it; 0: spheres outside it
  int material = 0;             ///< material index
  Vec3 force = Vec3::Zero();    ///< force exerted by the spheres on the wall (last step), N
  /// The sum of its contacts' normal forces (last step), N, compressive positive: the
  /// spheres' push on it (its mean pressure is normal_force over lateral_area()).
  Real normal_force = 0;
  Real work = 0;                ///< work done by the wall on the spheres, cumulative, J
  Real moved_since_build = 0;   ///< largest surface displacement since the last build, m

  bool finite() const { return std::isfinite(lo) && std::isfinite(hi); }
  /// The lateral area 2 pi R (hi - lo), m^2 (infinite for an infinite cylinder).
  Real lateral_area() const {
    return 2 * 3.14159265358979323846 * radius * (hi - lo);
  }
};

/// Where a sphere centred at x (m) meets cylinder w: the unit normal n (from the wall to the
/// sphere), the distance `dist` from the centre to the wall's surface along n (m; a sphere of
/// radius r overlaps it by r - dist) and the outward radial unit vector `e` at the contact
/// point. Returns false where the sphere's side of the wall is the other one (its centre is
/// beyond the lateral surface by more than r: it cannot be in contact).
///
/// Within the ends (lo <= t <= hi, t the centre's axial coordinate) the contact is on the
/// lateral surface (n = -e inside, +e outside; dist = R - rho inside, rho - R outside, rho the
/// centre's distance from the axis); beyond an end, it is at the nearest point of that end's
/// rim circle (n from it to the centre). At t = lo or hi both give the same point, so a sphere
/// crossing the end feels a continuous force.
inline bool cylinder_contact(const CylinderWall& w, const Vec3& x, Real r, Vec3& n, Real& dist,
                             Vec3& e) {
  const Vec3 d = x - w.centre;
  const Real t = d.dot(w.axis);
  const Vec3 q = d - t * w.axis;
  const Real rho = q.norm();
  if (rho > 1e-12 * w.radius) {
    e = q / rho;
  } else {  // on the axis: any direction across it
    const Vec3 ref = std::abs(w.axis[0]) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
    e = (ref - ref.dot(w.axis) * w.axis).normalized();
  }
  if (t >= w.lo && t <= w.hi) {
    dist = w.inside ? w.radius - rho : rho - w.radius;
    n = w.inside ? Vec3(-e) : e;
    return dist > -r;
  }
  // Beyond an end: the rim. (The centre must still be on the wall's side radially, within r.)
  const Real side = w.inside ? w.radius - rho : rho - w.radius;
  if (side <= -r) return false;
  const Real tc = t < w.lo ? w.lo : w.hi;
  const Vec3 p = w.centre + tc * w.axis + w.radius * e;
  const Vec3 v = x - p;
  dist = v.norm();
  if (!(dist > 0)) return false;
  n = v / dist;
  return true;
}

}  // namespace cpp_dem
