// The geogrid's cohesive beam law between two grid nodes (000 §2.2, eqs 7–12): its parameters,
// the link record (parameters and history), the stiffnesses, and the link kernel.
#pragma once

#include <cmath>

#include "cpp_dem/laws/tangential.hpp"

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
  int pad_material_ = 0;      ///< zero (explicit padding: checkpoints are byte-identical)
  Real radius = 0;            ///< R_c, m
  Real length0 = 0;           ///< initial length L_c, m
  Real kn = 0, ks = 0;        ///< N/m, 000 eqs (7), (8)
  Real kr = 0, ktw = 0;       ///< N m/rad, 000 eqs (9), (10)
  Real fn_max = 0, fs_max = 0;    ///< breakage forces, N (0: unbreakable)
  Real mr_max = 0, mtw_max = 0;   ///< elastic limits of the moments, N m (0: no limit)
  bool broken = false;
  std::uint8_t pad_broken_[7] = {};  ///< zero (explicit padding)
  // History.
  Vec3 normal = Vec3::Zero();  ///< unit a -> b at the last step
  Vec3 fs = Vec3::Zero();      ///< shear force on b, N
  Vec3 mb = Vec3::Zero();      ///< bending moment on b, N m
  Real mt = 0;                 ///< twisting moment on b about the normal, N m
  Real fn = 0;                 ///< axial force, N, tension positive
  Real dissip_plastic = 0;     ///< dissipated by capped moments, J
  int pending_break = -1;      ///< set during a step: 0 tension, 1 shear
  int pad_pending_ = 0;        ///< zero (explicit padding)
  // Output of the last step.
  Vec3 force_b = Vec3::Zero();   ///< total force on b (a gets the opposite), N
  Vec3 torque_a = Vec3::Zero(), torque_b = Vec3::Zero();  ///< N m

  /// Energy stored in the link's four springs (axial, shear, bending, twisting), J.
  Real elastic_energy() const {
    return 0.5 * fn * fn / kn + 0.5 * fs.squaredNorm() / ks + 0.5 * mb.squaredNorm() / kr +
           0.5 * mt * mt / ktw;
  }
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

/// One step of the beam law for link l (000 eqs 7–12), from its nodes' positions xa, xb (m),
/// velocities va, vb (m/s) and spins wa, wb (rad/s), over dt (s): the shear force and the
/// bending moment are carried into the turned frame of the link, the four springs are
/// incremented, the moments capped at their elastic limits (perfectly plastic beyond, eqs 11,
/// 12), a break at the tensile or shear strength is flagged (pending_break), and the forces
/// and torques on the nodes are set.
ALWAYS_INLINE void beam_link_step(GridLink& l, const Vec3& xa, const Vec3& xb, const Vec3& va,
                                  const Vec3& vb, const Vec3& wa, const Vec3& wb, Real dt) {
  const Vec3 d = xb - xa;
  const Real len = d.norm();
  const Vec3 n = d / len;
  // Keep the shear force and bending moment in the rotated frame of the link.
  Vec3 axis, twist;
  frame_turn<NarrowOps>(l.normal, n, Vec3(wa + wb), dt, axis, twist);
  turn_into_frame<NarrowOps>(l.fs, axis, twist, n);
  turn_into_frame<NarrowOps>(l.mb, axis, twist, n);
  l.normal = n;
  // Axial force, tension positive: k_n (L - L0), eq (7).
  l.fn = l.kn * (len - l.length0);
  // Shear at the middle of the link, eq (8); this with eq (9) gives the Euler–Bernoulli
  // beam element exactly for small rotations.
  const Vec3 ba = 0.5 * len * n, bb = -0.5 * len * n;
  const Vec3 vrel = (vb + wb.cross(bb)) - (va + wa.cross(ba));
  l.fs -= l.ks * dt * (vrel - vrel.dot(n) * n);
  // Bending, eq (9), and twisting, eq (10).
  const Vec3 wrel = wb - wa;
  const Real wtw = wrel.dot(n);
  l.mb -= l.kr * dt * (wrel - wtw * n);
  l.mt -= l.ktw * dt * wtw;
  // Elastic limits of the moments, eqs (11), (12): perfectly plastic beyond.
  if (l.mr_max > 0) cap_magnitude<NarrowOps>(l.mb, l.mr_max, l.kr, l.dissip_plastic);
  if (l.mtw_max > 0 && std::abs(l.mt) > l.mtw_max) {
    const Real trial = l.mt;
    l.mt = std::copysign(l.mtw_max, l.mt);
    l.dissip_plastic += (trial - l.mt) * l.mt / l.ktw;
  }
  // Breakage at the tensile or shear strength (the normal and shear cohesion).
  l.pending_break = -1;
  if (l.fn_max > 0 && l.fn >= l.fn_max) l.pending_break = 0;
  else if (l.fs_max > 0 && l.fs.norm() >= l.fs_max) l.pending_break = 1;
  l.force_b = -l.fn * n + l.fs;
  const Vec3 m = l.mb + l.mt * n;
  l.torque_b = bb.cross(l.force_b) + m;
  l.torque_a = ba.cross(-l.force_b) - m;
}

}  // namespace cpp_dem
