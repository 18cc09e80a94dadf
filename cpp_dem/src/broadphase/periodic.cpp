// The broad phase of a periodic cell: bins in reduced coordinates s = H^-1 x (parallelepipeds
// at least one interaction range thick across each pair of faces), neighbour bins across the
// cell's faces with the image shift they imply.
#include <algorithm>
#include <cmath>
#include <string>

#include "cpp_dem/broadphase/collider.hpp"

namespace cpp_dem {

void find_periodic_pairs(const std::vector<Vec3>& pos, const std::vector<Real>& radius,
                         const std::vector<std::uint8_t>& skip, Real margin,
                         const PeriodicCell& cell, std::vector<std::pair<int, int>>& out,
                         std::vector<std::uint8_t>& image) {
  out.clear();
  image.clear();
  const int n = static_cast<int>(pos.size());
  Real rmax = 0;
  int count = 0;
  for (int i = 0; i < n; ++i) {
    if (skip[i]) continue;
    rmax = std::max(rmax, radius[i]);
    ++count;
  }
  if (count < 1) return;
  const Real reach = 2 * rmax + margin;
  const Mat3 inv = cell.h.inverse();
  std::vector<Vec3> s(n);
  Vec3 lo = Vec3::Zero(), hi = Vec3::Ones();
  bool first = true;
  for (int i = 0; i < n; ++i) {
    if (skip[i]) continue;
    s[i] = inv * pos[i];
    for (int a = 0; a < 3; ++a) {
      if (cell.periodic[a]) continue;
      lo[a] = first ? s[i][a] : std::min(lo[a], s[i][a]);
      hi[a] = first ? s[i][a] : std::max(hi[a], s[i][a]);
    }
    first = false;
  }
  // Bins per axis: floor(thickness / range) across the cell (periodic, >= 2), or over the
  // bodies' extent (not periodic, >= 1); the range grows if there would be too many bins.
  long nb[3];
  Real width[3];  // bin width in reduced coordinates
  for (int a = 0; a < 3; ++a) {
    const Real t = cell.thickness(a);
    // Two ranges: a sphere then reaches at most one image of another (and none of itself).
    if (cell.periodic[a] && std::floor(t / reach) < 2)
      throw ParameterError(
          std::string("periodic cell: thickness ") + fmt_real(t) + " m across axis " +
          std::to_string(a) + " is less than 2 interaction ranges (2 x (2 r_max + margin) = " +
          fmt_real(2 * reach) + " m): make the cell larger or the grains smaller");
  }
  for (Real range = reach;; range *= 1.25) {
    long total = 1;
    for (int a = 0; a < 3; ++a) {
      const Real t = cell.thickness(a);
      if (cell.periodic[a]) {
        nb[a] = std::max(2L, static_cast<long>(std::floor(t / range)));
        width[a] = 1.0 / nb[a];
      } else {
        width[a] = range / t;  // bins one range thick, covering [lo, hi]
        nb[a] = std::min(1L << 20, static_cast<long>(std::floor((hi[a] - lo[a]) / width[a])) + 1);
      }
      total *= nb[a];
    }
    if (total <= 4L * count + 64) break;
  }
  const auto bin_of = [&](const Vec3& r, int a) {
    const long c = static_cast<long>(std::floor((r[a] - lo[a]) / width[a]));
    return std::clamp(c, 0L, nb[a] - 1);
  };
  const long nbins = nb[0] * nb[1] * nb[2];
  std::vector<long> body_bin(n, -1);
  std::vector<int> start(nbins + 1, 0);
  for (int i = 0; i < n; ++i) {
    if (skip[i]) continue;
    body_bin[i] = (bin_of(s[i], 0) * nb[1] + bin_of(s[i], 1)) * nb[2] + bin_of(s[i], 2);
    start[body_bin[i] + 1]++;
  }
  for (long c = 0; c < nbins; ++c) start[c + 1] += start[c];
  std::vector<int> members(count);
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (int i = 0; i < n; ++i)
      if (body_bin[i] >= 0) members[fill[body_bin[i]]++] = i;
  }
  std::vector<std::vector<std::pair<int, std::uint8_t>>> found(n);
#pragma omp parallel for schedule(dynamic, 256) if (n > 2000)
  for (int i = 0; i < n; ++i) {
    if (body_bin[i] < 0) continue;
    auto& mine = found[i];
    const long c[3] = {body_bin[i] / (nb[1] * nb[2]), (body_bin[i] / nb[2]) % nb[1],
                       body_bin[i] % nb[2]};
    for (int ox = -1; ox <= 1; ++ox)
      for (int oy = -1; oy <= 1; ++oy)
        for (int oz = -1; oz <= 1; ++oz) {
          const int o[3] = {ox, oy, oz};
          long q[3];
          int shift[3];
          bool skip_bin = false;
          for (int a = 0; a < 3 && !skip_bin; ++a) {
            q[a] = c[a] + o[a];
            shift[a] = 0;
            if (cell.periodic[a]) {
              if (q[a] < 0) q[a] += nb[a], shift[a] = -1;
              else if (q[a] >= nb[a]) q[a] -= nb[a], shift[a] = 1;
            } else if (q[a] < 0 || q[a] >= nb[a]) {
              skip_bin = true;
            }
          }
          if (skip_bin) continue;
          const long bin = (q[0] * nb[1] + q[1]) * nb[2] + q[2];
          const Vec3 off = cell.h * Vec3(shift[0], shift[1], shift[2]);
          const auto code =
              static_cast<std::uint8_t>(9 * (shift[0] + 1) + 3 * (shift[1] + 1) + shift[2] + 1);
          for (int k = start[bin]; k < start[bin + 1]; ++k) {
            const int j = members[k];
            if (j <= i) continue;
            const Real r = radius[i] + radius[j] + margin;
            if ((pos[j] + off - pos[i]).squaredNorm() < r * r) mine.emplace_back(j, code);
          }
        }
    std::sort(mine.begin(), mine.end());
  }
  size_t total = 0;
  for (int i = 0; i < n; ++i) total += found[i].size();
  out.reserve(total);
  image.reserve(total);
  for (int i = 0; i < n; ++i)
    for (const auto& [j, code] : found[i]) {
      out.emplace_back(i, j);
      image.push_back(code);
    }
}

}  // namespace cpp_dem
