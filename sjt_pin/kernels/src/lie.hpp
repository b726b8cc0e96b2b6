// The derivative of a logarithmic error (lie.cpp): a task error e = log6(N) (a pose) or
// e = log3(N) (an orientation) has the exact rows G J, -de/dq, where its CLIK rows J are
// only its first order near the target.
#pragma once

#include "array.hpp"

namespace sjt {

// G = Jlog6(N^-1) (6 x 6, [linear; angular]) from xi = log6(N)
void jlog6_inverse(const double* xi, MatrixMap G);
// A = Jlog3(N^-1) (3 x 3) from w = log3(N)
void jlog3_inverse(const double* w, MatrixMap A);

}  // namespace sjt
