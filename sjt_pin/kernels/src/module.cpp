// sjt_pin.kernels._core: the compiled kernels, one file per idea, each registering its Python
// entries here. Arrays cross the boundary through array.hpp's checks.
#include <nanobind/nanobind.h>

#include "array.hpp"
#include "registry.hpp"

NB_MODULE(_core, m) {
  sjt::import_numpy();
  m.doc() = "The compiled kernels of sjt-pin (C++17 on Eigen, bound with nanobind).";
  sjt::register_boundary(m);
  sjt::register_controller(m);
  sjt::register_braking(m);
  sjt::register_bounds(m);
  sjt::register_projection(m);
  sjt::register_method(m);
  sjt::register_lie(m);
  sjt::register_transforms(m);
  sjt::register_search(m);
  sjt::register_search_pose(m);
  sjt::register_symmetric_eigen(m);
  sjt::register_dampers(m);
  sjt::register_collision_braking(m);
  sjt::register_witnesses(m);
  sjt::register_broad_phase(m);
  sjt::register_collision_queries(m);
}
