// The collision limit's velocity-damper rows (sjt_pin/limits/collision.py): one row per pair
// on the relative normal velocity of its closest points.
#include <cmath>
#include <sstream>

#include "collision.hpp"
#include "registry.hpp"

namespace sjt {

void damper_rows_into(const StridedMatrixMap& J, const ConstMatrixMap& support, const double* rows,
                      Index k, double rate, double* A, double* b) {
  const Index N = J.cols();
  // (J's 6 rows known here: u^T J summed in place, column by column, without a temporary)
  Eigen::Map<const Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::RowMajor>, 0,
             Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>
      J6(J.data(), 6, N,
         Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(J.outerStride(), J.innerStride()));
  MatrixMap out(A, k, N);
  for (Index i = 0; i < k; ++i) {
    const double* r = rows + row::size * i;
    Eigen::Map<const Vector3> n(r + row::normal);
    Eigen::Matrix<double, 6, 1> u[2];
    Index joint[2];
    for (int side = 0; side < 2; ++side) {
      Eigen::Map<const Vector3> p(r + (side ? row::point_b : row::point_a));
      u[side] << n, p.cross(n);  // n.v(p) = n.v_O + (p x n).w
      joint[side] = static_cast<Index>(r[side ? row::joint_b : row::joint_a]);
    }
    out.row(i) = u[0].transpose().lazyProduct(J6).cwiseProduct(support.row(joint[0])) -
                 u[1].transpose().lazyProduct(J6).cwiseProduct(support.row(joint[1]));
    // a row no joint moves along n (a link turning about an axis through its closest point)
    // is rounding, not a lever: 3e-15 m/rad on Kinova's first link, whose row then bound the
    // base's turn to one direction
    double lever_sq = out.row(i).squaredNorm();
    if (lever_sq <= kRoundingLever * kRoundingLever) {
      out.row(i).setZero();
      lever_sq = 0.0;
    }
    b[i] = rate * (r[row::distance] - r[row::margin]);
    // inside the margin a short lever turns the link about a point near its closest one
    // rather than away, and the row only keeps the pair from closing. (Z1's upper arm beside
    // a table at its shoulder, 1.5 mm/rad: the push drove the shoulder at its speed limit, or
    // at half its acceleration limit, for good while the distance never grew; the arm swung
    // at up to 3.1 rad/s, and under acceleration limits its forearm went through the table.)
    if (b[i] < 0.0 && lever_sq < kPushLever * kPushLever) b[i] = 0.0;
  }
}

void register_dampers(nb::module_& m) {
  m.attr("ROUNDING_LEVER") = kRoundingLever;
  m.attr("PUSH_LEVER") = kPushLever;
  m.def(
      "damper_rows",
      [](nb::handle J_obj, nb::handle support_obj, nb::handle pairs_obj, double rate,
         nb::handle A_obj, nb::handle b_obj) {
        Array J(J_obj, "J", 2, Access::read, Order::any);
        const Array support(support_obj, "support", 2);
        Array pairs(pairs_obj, "pairs", 2);
        Array A(A_obj, "A", 2, Access::write);
        Array b(b_obj, "b", 1, Access::write);
        const Index k = pairs.rows(), N = J.cols();
        if (J.rows() != 6 || support.cols() != N || pairs.cols() != row::size ||
            A.rows() != k || A.cols() != N || b.size() != k) {
          std::ostringstream out;
          out << "J (6, N), support (njoints, N), pairs (k, 13), A (k, N) and b (k,) do not "
              << "fit: J (" << J.rows() << ", " << N << "), support (" << support.rows() << ", "
              << support.cols() << "), pairs (" << k << ", " << pairs.cols() << "), A ("
              << A.rows() << ", " << A.cols() << "), b (" << b.size() << ",)";
          fail(out.str());
        }
        check_row_joints(pairs.data(), k, support.rows(), "pairs", "support");
        damper_rows_into(J.strided(), support.matrix(), pairs.data(), k, rate, A.data(),
                         b.data());
      },
      nb::arg("J"), nb::arg("support"), nb::arg("pairs"), nb::arg("rate"), nb::arg("A"),
      nb::arg("b"),
      "damper_rows(J, support, pairs, rate, A, b): one velocity-damper row per pair. J (6, N):\n"
      "Pinocchio's WORLD joint Jacobians (data.J, rows linear then angular; C or Fortran\n"
      "order); support (njoints, N): 1 where a column moves a joint's frame; pairs (k, 13):\n"
      "distance d, margin, the joints of the two geometries (a, b), the unit normal n from a\n"
      "to b (coal's), the closest points p_a and p_b (world). Row i: A_i = (u_a^T J)\n"
      "support[a] - (u_b^T J) support[b] with u_x = [n; p_x x n], and b_i = rate (d -\n"
      "margin), but 0 where b_i < 0 and |A_i| < PUSH_LEVER (0.01: a pair inside its margin is\n"
      "pushed out only by a lever of at least 1 cm per unit); a row |A_i| <= ROUNDING_LEVER\n"
      "(1e-12) is rounding and set to 0; A (k, N) and b (k,) are written.");
}

}  // namespace sjt
