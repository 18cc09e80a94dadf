#include "cpp_dem/broadphase/collider.hpp"

#include <algorithm>
#include <cmath>

namespace cpp_dem {

long CellGrid::cell_of(const Vec3& x, int a) const {
  const long c = static_cast<long>(std::floor((x[a] - lo_[a]) / h_));
  return std::min(std::max(c, 0L), ncell_[a] - 1);
}

void CellGrid::build(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                     const std::vector<std::uint8_t>& skip, Real margin) {
  const int n = static_cast<int>(pos.size());
  body_cell_.assign(n, -1);
  nspheres_ = 0;
  Vec3 lo = Vec3::Constant(0), hi = Vec3::Constant(0);
  Real rmax = 0;
  for (int i = 0; i < n; ++i) {
    if (skip[i]) continue;
    if (nspheres_ == 0) lo = hi = pos[i];
    lo = lo.cwiseMin(pos[i]);
    hi = hi.cwiseMax(pos[i]);
    rmax = std::max(rmax, radius[i]);
    ++nspheres_;
  }
  // Cell edge: the largest interaction range, grown if the grid would have too many cells.
  Real h = std::max(2 * rmax + margin, 1e-300);
  const Vec3 ext = (hi - lo).cwiseMax(Vec3::Constant(1e-300));
  for (;;) {
    long total = 1;
    for (int a = 0; a < 3; ++a) {
      ncell_[a] = std::max(1L, static_cast<long>(std::floor(ext[a] / h)) + 1);
      total *= ncell_[a];
    }
    if (total <= 4L * nspheres_ + 64) break;
    h *= 1.25;
  }
  lo_ = lo;
  h_ = h;
  const long ncells = ncell_[0] * ncell_[1] * ncell_[2];
  for (int i = 0; i < n; ++i) {
    if (skip[i]) continue;
    body_cell_[i] = static_cast<int>((cell_of(pos[i], 0) * ncell_[1] + cell_of(pos[i], 1)) *
                                         ncell_[2] + cell_of(pos[i], 2));
  }
  // Counting sort of spheres into cells (spheres in each cell stay in id order).
  cell_start_.assign(ncells + 1, 0);
  for (int i = 0; i < n; ++i)
    if (body_cell_[i] >= 0) cell_start_[body_cell_[i] + 1]++;
  for (long c = 0; c < ncells; ++c) cell_start_[c + 1] += cell_start_[c];
  cell_bodies_.resize(nspheres_);
  std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (int i = 0; i < n; ++i)
    if (body_cell_[i] >= 0) cell_bodies_[fill[body_cell_[i]]++] = i;
}

void CellGrid::find_pairs(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                          Real margin, std::vector<std::pair<int, int>>& out) {
  out.clear();
  const int n = static_cast<int>(pos.size());
  if (nspheres_ < 2) return;
  if (static_cast<int>(per_body_.size()) < n) per_body_.resize(n);
#pragma omp parallel for schedule(dynamic, 256) if (n > 2000)
  for (int i = 0; i < n; ++i) {
    std::vector<int>& mine = per_body_[i];
    mine.clear();
    if (body_cell_[i] < 0) continue;
    const long cz = body_cell_[i] % ncell_[2];
    const long cy = (body_cell_[i] / ncell_[2]) % ncell_[1];
    const long cx = body_cell_[i] / (ncell_[2] * ncell_[1]);
    for (long x = std::max(0L, cx - 1); x <= std::min(ncell_[0] - 1, cx + 1); ++x)
      for (long y = std::max(0L, cy - 1); y <= std::min(ncell_[1] - 1, cy + 1); ++y)
        for (long z = std::max(0L, cz - 1); z <= std::min(ncell_[2] - 1, cz + 1); ++z) {
          const long c = (x * ncell_[1] + y) * ncell_[2] + z;
          for (int k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
            const int j = cell_bodies_[k];
            if (j <= i) continue;
            const Real reach = radius[i] + radius[j] + margin;
            if ((pos[j] - pos[i]).squaredNorm() < reach * reach) mine.push_back(j);
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

void CellGrid::query_box(const Vec3& lo, const Vec3& hi, const std::vector<Vec3>& pos,
                         const std::vector<Real>& radius, Real margin,
                         std::vector<int>& out) const {
  const size_t first = out.size();
  if (nspheres_ == 0) return;
  // Spheres are binned by centre; a sphere of any radius r <= r_max reaches at most one cell
  // beyond the box's cells.
  long c0[3], c1[3];
  for (int a = 0; a < 3; ++a) {
    c0[a] = std::max(0L, cell_of(lo, a) - 1);
    c1[a] = std::min(ncell_[a] - 1, cell_of(hi, a) + 1);
  }
  for (long x = c0[0]; x <= c1[0]; ++x)
    for (long y = c0[1]; y <= c1[1]; ++y)
      for (long z = c0[2]; z <= c1[2]; ++z) {
        const long c = (x * ncell_[1] + y) * ncell_[2] + z;
        for (int k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
          const int j = cell_bodies_[k];
          const Real r = radius[j] + margin;
          bool hit = true;
          for (int a = 0; a < 3 && hit; ++a)
            hit = pos[j][a] + r > lo[a] && pos[j][a] - r < hi[a];
          if (hit) out.push_back(j);
        }
      }
  std::sort(out.begin() + first, out.end());
}

void CellGrid::add_memory(std::vector<std::pair<std::string, std::size_t>>& out) const {
  const auto bytes = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
  out.emplace_back("broadphase.cell_start", bytes(cell_start_));
  out.emplace_back("broadphase.cell_bodies", bytes(cell_bodies_));
  out.emplace_back("broadphase.body_cell", bytes(body_cell_));
  std::size_t per = per_body_.capacity() * sizeof(std::vector<int>);
  for (const auto& v : per_body_) per += v.capacity() * sizeof(int);
  out.emplace_back("broadphase.per_body_buffers", per);
}

}  // namespace cpp_dem
