// Each kernel file's registration of its Python entries (called by module.cpp).
#pragma once

#include <nanobind/nanobind.h>

namespace sjt {

void register_boundary(nanobind::module_& m);

}  // namespace sjt
