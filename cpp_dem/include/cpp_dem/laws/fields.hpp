// The parameters of a material as one field list: each field's name, unit, default and allowed
// range. The Python face (Material's keywords, attributes, repr, pickle, replace), validation
// and the checkpoint all read the list, so a new parameter is one line where it belongs:
// material.hpp's kMaterialFields for the parameters every law shares, the law's own kFields
// (laws/linear.hpp, laws/hertz_mindlin.hpp) for the ones only that law reads.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "cpp_dem/core/types.hpp"

namespace cpp_dem {

struct Material;

/// Law-owned parameters a material carries (Material::law_params): the most any law declares.
inline constexpr int kLawParamSlots = 4;

/// How a field's Python value relates to the stored one.
enum class FieldScale : std::uint8_t {
  Plain,    ///< stored as given
  Degrees,  ///< given in degrees, stored in radians
};

/// One parameter of a material. Values and bounds are in the Python units (`unit`).
struct FieldInfo {
  const char* name;   ///< Python keyword and attribute, checkpoint key
  const char* unit;   ///< SI unit of the Python value ("-": none)
  const char* doc;    ///< one line for the docstring
  Real fallback;      ///< default; NaN: the parameter is required
  Real lo;            ///< lower bound (-inf: none)
  bool lo_closed;     ///< lo itself allowed
  Real hi;            ///< upper bound (inf: none)
  bool hi_closed;     ///< hi itself allowed
  FieldScale scale = FieldScale::Plain;
  /// Where the value is stored: a named member of Material (a shared field), or nullptr and
  /// the Material::law_params slot (a law-owned field).
  Real Material::*member = nullptr;
  int slot = -1;

  bool required() const { return std::isnan(fallback); }
  /// The stored value of a Python value (degrees -> radians: v * pi / 180).
  Real to_stored(Real v) const { return scale == FieldScale::Degrees ? v * M_PI / 180.0 : v; }
  /// The Python value of a stored value (radians -> degrees: s * 180 / pi).
  Real to_python(Real s) const { return scale == FieldScale::Degrees ? s * 180.0 / M_PI : s; }
  /// "> 0", "in [0, 1]", ... (Python units)
  std::string range() const;
  /// "must be > 0 (Pa)", "must be in [0, 1] (ratio of critical)", ...
  std::string allowed() const;
  /// Throws ParameterError("<name>=<value>: must be ...") unless the Python value is allowed.
  void check(Real python_value) const;
};

inline constexpr Real kRequired = std::numeric_limits<Real>::quiet_NaN();
inline constexpr Real kNoBound = std::numeric_limits<Real>::infinity();

}  // namespace cpp_dem
