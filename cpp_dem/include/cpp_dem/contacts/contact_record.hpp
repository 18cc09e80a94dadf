// One contact of any container, as the readers of contacts (measurements, time-step and servo
// stiffness, the Python face) see it: Scene::for_each_contact visits them, so those readers
// do not walk the containers' raw vectors.
#pragma once

#include <cstdint>

#include "cpp_dem/laws/contact_law.hpp"

namespace cpp_dem {

/// The container a contact lives in.
/// Cylinder: a sphere against a cylindrical wall (CylinderWall); Mesh: against a face, edge or
/// vertex of a triangle-mesh wall (MeshSub); sides as a wall contact's.
enum class ContactKind : std::uint8_t { Pair = 0, Wall = 1, Grid = 2, Cylinder = 3, Mesh = 4 };

/// A contact seen through Scene::for_each_contact. Sides: a pair contact is (i, j); a wall
/// contact (the wall, the sphere); a grain–geogrid contact (the virtual sphere of the
/// primitive, the grain).
struct ContactRecord {
  ContactKind kind = ContactKind::Pair;
  long index = 0;        ///< index in its container (a pair: its candidate pair; wall_contacts, grid_contacts)
  bool active = false;   ///< touching in the last step
  int body1 = -1;        ///< storage slot of side 1 (-1: a wall or a geogrid primitive)
  int body2 = -1;        ///< storage slot of side 2
  int other = -1;        ///< the wall's (or cylinder's) index, or the grid contact's primitive (-1 for a pair)
  const ContactPhys* phys = nullptr;  ///< its law's parameters
  /// Its history (springs, normal, overlap, f_n, dissipation): the container's record, or for
  /// a pair contact (stored in a hot and a cold part) a copy valid during the visit.
  const ContactState* state = nullptr;
  Vec3 force2 = Vec3::Zero();  ///< force on side 2 in the last step, N
  /// A pair contact in a periodic cell: side 2 is seen at its image x_2 + shift (m); zero
  /// otherwise.
  Vec3 shift2 = Vec3::Zero();
  Real arm1 = 0;         ///< branch length of side 1, m (a wall: 0; a virtual sphere: R_c - d/2)
  Real arm2 = 0;         ///< branch length of side 2, R - overlap/2, m

  /// Tangent stiffnesses at the current overlap, N/m.
  void stiffness(Real& kn, Real& ks) const { tangent_stiffness(*phys, state->overlap, kn, ks); }
  /// Energy stored in the contact's springs, J (0 when not active).
  Real elastic_energy() const { return active ? contact_elastic_energy(*phys, *state) : 0.0; }
};

}  // namespace cpp_dem
