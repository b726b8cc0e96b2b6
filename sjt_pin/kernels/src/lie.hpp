// The derivative of SE(3)'s logarithm (lie.cpp).
#pragma once

#include "array.hpp"

namespace sjt {

// G = Jlog6(N^-1) (6 x 6, [linear; angular]) from xi = (v, w) = log6(N): the exact rows of a
// pose error e = log6(N) from its CLIK rows J are G J (-de/dq).
void jlog6_inverse(const double* xi, MatrixMap G);

}  // namespace sjt
