// Binding of the exact checkpoint (checkpoint.hpp): bytes in, bytes out.
#include "convert.hpp"
#include "cpp_dem/checkpoint.hpp"

namespace cpp_dem::bind {

void bind_checkpoint(py::module_& m) {
  m.def("_checkpoint_save", [](const Scene& s) {
    const auto blob = Checkpoint::save(s);
    return py::bytes(reinterpret_cast<const char*>(blob.data()), blob.size());
  }, py::arg("scene"), "The whole state of a scene and of its controllers as bytes.");
  m.def("_checkpoint_load", [](Scene& s, py::bytes data, bool replace) {
    const std::string str = data;
    std::vector<std::uint8_t> blob(str.begin(), str.end());
    Checkpoint::load(s, blob, replace);
  }, py::arg("scene"), py::arg("blob"), py::kw_only(), py::arg("replace") = false,
     "Restores bytes from _checkpoint_save into the scene they came from (or a blank one), "
     "holding the same controllers; replace=True lets them replace another scene.");
}

}  // namespace cpp_dem::bind
