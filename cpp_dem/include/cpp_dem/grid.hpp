// Deformable geogrid: grid nodes, connections (Minkowski-sum cylinders), PFacets, and the
// cohesive beam law between nodes (000 §2.2, eqs 7–19).
#pragma once

#include <cmath>

#include "cpp_dem/contact.hpp"

namespace cpp_dem {

/// Parameters of the cohesive beam link between two grid nodes (000 eqs 7–12). SI units.
struct BeamParams {
  Real young = 4e9;            ///< E of the geogrid, Pa (000 Table 1: 4e9)
  Real poisson = 0.3;          ///< nu, - (G = E / (2 (1 + nu)))
  Real radius = 1e-3;          ///< R_c, radius of the cylinder cross-section, m
  Real normal_cohesion = 0;    ///< sigma_n^max, tensile strength, Pa (0: unbreakable)
  Real shear_cohesion = 0;     ///< tau^max, shear strength, Pa (0: unbreakable)
  /// Throws ParameterError naming the bad field.
  void validate() const;
};

/// A cohesive link between nodes a and b; also the connection (cylinder) grains touch.
struct GridLink {
  int a = 0, b = 0;           ///< node body ids
  int material = 0;           ///< material for grain contacts
  Real radius = 0;            ///< R_c, m
  Real length0 = 0;           ///< initial length L_c, m
  Real kn = 0, ks = 0;        ///< N/m, 000 eqs (7), (8)
  Real kr = 0, ktw = 0;       ///< N m/rad, 000 eqs (9), (10)
  Real fn_max = 0, fs_max = 0;    ///< breakage forces, N (0: unbreakable)
  Real mr_max = 0, mtw_max = 0;   ///< elastic limits of the moments, N m (0: no limit)
  bool broken = false;
  // History.
  Vec3 normal = Vec3::Zero();  ///< unit a -> b at the last step
  Vec3 fs = Vec3::Zero();      ///< shear force on b, N
  Vec3 mb = Vec3::Zero();      ///< bending moment on b, N m
  Real mt = 0;                 ///< twisting moment on b about the normal, N m
  Real fn = 0;                 ///< axial force, N, tension positive
  Real dissip_plastic = 0;     ///< dissipated by capped moments, J
  int pending_break = -1;      ///< set during a step: 0 tension, 1 shear
  // Output of the last step.
  Vec3 force_b = Vec3::Zero();   ///< total force on b (a gets the opposite), N
  Vec3 torque_a = Vec3::Zero(), torque_b = Vec3::Zero();  ///< N m

  /// Energy stored in the link's four springs (axial, shear, bending, twisting), J.
  Real elastic_energy() const {
    return 0.5 * fn * fn / kn + 0.5 * fs.squaredNorm() / ks + 0.5 * mb.squaredNorm() / kr +
           0.5 * mt * mt / ktw;
  }
};

/// A PFacet: a triangle of three nodes with its three connections, dilated by R_c.
struct PFacet {
  int n[3] = {0, 0, 0};     ///< node body ids
  int link[3] = {-1, -1, -1};  ///< connections (n0 n1), (n1 n2), (n2 n0)
  int material = 0;
  Real radius = 0;          ///< R_c, m
};

/// Kinds of grid primitive a grain can touch.
enum class GridPrimitive : std::uint8_t { Node = 0, Connection = 1, Facet = 2 };

/// A grain–geogrid contact: one sphere and one primitive, through a virtual sphere of radius
/// R_c centred at the closest skeleton point q (000 eqs 13–19). Only the primitive that owns
/// the closest point (a local minimum of the distance to the skeleton) is active, so a grain
/// crossing a node or an edge keeps exactly one contact; its history is handed over.
struct GridContact {
  int sphere = 0;
  GridPrimitive kind = GridPrimitive::Node;
  int prim = 0;                ///< node body id, link index or facet index
  bool active = false;
  bool owner = false;          ///< owns the contact this step
  int phys_version = -1;
  Real rc = 0;                 ///< radius of the virtual sphere R_c, m
  int nnodes = 0;              ///< 1, 2 or 3
  int node[3] = {0, 0, 0};
  Real w[3] = {0, 0, 0};       ///< interpolation weights of the nodes, sum 1
  ContactPhys phys;
  ContactState state;
  ContactGeometry geom{Vec3::Zero(), 0, Vec3::Zero(), Vec3::Zero(),
                       Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};  ///< scratch of this step
  Vec3 force = Vec3::Zero();   ///< force on the sphere, N (the nodes get -w_i force)
  Vec3 torque_sphere = Vec3::Zero();
  Vec3 torque_virtual = Vec3::Zero();  ///< torque on the virtual sphere (split by weights)
};

/// A link that broke: when, which, why.
struct BreakEvent {
  long step = 0;
  Real time = 0;       ///< s
  int link = 0;
  int reason = 0;      ///< 0 tension, 1 shear
  Real force = 0;      ///< the force that exceeded the limit, N
};

/// Beam stiffnesses and limits of a link of length L from its parameters (000 eqs 7–12).
inline void beam_stiffness(const BeamParams& p, Real length, GridLink& l) {
  const Real area = M_PI * p.radius * p.radius;
  const Real i_r = M_PI * std::pow(p.radius, 4) / 4.0;   // bending moment of inertia
  const Real i_tw = M_PI * std::pow(p.radius, 4) / 2.0;  // polar moment of inertia
  const Real g = p.young / (2.0 * (1.0 + p.poisson));
  l.kn = p.young * area / length;                       // eq (7)
  l.ks = 12.0 * p.young * i_r / (length * length * length);  // eq (8)
  l.kr = p.young * i_r / length;                        // eq (9)
  l.ktw = g * i_tw / length;                            // eq (10)
  l.fn_max = p.normal_cohesion * area;
  l.fs_max = p.shear_cohesion * area;
  l.mr_max = 4.0 * p.normal_cohesion * i_r / p.radius;   // eq (11)
  l.mtw_max = 2.0 * p.normal_cohesion * i_tw / p.radius; // eq (12)
  l.radius = p.radius;
  l.length0 = length;
}

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

}  // namespace cpp_dem
