// Contact-law part: rolling resistance, an elastic-plastic rolling spring (Iwashita–Oda type):
// M_r -= k_r dt w_roll, |M_r| <= eta_r R* |F_n|.
#pragma once

#include "cpp_dem/laws/tangential.hpp"

namespace cpp_dem {

/// Rolling part for one step of dt (s): increments the stored rolling moment mr (N m, on side
/// 2) by the rolling part of the relative spin rel_angvel (rad/s; its component about the
/// normal n is twist, not rolling), with stiffness kr (N m/rad), and caps it at
/// rolling_cap |fn| (rolling_cap = eta_r R*, m; fn N); the slip's energy (J) is added to
/// `dissipated`.
inline void rolling_resistance(Vec3& mr, const Vec3& rel_angvel, const Vec3& n, Real kr,
                               Real rolling_cap, Real fn, Real dt, Real& dissipated) {
  const Vec3 w = rel_angvel - rel_angvel.dot(n) * n;
  mr -= kr * dt * w;
  cap_magnitude<NarrowOps>(mr, rolling_cap * (fn > 0 ? fn : 0.0), kr, dissipated);
}

}  // namespace cpp_dem
