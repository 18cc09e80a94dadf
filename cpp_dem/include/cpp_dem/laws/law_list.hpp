// The list of contact laws: one line per law. Everything that enumerates the laws (the
// ContactModel ids, the registry table, the dispatch of the hot loops, the Python names) is
// generated from this list, so adding a law touches this line, its own header (the elastic
// part: mixing rule, force, stiffness, energy; see laws/linear.hpp) and its registry include
// (laws/registry.hpp). docs/developing.md walks through it.
#pragma once

#include <cstdint>

/// X(Id, "python name", ElasticPart): the law's id in ContactModel, its name in the Python
/// API and run files, and the struct of static functions that is its elastic part.
#define CPP_DEM_CONTACT_LAWS(X)                         \
  X(Linear, "linear", LinearElastic)                   \
  X(HertzMindlin, "hertz_mindlin", HertzMindlinElastic)

namespace cpp_dem {

/// The elastic (normal/tangential) model of a contact law: its id in the registry.
enum class ContactModel : std::uint8_t {
#define CPP_DEM_LAW_ID(id, name, part) id,
  CPP_DEM_CONTACT_LAWS(CPP_DEM_LAW_ID)
#undef CPP_DEM_LAW_ID
};

}  // namespace cpp_dem
