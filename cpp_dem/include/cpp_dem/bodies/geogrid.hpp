// Geogrid bodies besides the grid nodes (which are bodies of the body store, kind 1): the
// PFacet triangles. The links between nodes are the beam law's records (laws/beam.hpp).
#pragma once

#include "cpp_dem/laws/beam.hpp"

namespace cpp_dem {

/// A PFacet: a triangle of three nodes with its three connections, dilated by R_c.
struct PFacet {
  int n[3] = {0, 0, 0};     ///< node body ids
  int link[3] = {-1, -1, -1};  ///< connections (n0 n1), (n1 n2), (n2 n0)
  int material = 0;
  int pad_ = 0;             ///< zero (explicit padding: checkpoints are byte-identical)
  Real radius = 0;          ///< R_c, m
};

}  // namespace cpp_dem
