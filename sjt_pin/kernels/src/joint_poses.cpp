// The joints' world poses the collision kernels read from Pinocchio's data, and the checks of
// the joints a pair row names (collision.hpp).
#include <sstream>

#include "collision.hpp"

namespace sjt {

void check_row_joints(const double* rows, Index count, Index njoints, const char* name,
                      const char* of) {
  for (Index i = 0; i < count; ++i)
    for (Index side : {row::joint_a, row::joint_b}) {
      double j = rows[row::size * i + side];
      // (a whole number in range: NaN, inf and fractions name no joint)
      if (!(j >= 0.0 && j < static_cast<double>(njoints) && j == static_cast<double>(
                                                                     static_cast<Index>(j)))) {
        std::ostringstream out;
        out << name << "[" << i << "] names joint "
            << (j >= 0.0 && j < 9e18 ? std::to_string(static_cast<long long>(j))
                                     : std::to_string(j))
            << "; " << of << " has " << njoints;
        fail(out.str());
      }
    }
}

void check_views(nb::handle views, const char* who) {
  PyObject* v = views.ptr();
  if (PyTuple_Check(v) && PyTuple_GET_SIZE(v) == 4 && PyList_Check(PyTuple_GET_ITEM(v, 2)) &&
      PyList_Check(PyTuple_GET_ITEM(v, 3)) &&
      PyList_GET_SIZE(PyTuple_GET_ITEM(v, 2)) == PyList_GET_SIZE(PyTuple_GET_ITEM(v, 3)))
    return;
  std::ostringstream out;
  out << who << ": data views must be (data, J, rotations, translations), the last two lists "
      << "of one array per joint";
  throw nb::type_error(out.str().c_str());
}

JointPoses::JointPoses(nb::handle source, Source kind, Index njoints, double* out)
    : source_(source), kind_(kind), njoints_(njoints), out_(out),
      fetched_(static_cast<std::size_t>(njoints), 0) {
  if (kind == Source::views) check_views(source, "joint poses");
  if (kind == Source::oMi) oMi_ = nb::borrow(source);
  if (njoints > 0) {
    PoseMap(out_).setIdentity();  // joint 0: the world
    fetched_[0] = 1;
  }
}

ConstPoseMap JointPoses::at(Index j) {
  if (j < 0 || j >= njoints_) {
    std::ostringstream out;
    out << "joint " << j << " is no joint (njoints " << njoints_ << ")";
    fail(out.str());
  }
  double* H = out_ + 16 * j;
  if (fetched_[static_cast<std::size_t>(j)]) return ConstPoseMap(H);
  PoseMap pose(H);
  if (kind_ == Source::views) {
    nb::handle rotations = PyTuple_GET_ITEM(source_.ptr(), 2);
    nb::handle translations = PyTuple_GET_ITEM(source_.ptr(), 3);
    if (j >= static_cast<Index>(PyList_GET_SIZE(rotations.ptr()))) {
      std::ostringstream out;
      out << "no view of joint " << j << "'s pose (" << PyList_GET_SIZE(rotations.ptr())
          << " joints)";
      fail(out.str());
    }
    // (views onto Pinocchio's Eigen matrices: a rotation is Fortran-ordered)
    Array R(PyList_GET_ITEM(rotations.ptr(), j), "a joint's rotation", 2, Access::read,
            Order::any);
    Array t(PyList_GET_ITEM(translations.ptr(), j), "a joint's translation", 1);
    R.shape(3, 3);
    t.length(3);
    pose.setIdentity();
    pose.topLeftCorner<3, 3>() = R.strided();
    pose.topRightCorner<3, 1>() = t.vector();
  } else {
    if (!oMi_.is_valid()) oMi_ = source_.attr("oMi");
    nb::object H_obj = oMi_[nb::int_(j)].attr("homogeneous");
    Array M(H_obj, "oMi[j].homogeneous", 2, Access::read, Order::any);
    M.shape(4, 4);
    pose = M.strided();
  }
  fetched_[static_cast<std::size_t>(j)] = 1;
  return ConstPoseMap(H);
}

}  // namespace sjt
