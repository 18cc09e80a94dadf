// How the hot loops share work between OpenMP threads: thresholds, blocks of bodies, and
// the fixed split that keeps every sum independent of the number of threads.
#pragma once

#include <utility>

#ifdef _OPENMP
#include <omp.h>
#endif

namespace cpp_dem {

/// Below this many items a loop runs serially: a parallel region costs more than it saves
/// (measured: at 1000 spheres a threshold of 1000 cost a third of the 2-thread speed).
/// (Results do not depend on it: every item is computed independently.)
constexpr long kParallelMin = 128;

/// Bodies per block of the integration pass; the wall pass visits its contacts by the same
/// blocks, and both give thread t the blocks thread_share(nblocks, t, nt), so a thread's wall
/// contacts belong to the bodies it integrates (their records stay in its cache).
constexpr int kBodyBlock = 64;
inline std::pair<long, long> thread_share(long total, long t, long nt) {
  return {t * total / nt, (t + 1) * total / nt};
}
/// This thread's number and the number of threads in the team.
/// The threads a parallel region would start with (1 without OpenMP).
inline int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

inline std::pair<long, long> thread_and_team() {
#ifdef _OPENMP
  return {omp_get_thread_num(), omp_get_num_threads()};
#else
  return {0, 1};
#endif
}


}  // namespace cpp_dem
