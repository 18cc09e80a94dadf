// Broad phase: a uniform cell grid with a Verlet margin.
#pragma once

#include <string>

#include <cstdint>
#include <utility>
#include <vector>

#include "cpp_dem/bodies/cell.hpp"
#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

/// A cell grid over the spheres of a scene (bodies whose `skip` flag is 0).
class CellGrid {
 public:
  /// Bins the spheres; cells are at least 2 r_max + margin wide.
  void build(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
             const std::vector<std::uint8_t>& skip, Real margin);
  /// All sphere pairs (i < j) with |x_i - x_j| < r_i + r_j + margin, sorted by (i, j), as
  /// rows by i: i's partners j are js[off[i]] .. js[off[i + 1]) (off: one entry per body
  /// and one more). The result does not depend on the number of threads.
  void find_pairs(const std::vector<Vec3>& pos, const std::vector<Real>& radius, Real margin,
                  std::vector<int>& off, std::vector<int>& js);
  /// Appends to `out` the spheres whose box (centre +- r + margin) overlaps [lo, hi],
  /// in increasing id order.
  void query_box(const Vec3& lo, const Vec3& hi, const std::vector<Vec3>& pos,
                 const std::vector<Real>& radius, Real margin, std::vector<int>& out) const;
  /// Appends (field, bytes allocated) of the grid's arrays to `out` (Scene::memory_by_field).
  /// Frees the grid's cells (made again by the next build; the threads' blocks are kept).
  void release();
  void add_memory(std::vector<std::pair<std::string, std::size_t>>& out) const;

 private:
  long cell_of(const Vec3& x, int axis) const;
  Vec3 lo_ = Vec3::Zero();
  Real h_ = 1;
  long ncell_[3] = {1, 1, 1};
  int nspheres_ = 0;
  std::vector<int> cell_start_, cell_bodies_, body_cell_;
  /// find_pairs on threads: each block of bodies' partners j (kept for their capacity)
  std::vector<std::vector<int>> blocks_;
};

/// The broad phase of a periodic cell (broadphase/periodic.cpp): every pair (i < j) of spheres
/// (skip 0) with |x_j + H s - x_i| < r_i + r_j + margin for an image shift s, sorted by
/// (i, j), with the image code of s in `image` (one per pair). Bodies are binned by their
/// reduced coordinates H^-1 x; along a periodic axis the cell must be at least 2 (2 r_max +
/// margin) thick, so each pair has at most one image in reach (ParameterError otherwise). The result does not depend on the number of threads.
void find_periodic_pairs(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                         const std::vector<std::uint8_t>& skip, Real margin,
                         const PeriodicCell& cell, std::vector<std::pair<int, int>>& out,
                         std::vector<std::uint8_t>& image);

}  // namespace cpp_dem
