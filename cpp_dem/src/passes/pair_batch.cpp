// The pair pass's batch kernel (pair_batch.hpp), compiled for AVX-512 (x86-64-v4): every
// function of pair_batch_kernel.inc is parsed under that target in a namespace of its own,
// so none of its inline functions is shared with code for another instruction set. With 16
// AVX2 registers the 8-lane kernel spills: compiled for x86-64-v3, the step at 1e3 bodies
// took 1.9 x its time with the v4 kernel and 1.6 x its time with the per-contact loop alone,
// so a CPU without AVX-512 runs that loop.
#include <cmath>
#include <cstring>

#include "cpp_dem/core/types.hpp"
#include "pair_batch.hpp"

#if defined(CPP_DEM_MULTIVERSIONED)
#pragma GCC push_options
#pragma GCC target("arch=x86-64-v4")
namespace cpp_dem::pair_batch::isa_v4 {
#include "pair_batch_kernel.inc"
}  // namespace cpp_dem::pair_batch::isa_v4
#pragma GCC pop_options
#elif defined(__AVX512F__)
// (a build for one instruction set with AVX-512, CPP_DEM_MARCH: its own)
namespace cpp_dem::pair_batch::isa_own {
#include "pair_batch_kernel.inc"
}  // namespace cpp_dem::pair_batch::isa_own
#endif

namespace cpp_dem {
namespace pair_batch {

template <bool kYadeShear, bool kPeriodic>
Kernel kernel() {
#if defined(CPP_DEM_MULTIVERSIONED)
  // (the test of the clones' resolver: a CPU with every feature of the level)
  static const bool v4 = __builtin_cpu_supports("x86-64-v4");
  return v4 ? &isa_v4::run<kYadeShear, kPeriodic> : nullptr;
#elif defined(__AVX512F__)
  return &isa_own::run<kYadeShear, kPeriodic>;
#else
  return nullptr;
#endif
}

template Kernel kernel<false, false>();
template Kernel kernel<false, true>();
template Kernel kernel<true, false>();
template Kernel kernel<true, true>();

}  // namespace pair_batch

bool linear_batch_available() {
  return use_wide_ops() && pair_batch::kernel<false, false>() != nullptr;
}

}  // namespace cpp_dem
