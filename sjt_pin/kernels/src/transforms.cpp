// The tasks' small transforms: a desired twist seen from the frame, the rotation defect of a
// homogeneous matrix, a position task's rows, and the unit-norm defect of a configuration's
// blocks (quaternions, (cos, sin) pairs).
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <utility>

#include "array.hpp"
#include "registry.hpp"

namespace sjt {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The desired twist `velocity` ([linear, angular], world axes at the desired origin oMd) in
// the frame's own axes at its origin (LOCAL): v' = R^T (v + w x (p_f - p_d)), w' = R^T w.
void frame_velocity(const Array& f, const Array& target, const double* velocity, double* out) {
  ConstMatrixMap oMf = f.matrix(), oMd = target.matrix();
  Eigen::Vector3d d = oMf.block<3, 1>(0, 3) - oMd.block<3, 1>(0, 3);
  Eigen::Vector3d w(velocity[3], velocity[4], velocity[5]);
  Eigen::Vector3d v = Eigen::Vector3d(velocity[0], velocity[1], velocity[2]) + w.cross(d);
  Eigen::Matrix3d Rt = oMf.block<3, 3>(0, 0).transpose();
  Eigen::Matrix<double, 6, 1> twist;
  twist << Rt * v, Rt * w;
  Eigen::Map<Eigen::Matrix<double, 6, 1>> result(out);
  result = twist;
}

// max |R^T R - I| of the 4 x 4 M's rotation block; inf when M is not rigid otherwise (det <= 0,
// a last row other than [0 0 0 1]), NaN when an entry of its first three rows is not finite.
double rotation_defect(const Array& a) {
  ConstMatrixMap M = a.matrix();
  Eigen::Matrix3d R = M.block<3, 3>(0, 0);
  Eigen::Matrix3d gram = R.transpose() * R - Eigen::Matrix3d::Identity();
  double defect = 0.0;
  for (Index k = 0; k < 9; ++k) {
    double x = gram.data()[k];
    if (std::isnan(x)) return kNaN;
    defect = std::fmax(defect, std::fabs(x));
  }
  double det = R.determinant();
  if (std::isnan(det) || !M.block<3, 1>(0, 3).allFinite()) return kNaN;
  if (!(det > 0.0) || M(3, 0) != 0.0 || M(3, 1) != 0.0 || M(3, 2) != 0.0 || M(3, 3) != 1.0)
    return kInf;
  return defect;
}

// The largest |sum(q[first:first + size]^2) - 1| over the blocks (first, size); NaN if one is.
double unit_defect(const double* q, const IndexArray& blocks) {
  double worst = 0.0;
  for (Index i = 0; i < blocks.rows(); ++i) {
    double sum = 0.0;
    for (std::int64_t j = blocks(i, 0); j < blocks(i, 0) + blocks(i, 1); ++j) sum += q[j] * q[j];
    double d = std::fabs(sum - 1.0);
    if (std::isnan(d)) return d;
    worst = std::fmax(worst, d);
  }
  return worst;
}

}  // namespace

void register_transforms(nb::module_& m) {
  m.def(
      "frame_velocity",
      [](nb::handle oMf, nb::handle oMd, nb::handle velocity, nb::handle out) {
        Array f(oMf, "oMf", 2), d(oMd, "oMd", 2), v(velocity, "velocity", 1);
        Array o(out, "out", 1, Access::write);
        f.shape(4, 4);
        d.shape(4, 4);
        v.length(6);
        o.length(6);
        frame_velocity(f, d, v.data(), o.data());
      },
      nb::arg("oMf").none(), nb::arg("oMd").none(), nb::arg("velocity").none(),
      nb::arg("out").none(),
      "frame_velocity(oMf, oMd, velocity, out): the desired twist velocity (6,: [linear, "
      "angular], world axes at oMd's origin) seen from the frame oMf (4 x 4), LOCAL, into out.");
  m.def(
      "rotation_defect",
      [](nb::handle M) {
        Array a(M, "M", 2);
        a.shape(4, 4);
        return rotation_defect(a);
      },
      nb::arg("M").none(),
      "rotation_defect(M) -> float: max |R^T R - I| of a 4 x 4 homogeneous matrix (inf: not "
      "rigid, nan: not finite).");
  m.def(
      "position_rows",
      [](nb::handle J6, nb::handle oMf, nb::handle p_d, nb::handle velocity, nb::handle axes,
         nb::handle J, nb::handle e, nb::handle ff) {
        Array J6a(J6, "J6", 2), f(oMf, "oMf", 2), p(p_d, "p_d", 1), v(velocity, "velocity", 1);
        IndexArray rows(axes, "axes", 1);
        Array Jo(J, "J", 2, Access::write), eo(e, "e", 1, Access::write);
        Array fo(ff, "ff", 1, Access::write);
        Index n = J6a.cols(), d = rows.size();
        J6a.shape(6, n);
        f.shape(4, 4);
        p.length(3);
        if (v.size() != 0 && v.size() != 3 && v.size() != 6)
          fail("velocity must have length 0 (none), 3 or 6, got " + std::to_string(v.size()));
        if (d < 1 || d > 3) fail("axes must have 1 to 3 entries, got " + std::to_string(d));
        rows.within(0, 3);
        Jo.shape(d, n);
        eo.length(d);
        fo.length(d);
        ConstMatrixMap J6m = std::as_const(J6a).matrix(), fm = std::as_const(f).matrix();
        MatrixMap Jm = Jo.matrix();
        for (Index r = 0; r < d; ++r) {
          Index a = rows[r];
          Jm.row(r) = J6m.row(a);
          eo.data()[r] = p.data()[a] - fm(a, 3);
          if (v.size() != 0) fo.data()[r] = v.data()[a];
        }
      },
      nb::arg("J6").none(), nb::arg("oMf").none(), nb::arg("p_d").none(),
      nb::arg("velocity").none(), nb::arg("axes").none(), nb::arg("J").none(), nb::arg("e").none(),
      nb::arg("ff").none(),
      "position_rows(J6, oMf, p_d, velocity, axes, J, e, ff): a position task's rows along "
      "axes (int64, 0-2): J = J6[axes] (the linear rows of the LOCAL_WORLD_ALIGNED Jacobian), "
      "e = (p_d - p)[axes] and, with a velocity (3 or 6 entries; none: length 0), "
      "ff = velocity[axes].");
  m.def(
      "unit_defect",
      [](nb::handle q, nb::handle blocks) {
        Array qa(q, "q", 1);
        IndexArray b(blocks, "blocks", 2);
        b.shape(b.rows(), 2);
        for (Index i = 0; i < b.rows(); ++i)
          if (b(i, 0) < 0 || b(i, 1) < 0 || b(i, 1) > qa.size() || b(i, 0) > qa.size() - b(i, 1)) {
            std::ostringstream out;
            out << "blocks: block (" << b(i, 0) << ", " << b(i, 1) << ") is outside q ("
                << qa.size() << ",)";
            fail(out.str());
          }
        return unit_defect(qa.data(), b);
      },
      nb::arg("q").none(), nb::arg("blocks").none(),
      "unit_defect(q, blocks) -> float: the largest |squared norm - 1| of q's unit blocks "
      "(blocks: int64 (k, 2) of (first, size); NaN if a block is NaN).");
}

}  // namespace sjt
