// Sphere–wall contacts.
#pragma once

#include "cpp_dem/laws/contact_law.hpp"

namespace cpp_dem {

/// A sphere–wall contact. Side 1 = the wall, side 2 = the sphere.
struct WallContact {
  int body = 0, wall = 0;
  bool active = false;
  /// Linear law without viscous damping and rolling resistance: the wall pass runs its
  /// short kernel (the same operations as apply_law).
  bool simple = false;
  std::uint8_t pad_[2] = {};    ///< zero (explicit padding: checkpoints are byte-identical)
  int phys_version = -1;
  ContactPhys phys;
  ContactState state;
  Vec3 force = Vec3::Zero();    ///< force on the sphere, N
  Vec3 torque = Vec3::Zero();   ///< torque on the sphere, N m
};

}  // namespace cpp_dem
