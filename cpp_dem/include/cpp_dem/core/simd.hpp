// 3-vectors in registers for the hot loops, in two forms with the same arithmetic:
// WideOps (one 4-lane register, where the CPU has AVX2) and NarrowOps (Eigen's Vector3d).
// The law kernels (laws/) are templates over these, so each is written once for both.
#pragma once

#include <cstdlib>
#include <cstring>
#include <string>

#include "cpp_dem/core/types.hpp"

// V4 below is a 32-byte vector type; GCC notes that passing one by value has an ABI that
// depends on AVX. Its helpers are always inlined and no V4 crosses a function boundary.
#pragma GCC diagnostic ignored "-Wpsabi"

#define ALWAYS_INLINE __attribute__((always_inline)) inline

namespace cpp_dem {


/// 3-vectors in 4-lane registers (lane 3 zero) for the pair pass: one instruction per
/// operation where Eigen's Vector3d takes a 2-lane packet plus a scalar. GCC lowers the type
/// to the widest registers of each clone (two SSE2 registers in the baseline one).
typedef double V4 __attribute__((vector_size(32)));
typedef long long V4i __attribute__((vector_size(32)));
ALWAYS_INLINE V4 v4(const Vec3& a) { return V4{a[0], a[1], a[2], 0.0}; }
ALWAYS_INLINE Vec3 vec3(const V4& a) { return Vec3(a[0], a[1], a[2]); }
ALWAYS_INLINE void store3(Vec3& a, const V4& v) {
  a[0] = v[0];
  a[1] = v[1];
  a[2] = v[2];
}
/// Four doubles from / to memory laid out for it (a padded record: PairOutput, pair_fi_).
ALWAYS_INLINE V4 load4(const Real* p) {
  V4 r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
ALWAYS_INLINE void store4(Real* p, const V4& v) {
  std::memcpy(p, &v, sizeof v);
}
/// v with lane 3 set to zero, and v with lane 3 set to s.
ALWAYS_INLINE V4 zero_lane3(const V4& v) {
  return __builtin_shuffle(v, V4{}, V4i{0, 1, 2, 4});
}
ALWAYS_INLINE V4 with_lane3(const V4& v, Real s) {
  return __builtin_shuffle(v, V4{s, s, s, s}, V4i{0, 1, 2, 7});
}
ALWAYS_INLINE Real dot3(const V4& a, const V4& b) {
  const V4 p = a * b;
  return (p[0] + p[1]) + p[2];
}
ALWAYS_INLINE V4 cross3(const V4& a, const V4& b) {
  const V4i yzx = {1, 2, 0, 3}, zxy = {2, 0, 1, 3};
  return __builtin_shuffle(a, yzx) * __builtin_shuffle(b, zxy) -
         __builtin_shuffle(a, zxy) * __builtin_shuffle(b, yzx);
}

/// The 3-vector operations of the pair pass and the reduction, in two forms with the same
/// arithmetic. WideOps keeps a 3-vector in one 4-lane register (lane 3 zero), which pays where
/// the CPU has 256-bit registers (AVX2, AVX-512). NarrowOps is Eigen's Vector3d: without AVX,
/// GCC lowers the 4-lane type through the stack and the wide pass ran 5x slower (measured
/// with CPP_DEM_CLONES=OFF). The hot functions pick one per call (use_wide_ops()).
struct WideOps {
  using V = V4;
  ALWAYS_INLINE static V zero() { return V4{}; }
  ALWAYS_INLINE static V unit_z() { return V4{0, 0, 1, 0}; }
  ALWAYS_INLINE static V load(const Vec3& a) { return v4(a); }
  /// Three doubles and a zero pad (PairOutput, pair_fi_).
  ALWAYS_INLINE static V load_padded(const Real* p) { return load4(p); }
  /// Three doubles followed by another value (PairContact's fs, overlap and normal, fn).
  ALWAYS_INLINE static V load_head(const Real* p) { return zero_lane3(load4(p)); }
  ALWAYS_INLINE static void store(Vec3& a, const V& v) { store3(a, v); }
  ALWAYS_INLINE static void store_padded(Real* p, const V& v) { store4(p, v); }  // lane 3: 0
  ALWAYS_INLINE static void store_with(Real* p, const V& v, Real s) {
    store4(p, with_lane3(v, s));
  }
  ALWAYS_INLINE static Real dot(const V& a, const V& b) { return dot3(a, b); }
  ALWAYS_INLINE static V cross(const V& a, const V& b) { return cross3(a, b); }
  ALWAYS_INLINE static Vec3 vec(const V& a) { return vec3(a); }
};
struct NarrowOps {
  using V = Vec3;
  ALWAYS_INLINE static V zero() { return Vec3::Zero(); }
  ALWAYS_INLINE static V unit_z() { return Vec3::UnitZ(); }
  ALWAYS_INLINE static V load(const Vec3& a) { return a; }
  ALWAYS_INLINE static V load_padded(const Real* p) { return Vec3(p[0], p[1], p[2]); }
  ALWAYS_INLINE static V load_head(const Real* p) { return Vec3(p[0], p[1], p[2]); }
  ALWAYS_INLINE static void store(Vec3& a, const V& v) { a = v; }
  ALWAYS_INLINE static void store_padded(Real* p, const V& v) {  // the pad stays zero
    p[0] = v[0];
    p[1] = v[1];
    p[2] = v[2];
  }
  ALWAYS_INLINE static void store_with(Real* p, const V& v, Real s) {
    store_padded(p, v);
    p[3] = s;
  }
  ALWAYS_INLINE static Real dot(const V& a, const V& b) { return a.dot(b); }
  ALWAYS_INLINE static V cross(const V& a, const V& b) { return a.cross(b); }
  ALWAYS_INLINE static Vec3 vec(const V& a) { return a; }
};

/// A tangential 2-vector in the plane of an axis-aligned wall (its two other axes): the
/// operations of the tangential law parts, for the wall's short kernel.
struct Tan2 {
  Real a, b;
};
ALWAYS_INLINE Tan2 operator-(const Tan2& x, const Tan2& y) { return {x.a - y.a, x.b - y.b}; }
ALWAYS_INLINE Tan2 operator*(const Tan2& x, Real s) { return {x.a * s, x.b * s}; }
struct PlaneOps {
  using V = Tan2;
  ALWAYS_INLINE static V zero() { return {0.0, 0.0}; }
  ALWAYS_INLINE static Real dot(const V& x, const V& y) { return x.a * y.a + x.b * y.b; }
};

/// Whether the hot loops run WideOps: in the x86-64-v3/v4 variants of a multiversioned build
/// (the loader picked one, so the CPU has AVX2), or in a build for AVX; never with the
/// environment variable CPP_DEM_NARROW=1 set when the module loads (tests run both forms).
inline bool use_wide_ops() {
  static const bool narrow_asked = [] {
    const char* v = std::getenv("CPP_DEM_NARROW");
    return v != nullptr && std::string(v) == "1";
  }();
#if defined(CPP_DEM_CLONES)
  static const bool wide = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return wide && !narrow_asked;
#elif defined(__AVX__)
  return !narrow_asked;
#else
  (void)narrow_asked;
  return false;
#endif
}

/// Whether the pair pass runs its active linear contacts eight at a time on this CPU (its
/// batch kernel is compiled for AVX-512; passes/pair_batch.cpp), with the wide form on.
bool linear_batch_available();

}  // namespace cpp_dem
