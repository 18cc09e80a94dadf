#include "cpp_dem/collider.hpp"

#include <algorithm>
#include <cmath>

namespace cpp_dem {

void CellGrid::find_pairs(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                          Real margin, std::vector<std::pair<int, int>>& out) {
  out.clear();
  const int n = static_cast<int>(pos.size());
  if (n < 2) return;
  Vec3 lo = pos[0], hi = pos[0];
  Real rmax = 0;
  for (int i = 0; i < n; ++i) {
    lo = lo.cwiseMin(pos[i]);
    hi = hi.cwiseMax(pos[i]);
    rmax = std::max(rmax, radius[i]);
  }
  // Cell edge: the largest interaction range, grown if the grid would have too many cells.
  Real h = 2 * rmax + margin;
  const Vec3 ext = (hi - lo).cwiseMax(Vec3::Constant(1e-300));
  long ncell[3];
  for (;;) {
    long total = 1;
    for (int a = 0; a < 3; ++a) {
      ncell[a] = std::max(1L, static_cast<long>(std::floor(ext[a] / h)) + 1);
      total *= ncell[a];
    }
    if (total <= 4L * n + 64) break;
    h *= 1.25;
  }
  const long ncells = ncell[0] * ncell[1] * ncell[2];
  body_cell_.resize(n);
  auto cell_coord = [&](const Vec3& x, int a) {
    long c = static_cast<long>(std::floor((x[a] - lo[a]) / h));
    return std::min(std::max(c, 0L), ncell[a] - 1);
  };
  for (int i = 0; i < n; ++i) {
    body_cell_[i] = static_cast<int>((cell_coord(pos[i], 0) * ncell[1] + cell_coord(pos[i], 1)) *
                                         ncell[2] +
                                     cell_coord(pos[i], 2));
  }
  // Counting sort of bodies into cells (bodies in each cell stay in id order).
  cell_start_.assign(ncells + 1, 0);
  for (int i = 0; i < n; ++i) cell_start_[body_cell_[i] + 1]++;
  for (long c = 0; c < ncells; ++c) cell_start_[c + 1] += cell_start_[c];
  cell_bodies_.resize(n);
  {
    std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
    for (int i = 0; i < n; ++i) cell_bodies_[fill[body_cell_[i]]++] = i;
  }
  if (static_cast<int>(per_body_.size()) < n) per_body_.resize(n);
#pragma omp parallel for schedule(dynamic, 256) if (n > 2000)
  for (int i = 0; i < n; ++i) {
    std::vector<int>& mine = per_body_[i];
    mine.clear();
    const long cz = body_cell_[i] % ncell[2];
    const long cy = (body_cell_[i] / ncell[2]) % ncell[1];
    const long cx = body_cell_[i] / (ncell[2] * ncell[1]);
    for (long dx = -1; dx <= 1; ++dx) {
      const long x = cx + dx;
      if (x < 0 || x >= ncell[0]) continue;
      for (long dy = -1; dy <= 1; ++dy) {
        const long y = cy + dy;
        if (y < 0 || y >= ncell[1]) continue;
        for (long dz = -1; dz <= 1; ++dz) {
          const long z = cz + dz;
          if (z < 0 || z >= ncell[2]) continue;
          const long c = (x * ncell[1] + y) * ncell[2] + z;
          for (int k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
            const int j = cell_bodies_[k];
            if (j <= i) continue;
            const Real reach = radius[i] + radius[j] + margin;
            if ((pos[j] - pos[i]).squaredNorm() < reach * reach) mine.push_back(j);
          }
        }
      }
    }
    std::sort(mine.begin(), mine.end());
  }
  size_t total = 0;
  for (int i = 0; i < n; ++i) total += per_body_[i].size();
  out.reserve(total);
  for (int i = 0; i < n; ++i)
    for (int j : per_body_[i]) out.emplace_back(i, j);
}

}  // namespace cpp_dem
