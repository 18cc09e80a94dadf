// Basic types shared by the whole DEM core. SI units throughout.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace cpp_dem {

using Real = double;
using Vec3 = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;
using Mat3 = Eigen::Matrix3d;

/// Whether the geogrid (grid nodes, cohesive links, PFacets, grain–geogrid contacts) is
/// compiled into the step loop. CMake option CPP_DEM_GEOGRID (default ON); OFF defines
/// CPP_DEM_NO_GEOGRID, the step loop loses its geogrid branches (`if constexpr`) and the
/// entry points that add grid nodes, links or PFacets throw ParameterError.
#ifdef CPP_DEM_NO_GEOGRID
inline constexpr bool kGeogridBuilt = false;
#else
inline constexpr bool kGeogridBuilt = true;
#endif

/// The step's hot loops are compiled three times, for x86-64-v4 (AVX-512), x86-64-v3 (AVX2 +
/// FMA) and the baseline x86-64, and the dynamic loader picks the best one the CPU runs (GCC
/// function multiversioning): the default build runs on any x86-64 and uses AVX2 + FMA where
/// the CPU has them (measured on the benchmark packing: 12 % less time per step). Results
/// are the same on 1 and 2 threads either way; the baseline differs from the others in the
/// last bits (fused multiply-adds), so one machine's results are bitwise repeatable, not every
/// machine's. CMake: CPP_DEM_CLONES (default ON; off when CPP_DEM_MARCH is set).
#if defined(CPP_DEM_CLONES) && defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define CPP_DEM_MULTIVERSIONED 1  // (the clones exist: pair_batch.cpp compiles for their v4)
#define CPP_DEM_HOT __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define CPP_DEM_HOT
#endif

/// Degrees of freedom that can be blocked on a body (bit mask).
/// A blocked DOF keeps its current velocity (which may be an imposed one).
enum Dof : std::uint8_t {
  DOF_NONE = 0,
  DOF_X = 1,
  DOF_Y = 2,
  DOF_Z = 4,
  DOF_RX = 8,
  DOF_RY = 16,
  DOF_RZ = 32,
  DOF_XYZ = DOF_X | DOF_Y | DOF_Z,
  DOF_ROT = DOF_RX | DOF_RY | DOF_RZ,
  DOF_ALL = DOF_XYZ | DOF_ROT,
};

/// Bad user input: names the field, the value and what is allowed.
class ParameterError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// The simulation became unphysical (non-finite value, overlap too large).
/// The message names the step, the body (or contact) and the quantity.
class BlowUpError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Formats a value for error messages with enough digits to be recognised.
std::string fmt_real(Real v);

/// Throws ParameterError("<field>=<value>: <allowed>") unless ok.
inline void require(bool ok, const char* field, Real value, const char* allowed) {
  if (!ok) throw ParameterError(std::string(field) + "=" + fmt_real(value) + ": " + allowed);
}

/// A zero vector to read where a lazily allocated per-body array is empty (the external
/// forces and torques: BodyStore).
inline const Vec3 kZeroVec3 = Vec3::Zero();

}  // namespace cpp_dem
