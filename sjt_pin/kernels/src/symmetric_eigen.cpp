// The eigen-decomposition of a small symmetric matrix: the saddle escape's curvature test
// (sjt_pin/curvature.py) reads the curvatures of f = 1/2 |e_w|^2 and their directions from the
// symmetric part of its finite-difference Hessian. Eigen's SelfAdjointEigenSolver
// (Householder tridiagonalisation, then the implicit symmetric QR): eigenvalues ascending,
// orthonormal eigenvectors as columns, as numpy's eigh gives them. The test runs once every
// few hundred steps, its code cold in the caches: through numpy and LAPACK the decomposition
// of a 6 x 6 matrix took 33-82 us of its step (UR5 on two frames' circles), here one call.
#include <Eigen/Eigenvalues>

#include "array.hpp"
#include "registry.hpp"

namespace sjt {

void register_symmetric_eigen(nb::module_& m) {
  m.def(
      "symmetric_eigen",
      [](nb::handle h, nb::handle values_out, nb::handle vectors_out) {
        Array H(h, "H", 2);
        Array values(values_out, "values", 1, Access::write);
        Array vectors(vectors_out, "vectors", 2, Access::write);
        const Index n = H.rows();
        H.shape(n, n).finite();
        values.length(n);
        vectors.shape(n, n);
        if (n == 0) return;
        const Eigen::MatrixXd symmetric = 0.5 * (H.matrix() + H.matrix().transpose());
        const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(symmetric);
        if (solver.info() != Eigen::Success)
          fail("symmetric_eigen: the decomposition did not converge");
        values.vector() = solver.eigenvalues();
        vectors.matrix() = solver.eigenvectors();
      },
      nb::arg("H").none(), nb::arg("values").none(), nb::arg("vectors").none(),
      "symmetric_eigen(H, values, vectors): the eigen-decomposition of H's symmetric part "
      "(H: n x n, finite) into values (n, ascending) and vectors (n x n, orthonormal "
      "eigenvectors as columns), as numpy.linalg.eigh of (H + H^T) / 2.");
}

}  // namespace sjt
