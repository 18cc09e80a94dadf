// Grain–geogrid contacts and link break events.
#pragma once

#include "cpp_dem/laws/contact_law.hpp"

namespace cpp_dem {

/// Kinds of grid primitive a grain can touch.
enum class GridPrimitive : std::uint8_t { Node = 0, Connection = 1, Facet = 2 };

/// A grain–geogrid contact: one sphere and one primitive, through a virtual sphere of radius
/// R_c centred at the closest skeleton point q (000 eqs 13–19). Only the primitive that owns
/// the closest point (a local minimum of the distance to the skeleton) is active, so a grain
/// crossing a node or an edge keeps exactly one contact; its history is handed over.
struct GridContact {
  int sphere = 0;
  GridPrimitive kind = GridPrimitive::Node;
  std::uint8_t pad_kind_[3] = {};  ///< zero (explicit padding: checkpoints are byte-identical)
  int prim = 0;                ///< node body id, link index or facet index
  bool active = false;
  bool owner = false;          ///< owns the contact this step
  std::uint8_t pad_owner_[2] = {};  ///< zero (explicit padding)
  int phys_version = -1;
  int pad_version_ = 0;        ///< zero (explicit padding)
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

}  // namespace cpp_dem
