// The geogrid's entry points in a build without the geogrid (CMake -DCPP_DEM_GEOGRID=OFF,
// which compiles this file instead of grid.cpp). A scene of such a build can hold spheres
// and walls only; its step loop has no geogrid branches (kGeogridBuilt is false).
#include "cpp_dem/scene.hpp"

#ifndef CPP_DEM_NO_GEOGRID
#error "grid_off.cpp is for builds with -DCPP_DEM_GEOGRID=OFF (CPP_DEM_NO_GEOGRID); use grid.cpp"
#endif

namespace cpp_dem {

namespace {
[[noreturn]] void no_geogrid(const char* what) {
  throw ParameterError(std::string(what) +
                       ": this build has no geogrid support (built with -DCPP_DEM_GEOGRID=OFF)");
}
}  // namespace

int Scene::add_grid_nodes(const std::vector<Vec3>&, Real, const std::vector<Real>&,
                          const std::vector<Real>&, int) {
  no_geogrid("add_grid_nodes");
}

int Scene::add_grid_link(int, int, const BeamParams&, int) { no_geogrid("add_grid_link"); }

int Scene::add_pfacet(int, int, int, int, int, int, int) { no_geogrid("add_pfacet"); }

}  // namespace cpp_dem
