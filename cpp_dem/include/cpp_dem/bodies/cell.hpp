// The periodic cell: a parallelepiped H [0,1)^3 (H's columns are the cell vectors, m) that
// repeats in space along its periodic axes and deforms under an imposed velocity gradient L
// (1/s): dH/dt = L H. Bodies carry the mean field v = L x (and, with mean_spin, the spin
// w = axial(skew L)); the body store holds the fluctuations about it. See docs/periodic.md.
#pragma once

#include <array>
#include <cstdint>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// Image code of a pair contact: which periodic image of body j the contact sees,
/// code = 9 (s_x + 1) + 3 (s_y + 1) + (s_z + 1) for the integer shift s in {-1, 0, 1}^3;
/// the image is x_j + H s. kNoShift (13) is the body itself (every contact without a cell).
inline constexpr std::uint8_t kNoShift = 13;
inline int image_shift(std::uint8_t code, int axis) {
  return axis == 0 ? code / 9 - 1 : axis == 1 ? (code / 3) % 3 - 1 : code % 3 - 1;
}

/// The cell's state (saved in checkpoints byte for byte).
struct PeriodicCell {
  bool on = false;                 ///< the scene is periodic along `periodic` axes
  bool mean_spin = true;           ///< bodies carry the mean spin axial(skew L)
  std::array<bool, 3> periodic{};  ///< which axes repeat
  std::uint8_t pad_[3] = {};       ///< zero (explicit padding: checkpoints are byte-identical)
  Mat3 h = Mat3::Identity();       ///< cell vectors as columns, m
  Mat3 h_ref = Mat3::Identity();   ///< h when the cell was set (reference of the strain)
  Mat3 h_at_build = Mat3::Identity();  ///< h at the last broad-phase build
  Mat3 vel_grad = Mat3::Zero();    ///< imposed velocity gradient L, 1/s
  Real work = 0;                   ///< work done on the contacts by the mean field, J

  /// Axial vector of the skew part of L (rad/s): the mean spin (zero without mean_spin).
  Vec3 spin() const {
    if (!mean_spin) return Vec3::Zero();
    const Mat3 w = 0.5 * (vel_grad - vel_grad.transpose());
    return Vec3(w(2, 1), w(0, 2), w(1, 0));
  }
  Real volume() const { return h.determinant(); }
  /// Thickness of the cell across the planes of the two other vectors of axis a, m.
  Real thickness(int a) const {
    const Vec3 c = h.col((a + 1) % 3).cross(h.col((a + 2) % 3));
    return std::abs(volume()) / c.norm();
  }
  /// The map of one step of the mean field, x -> A x with A = (I - L dt/2)^-1 (I + L dt/2)
  /// (Cayley's form: exactly orthogonal for a spin, so a rigid rotation keeps every distance).
  Mat3 step_map(Real dt) const {
    const Mat3 half = 0.5 * dt * vel_grad;
    return (Mat3::Identity() - half).inverse() * (Mat3::Identity() + half);
  }
};

/// One step of the mean field as the integration pass applies it to a body: x -> A x and the
/// orientation turned by the mean spin; fb is the cell's deformation since the last build
/// after this step (the broad phase's measure, Scene::displacement_since_build).
struct MeanFieldStep {
  Mat3 a = Mat3::Identity();
  Mat3 fb = Mat3::Identity();
  Quat spin = Quat::Identity();
  bool rotate = false;
  void apply(Vec3& x, Quat& q) const {
    x = a * x;
    if (rotate) q = spin * q;
  }
};

}  // namespace cpp_dem
