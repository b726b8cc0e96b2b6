// Each kernel file's registration of its Python entries (called by module.cpp).
#pragma once

#include <nanobind/nanobind.h>

namespace sjt {

void register_boundary(nanobind::module_& m);
void register_controller(nanobind::module_& m);
void register_braking(nanobind::module_& m);
void register_bounds(nanobind::module_& m);
void register_projection(nanobind::module_& m);
void register_method(nanobind::module_& m);
void register_lie(nanobind::module_& m);
void register_transforms(nanobind::module_& m);
void register_search(nanobind::module_& m);  // search_binding.cpp
void register_search_pose(nanobind::module_& m);
void register_symmetric_eigen(nanobind::module_& m);
// the collision limit's kernels (sjt_pin/limits/collision.py)
void register_dampers(nanobind::module_& m);             // dampers.cpp
void register_collision_braking(nanobind::module_& m);   // collision_braking.cpp
void register_witnesses(nanobind::module_& m);           // witnesses.cpp
void register_broad_phase(nanobind::module_& m);         // broad_phase.cpp
void register_collision_queries(nanobind::module_& m);   // collision_queries.cpp

}  // namespace sjt
