// Profiling driver for the throughput scene (bench/throughput.py), C++ only: reads a packing
// CSV (x,y,z,r, header), builds the same scene (linear law, friction 30 deg, E = 1e7 Pa,
// density 2600, local damping 0.2, no gravity, six walls of the box [0, side]^3, margin
// 0.2 x mean radius, dt = 0.5 min R sqrt(rho / E)), runs warm-up steps, then timed steps,
// and prints the time per step and a checksum of the final state (bit patterns of positions,
// velocities, angular velocities, orientations and wall forces) so that two builds or two
// thread counts can be compared bit for bit.
//
//   bash bench/build_profile_step.sh     # -> build/profile/profile_step
//   OMP_NUM_THREADS=1 build/profile/profile_step packing.csv <side> <steps> [warmup]
//   OMP_NUM_THREADS=1 valgrind --tool=callgrind --instr-atstart=no \
//       build/profile/profile_step packing.csv <side> 50 20   (counts the 50 timed steps only)
#include <omp.h>
#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#else
#define CALLGRIND_START_INSTRUMENTATION
#define CALLGRIND_STOP_INSTRUMENTATION
#endif

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include "cpp_dem/scene.hpp"

using namespace cpp_dem;

namespace {
std::uint64_t mix(std::uint64_t h, double v) {
  std::uint64_t b;
  std::memcpy(&b, &v, 8);
  h ^= b + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
  return h;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::cerr << "usage: profile_step packing.csv side_m steps [warmup]\n";
    return 2;
  }
  std::ifstream in(argv[1]);
  const double side = std::stod(argv[2]);
  const long steps = std::stol(argv[3]);
  const long warmup = argc > 4 ? std::stol(argv[4]) : 20;
  std::string line;
  std::getline(in, line);  // header
  std::vector<Vec3> pos;
  std::vector<Real> rad;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    std::stringstream ss(line);
    double v[4];
    char comma;
    ss >> v[0] >> comma >> v[1] >> comma >> v[2] >> comma >> v[3];
    pos.emplace_back(v[0], v[1], v[2]);
    rad.push_back(v[3]);
  }
  Scene s;
  Material m;
  m.model = ContactModel::Linear;
  m.density = 2600;
  m.young = 1e7;
  m.poisson = 0.3;
  m.friction_angle = 30.0 * M_PI / 180.0;
  const int mat = s.add_material(m);
  for (int a = 0; a < 3; ++a) {
    s.add_wall(a, 0.0, +1, mat);
    s.add_wall(a, side, -1, mat);
  }
  s.add_spheres(pos, rad, mat);
  double rsum = 0, rmin = 1e300;
  for (double r : rad) {
    rsum += r;
    rmin = std::min(rmin, r);
  }
  s.set_verlet_margin(0.2 * rsum / rad.size());
  s.set_local_damping(0.2);
  s.set_gravity(Vec3::Zero());
  s.set_dt(0.5 * rmin * std::sqrt(2600 / 1e7));
  s.run(warmup);
  const long builds0 = s.collider_stats().builds;
  // Under callgrind --instr-atstart=no only the timed steps are counted.
  CALLGRIND_START_INSTRUMENTATION;
  const double t0 = omp_get_wtime();
  s.run(steps);
  const double t1 = omp_get_wtime();
  CALLGRIND_STOP_INSTRUMENTATION;
  std::uint64_t h = 0;
  for (int b = 0; b < s.num_bodies(); ++b) {
    for (int a = 0; a < 3; ++a) {
      h = mix(h, s.positions()[b][a]);
      h = mix(h, s.velocities()[b][a]);
      h = mix(h, s.angular_velocities()[b][a]);
    }
    const Quat& q = s.orientations()[b];
    h = mix(h, q.w());
    h = mix(h, q.x());
    h = mix(h, q.y());
    h = mix(h, q.z());
  }
  for (int w = 0; w < s.num_walls(); ++w)
    for (int a = 0; a < 3; ++a) h = mix(h, s.wall(w).force[a]);
  // DUMP_STATE=file: positions, velocities, angular velocities, forces (n x 3 doubles each,
  // raw) to compare two builds that are not bit-identical.
  if (const char* dump = std::getenv("DUMP_STATE")) {
    std::ofstream out(dump, std::ios::binary);
    for (const auto* v : {&s.positions(), &s.velocities(), &s.angular_velocities(), &s.forces()})
      out.write(reinterpret_cast<const char*>(v->data()), v->size() * sizeof(Vec3));
  }
  std::printf(
      "n=%d threads=%d steps=%ld ms/step=%.4f p-steps/s=%.3e contacts=%d builds_timed=%ld "
      "pair_candidates=%zu wall_candidates=%zu checksum=%016llx\n",
      s.num_bodies(), omp_get_max_threads(), steps, 1e3 * (t1 - t0) / steps,
      s.num_bodies() * steps / (t1 - t0), s.num_active_contacts(),
      s.collider_stats().builds - builds0, s.collider_stats().pair_candidates, s.wall_contacts().size(),
      static_cast<unsigned long long>(h));
  return 0;
}
