#include "cpp_dem/broadphase/collider.hpp"

#include <algorithm>
#include <cmath>

#include "cpp_dem/core/parallel.hpp"

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
  // (The count in floating point: grains kilometres apart would overflow a 64-bit product.)
  for (;;) {
    double total = 1;
    for (int a = 0; a < 3; ++a) {
      ncell_[a] = std::max(1L, static_cast<long>(std::min(std::floor(ext[a] / h), 1e15)) + 1);
      total *= static_cast<double>(ncell_[a]);
    }
    if (total <= 4.0 * nspheres_ + 64) break;
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
                          Real margin, std::vector<int>& off, std::vector<int>& js) {
  const int n = static_cast<int>(pos.size());
  off.assign(n + 1, 0);
  js.clear();
  if (nspheres_ < 2) return;
  // The partners of body i (j > i, sorted) are appended to `to`; returns how many.
  const auto pairs_of = [&](int i, std::vector<int>& to) {
    if (body_cell_[i] < 0) return 0;
    const size_t first = to.size();
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
            if ((pos[j] - pos[i]).squaredNorm() < reach * reach) to.push_back(j);
          }
        }
    std::sort(to.begin() + first, to.end());
    return static_cast<int>(to.size() - first);
  };
  if (n <= 2000 || omp_get_max_threads() == 1) {  // (one thread: straight into js)
    for (int i = 0; i < n; ++i) off[i + 1] = off[i] + pairs_of(i, js);
    if (js.capacity() > js.size() + js.size() / 2) {
      // (grown by doubling: kept with an eighth to spare, so the next builds reuse it)
      std::vector<int> tight;
      tight.reserve(js.size() + js.size() / 8);
      tight.assign(js.begin(), js.end());
      js.swap(tight);
    }
    return;
  }
  // On threads: the bodies in blocks of kBlock, each block's partners in a buffer of its own
  // (kept: their capacity serves the next build) and each body's count in off[i + 1], joined
  // in block order: the same rows as on one thread.
  constexpr int kBlock = 256;
  const int nblocks = (n + kBlock - 1) / kBlock;
  if (static_cast<int>(blocks_.size()) < nblocks) blocks_.resize(nblocks);
#pragma omp parallel for schedule(dynamic, 1)
  for (int blk = 0; blk < nblocks; ++blk) {
    blocks_[blk].clear();
    const int end = std::min(n, (blk + 1) * kBlock);
    for (int i = blk * kBlock; i < end; ++i) off[i + 1] = pairs_of(i, blocks_[blk]);
  }
  for (int i = 0; i < n; ++i) off[i + 1] += off[i];
  js.reserve(off[n]);
  for (int blk = 0; blk < nblocks; ++blk)
    js.insert(js.end(), blocks_[blk].begin(), blocks_[blk].end());
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

void CellGrid::release() {
  for (auto* v : {&cell_start_, &cell_bodies_, &body_cell_}) std::vector<int>().swap(*v);
}

void CellGrid::add_memory(std::vector<std::pair<std::string, std::size_t>>& out) const {
  const auto bytes = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
  out.emplace_back("broadphase.cell_start", bytes(cell_start_));
  out.emplace_back("broadphase.cell_bodies", bytes(cell_bodies_));
  out.emplace_back("broadphase.body_cell", bytes(body_cell_));
  std::size_t blocks = blocks_.capacity() * sizeof(blocks_[0]);
  for (const auto& b : blocks_) blocks += b.capacity() * sizeof(b[0]);
  out.emplace_back("broadphase.thread_blocks", blocks);
}

}  // namespace cpp_dem
