// Each kernel file's registration of its Python entries (called by module.cpp).
#pragma once

#include <nanobind/nanobind.h>

namespace sjt {

void register_boundary(nanobind::module_& m);
void register_controller(nanobind::module_& m);
void register_braking(nanobind::module_& m);
void register_projection(nanobind::module_& m);
void register_method(nanobind::module_& m);
void register_lie(nanobind::module_& m);
void register_transforms(nanobind::module_& m);
void register_search(nanobind::module_& m);
void register_search_pose(nanobind::module_& m);

}  // namespace sjt
