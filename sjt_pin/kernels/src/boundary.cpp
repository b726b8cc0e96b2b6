// check_array: the boundary's own check, exposed for the tests (tests/test_boundary.py).
#include "array.hpp"
#include "registry.hpp"

namespace sjt {

void register_boundary(nb::module_& m) {
  m.def(
      "check_array",
      [](nb::handle object, int ndim, bool writable) {
        Array a(object, "array", ndim, writable ? Access::write : Access::read);
        return a.size();
      },
      nb::arg("array"), nb::arg("ndim"), nb::arg("writable") = false,
      "check_array(array, ndim, writable=False) -> int: the number of entries of a float64 "
      "array the kernels accept (TypeError or ValueError otherwise, naming what is wrong).");
}

}  // namespace sjt
