// The derivative of SE(3)'s logarithm: with e = log6(N) a pose error (m, rad) and J its CLIK
// rows, Jlog6(N^-1) J is the exact derivative of e, where J alone is its first order near the
// target (the set-point search's model on its general path, Task.error_jacobian).
#include <cmath>

#include "lie.hpp"
#include "registry.hpp"

namespace sjt {

namespace {

using Matrix3 = Eigen::Matrix3d;
using Vector3 = Eigen::Vector3d;

Matrix3 skew(const Vector3& x) {
  Matrix3 S;
  S << 0.0, -x(2), x(1), x(2), 0.0, -x(0), -x(1), x(0), 0.0;
  return S;
}

// The coefficients of the coupling block Q(v, w) of SE(3)'s Jacobian (Barfoot and Furgale,
// IEEE T-RO 2014, eq. 102) at t = |w|: c1 = (t - sin t) / t^3, c2 = (1 - t^2/2 - cos t) / t^4
// and c3 = (c2 - 3 (t - sin t - t^3/6) / t^5) / 2, as series below 0.3 rad (to t^8: the
// closed forms cancel there).
struct Coupling {
  double c1, c2, c3;
};

Coupling coupling(double t) {
  double t2 = t * t, d;
  Coupling c{};
  if (t < 0.3) {
    c.c1 = 1.0 / 6 + t2 * (-1.0 / 120 + t2 * (1.0 / 5040 + t2 * (-1.0 / 362880 + t2 / 39916800)));
    c.c2 =
        -1.0 / 24 + t2 * (1.0 / 720 + t2 * (-1.0 / 40320 + t2 * (1.0 / 3628800 - t2 / 479001600)));
    d = -1.0 / 120 +
        t2 * (1.0 / 5040 + t2 * (-1.0 / 362880 + t2 * (1.0 / 39916800 - t2 / 6227020800.0)));
  } else {
    double s = std::sin(t), co = std::cos(t);
    c.c1 = (t - s) / (t2 * t);
    c.c2 = (1.0 - 0.5 * t2 - co) / (t2 * t2);
    d = (t - s - t2 * t / 6.0) / (t2 * t2 * t);
  }
  c.c3 = 0.5 * (c.c2 - 3.0 * d);
  return c;
}

}  // namespace

// G = Jlog6(N^-1) (lie.hpp) is
// [[A, -A Q(v, w) A], [0, A]] with A = Jlog3(-w) = I - W/2 + k W^2, k = 1/t^2 - cot(t/2)/(2t),
// and Q the coupling block of SE(3)'s left Jacobian at (v, w).
void jlog6_inverse(const double* xi, MatrixMap G) {
  Vector3 v(xi[0], xi[1], xi[2]), w(xi[3], xi[4], xi[5]);
  Matrix3 V = skew(v), W = skew(w);
  double t = w.norm();
  double k = t < 1e-2 ? 1.0 / 12 + t * t / 720 + t * t * t * t / 30240
                      : 1.0 / (t * t) - 1.0 / (2.0 * t * std::tan(0.5 * t));
  Coupling c = coupling(t);
  Matrix3 WW = W * W, WV = W * V, VW = V * W, WVW = WV * W;
  Matrix3 A = Matrix3::Identity() - 0.5 * W + k * WW;
  Matrix3 Q = 0.5 * V + c.c1 * (WV + VW + WVW) + 3.0 * c.c2 * WVW - c.c2 * (W * WV) -
              c.c2 * (VW * W) - c.c3 * (WVW * W) - c.c3 * (W * WVW);
  G.topLeftCorner<3, 3>() = A;
  G.bottomRightCorner<3, 3>() = A;
  G.topRightCorner<3, 3>() = -(A * Q) * A;
  G.bottomLeftCorner<3, 3>().setZero();
}

void register_lie(nb::module_& m) {
  m.def(
      "jlog6_inverse",
      [](nb::handle xi, nb::handle out) {
        Array x(xi, "xi", 1);
        Array G(out, "out", 2, Access::write);
        x.length(6);
        G.shape(6, 6);
        jlog6_inverse(x.data(), G.matrix());
      },
      nb::arg("xi").none(), nb::arg("out").none(),
      "jlog6_inverse(xi, out): out (6 x 6) = Jlog6(N^-1) for xi = log6(N), [linear; angular]: "
      "the exact rows of a pose error log6 from its CLIK rows (-de/dq = G J).");
}

}  // namespace sjt
