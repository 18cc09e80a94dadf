// Broad phase: a uniform cell grid with a Verlet margin.
#pragma once

#include <utility>
#include <vector>

#include "cpp_dem/types.hpp"

namespace cpp_dem {

/// Finds all sphere pairs (i < j) with |x_i - x_j| < r_i + r_j + margin.
/// The output is sorted by (i, j) and does not depend on the number of threads.
class CellGrid {
 public:
  /// Candidate pairs, sorted by (i, j).
  void find_pairs(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                  Real margin, std::vector<std::pair<int, int>>& out);

 private:
  std::vector<int> cell_start_, cell_bodies_, body_cell_;
  std::vector<std::vector<int>> per_body_;  // reused buffers, one per body
};

}  // namespace cpp_dem
