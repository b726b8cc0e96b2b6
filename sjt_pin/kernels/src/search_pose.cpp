// The set-point search on one pose task: every iteration of a start in one call (per
// iteration one call of Pinocchio's frame Jacobian, then the pose error log6, the iteration of
// search.cpp and the integration of its step), and the starts of the restart table
// (sjt_pin.restarts.NearStarts) in one call.
#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <utility>

#include "registry.hpp"
#include "search.hpp"

namespace sjt {

namespace {

using Matrix3 = Eigen::Matrix3d;
using Vector3 = Eigen::Vector3d;

// w = log3(R) (rad): (theta / sin theta) vee(R - R^T) / 2 below 120 degrees, the axis from the
// symmetric part R + R^T above (where sin theta no longer carries it)
Vector3 log3(const Matrix3& R) {
  Vector3 a(0.5 * (R(2, 1) - R(1, 2)), 0.5 * (R(0, 2) - R(2, 0)), 0.5 * (R(1, 0) - R(0, 1)));
  double s = a.norm(), c = 0.5 * (R.trace() - 1.0);
  double theta = std::atan2(s, c);
  if (c > -0.5) return (s > 0.0 ? theta / s : 1.0) * a;
  Index k = 0;  // (R + R^T) / 2 - c I = (1 - c) u u^T: its largest diagonal entry's column
  for (Index i = 1; i < 3; ++i)
    if (R(i, i) > R(k, k)) k = i;
  Vector3 u = 0.5 * (R.col(k) + R.row(k).transpose());
  u[k] -= c;
  double scale = theta / std::sqrt(u[k] * (1.0 - c));
  return (u.dot(a) < 0.0 ? -scale : scale) * u;
}

// The pose error [e_p; e_w] = log6(oMf^-1 oMd) of a frame at (R, p) to the target Md (4 x 4),
// in world axes at the frame (the rows of the LOCAL_WORLD_ALIGNED Jacobian): with
// w = log3(R_d R^T) and d = p_d - p, e_w = w and e_p = a d - w x d / 2 + b (w.d) w, where
// a = (t / 2) / tan(t / 2), b = (1 - a) / t^2, t = |w| (the SE(3) logarithm's V^-1).
void pose_error(const Array& rotation_t, const double* p, const Array& target, double* e) {
  using Rows3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  using Rows4 = Eigen::Matrix<double, 4, 4, Eigen::RowMajor>;
  Eigen::Map<const Rows3> Rt(rotation_t.data());  // (shapes checked by PoseCall)
  Eigen::Map<const Rows4> Md(target.data());
  Matrix3 error = Md.topLeftCorner<3, 3>() * Rt;
  Vector3 w = log3(error);
  Vector3 d = Md.block<3, 1>(0, 3) - Vector3(p[0], p[1], p[2]);
  double t2 = w.squaredNorm(), t = std::sqrt(t2), a, b;
  if (t < 1e-3) {
    a = 1.0 - t2 / 12.0 - t2 * t2 / 720.0;
    b = 1.0 / 12.0 + t2 / 720.0;
  } else {
    a = 0.5 * t / std::tan(0.5 * t);
    b = (1.0 - a) / t2;
  }
  Vector3 linear = a * d - 0.5 * w.cross(d) + (b * w.dot(d)) * w;
  for (Index i = 0; i < 3; ++i) {
    e[i] = linear[i];
    e[3 + i] = w[i];
  }
}

// The joints' table (3 x k, int64: q index, v index, kind): kind 0 one coordinate (revolute,
// prismatic), kind 1 a continuous joint's (cos, sin) pair; every column within q and the
// velocity, or ValueError.
void check_joints(const IndexArray& joints, Index nq, Index n) {
  if (joints.rows() != 3) joints.shape(3, joints.cols());
  for (Index k = 0; k < joints.cols(); ++k) {
    std::int64_t qi = joints(0, k), vi = joints(1, k), kind = joints(2, k);
    if ((kind != 0 && kind != 1) || qi < 0 || qi + 1 + kind > nq || vi < 0 || vi >= n) {
      std::ostringstream out;
      out << "joints: column " << k << " (" << qi << ", " << vi << ", " << kind
          << ") is no joint of q (" << nq << ",) and the velocity (" << n
          << ",): q index, v index, kind 0 or 1";
      fail(out.str());
    }
  }
}

// q = q_cur (+) step, Pinocchio's integrate on the joints of the table: kind 0 adds, kind 1
// turns a (cos, sin) pair by the angle and renormalises it to first order
void integrate(const Vector& current, const Vector& step, const IndexArray& joints, double* q) {
  std::memmove(q, current.data(), sizeof(double) * static_cast<size_t>(current.size()));
  for (Index r = 0; r < joints.cols(); ++r) {
    Index qi = joints(0, r), vi = joints(1, r);
    if (joints(2, r) == 0) {
      q[qi] = current[qi] + step[vi];
      continue;
    }
    double ca = current[qi], sa = current[qi + 1], co = std::cos(step[vi]), si = std::sin(step[vi]);
    double c = co * ca - si * sa, s = si * ca + co * sa, scale = 0.5 * (3.0 - c * c - s * s);
    q[qi] = scale * c;
    q[qi + 1] = scale * s;
  }
}

// One search_pose call's arguments, checked
struct PoseCall {
  PyObject* jacobian;
  PyObject* arguments;
  Array rotation_t, translation, target;
  IndexArray joints;
  Array trial, error;

  PoseCall(const SetPointSearch& s, nb::handle jacobian_, nb::handle arguments_,
           nb::handle rotation_t_, nb::handle translation_, nb::handle target_, nb::handle joints_,
           nb::handle trial_, nb::handle error_)
      : jacobian(jacobian_.ptr()),
        arguments(arguments_.ptr()),
        rotation_t(rotation_t_, "rotation_t", 2),
        translation(translation_, "translation", 1),
        target(target_, "target", 2),
        joints(joints_, "joints", 2),
        trial(trial_, "trial", 1, Access::write),
        error(error_, "error", 1, Access::write) {
    if (!PyCallable_Check(jacobian) || !PyTuple_Check(arguments))
      throw nb::type_error("jacobian must be callable and arguments a tuple");
    if (s.m != 6) fail("search_pose takes a search of 6 rows (one pose task)");
    rotation_t.shape(3, 3);
    translation.length(3);
    target.shape(4, 4);
    check_joints(joints, s.nq, s.n);
    trial.length(s.nq);
    error.length(6);
  }

  // The rows of jacobian(*arguments): (6, n), or (6,) for a robot of one joint (Pinocchio's
  // Jacobian of one column); `holder` keeps them alive
  const double* rows(nb::object& holder, Index n) const {
    holder = nb::steal(PyObject_Call(jacobian, arguments, nullptr));
    if (!holder.is_valid()) throw nb::python_error();
    if (n == 1 && ndim_of(holder) == 1) {
      Array J(holder, "the Jacobian", 1);
      J.length(6);
      return J.data();
    }
    Array J(holder, "the Jacobian", 2);
    J.shape(6, n);
    return J.data();
  }
};

// Up to `count` iterations of a start from `trial` (its state already reset): (status,
// iterations)
std::pair<int, long> run(SetPointSearch& s, PoseCall& call, long count) {
  int status = kContinue;
  long done = 0;
  while (done < count) {
    nb::object holder;
    const double* J = call.rows(holder, s.n);
    pose_error(call.rotation_t, call.translation.data(), call.target, call.error.data());
    status = s.iterate(J, call.error.data(), call.trial.data());
    ++done;
    if (status != kContinue) break;
    integrate(s.q(), s.step(), call.joints, call.trial.data());
  }
  return {status, done};
}

// The table's starts in one call: up to `starts` starts, each from the configuration whose
// distance is the smallest left (then marked used: +inf), with the quick stall test, of at
// most min(max_iters, iterations left of `count`) iterations, until one converges, the
// iterations run out, or a start ends with a non-finite error (for Python to report). best
// (|e| of the best start so far) and best_q follow every start whose |e| is below it.
nb::tuple table(SetPointSearch& s, PoseCall& call, long count, nb::handle configurations_,
                nb::handle distance_, nb::handle best_q_, long starts, long max_iters,
                double best) {
  Array configurations(configurations_, "configurations", 2);
  Array distance(distance_, "distance", 1, Access::write);
  Array best_q(best_q_, "best_q", 1, Access::write);
  Index size = configurations.rows();
  if (size < 1 || configurations.cols() != s.nq || distance.size() != size ||
      best_q.size() != s.nq) {
    std::ostringstream out;
    out << "the table's arrays do not fit: configurations must be (k, nq = " << s.nq
        << ") with k >= 1, distance (k,) and best_q (nq,); got " << configurations.rows() << " x "
        << configurations.cols() << ", " << distance.size() << " and " << best_q.size();
    fail(out.str());
  }
  double* d = distance.data();
  int status = kContinue;
  long used = 0, made = 0;
  while (made < starts && used < count) {
    Index nearest = 0;
    for (Index i = 1; i < size; ++i)
      if (d[i] < d[nearest]) nearest = i;
    d[nearest] = std::numeric_limits<double>::infinity();
    std::memmove(call.trial.data(), configurations.data() + nearest * s.nq,
                 sizeof(double) * static_cast<size_t>(s.nq));
    s.start(true);
    auto [last, done] = run(s, call, count - used < max_iters ? count - used : max_iters);
    status = last;
    used += done;
    ++made;
    double error = std::sqrt(s.state.e_sq);
    if (!std::isfinite(error)) break;
    if (error < best) {
      best = error;
      std::memmove(best_q.data(), s.q().data(), sizeof(double) * static_cast<size_t>(s.nq));
    }
    if (status == kConverged) break;
  }
  return nb::make_tuple(status, used, made, best);
}

}  // namespace

void register_search_pose(nb::module_& m) {
  m.def(
      "search_pose",
      [](SetPointSearch& s, nb::handle jacobian, nb::handle arguments, nb::handle rotation_t,
         nb::handle translation, nb::handle target, nb::handle joints, nb::handle trial,
         nb::handle error, long count) {
        PoseCall call(s, jacobian, arguments, rotation_t, translation, target, joints, trial,
                      error);
        auto [status, done] = run(s, call, count);
        return nb::make_tuple(status, done);
      },
      nb::arg("search"), nb::arg("jacobian").none(), nb::arg("arguments").none(),
      nb::arg("rotation_t").none(), nb::arg("translation").none(), nb::arg("target").none(),
      nb::arg("joints").none(), nb::arg("trial").none(), nb::arg("error").none(), nb::arg("count"),
      "search_pose(search, jacobian, arguments, rotation_t, translation, target, joints, "
      "trial, error, count) -> (status, iterations): up to count iterations of a start of "
      "search (a SetPointSearch of one pose task, its state reset) from trial (nq,), each "
      "calling jacobian(*arguments) once for the frame's rows (6, n), LOCAL_WORLD_ALIGNED, "
      "which updates the frame's placement: rotation_t (R^T, 3 x 3) and translation (3,); "
      "the error log6 to target (4 x 4) in world axes into error (6,); the step integrated on "
      "joints (int64, 3 x k: q index, v index, kind 0 one coordinate, 1 a (cos, sin) pair).");
  m.def(
      "search_table",
      [](SetPointSearch& s, nb::handle jacobian, nb::handle arguments, nb::handle rotation_t,
         nb::handle translation, nb::handle target, nb::handle joints, nb::handle trial,
         nb::handle error, long count, nb::handle configurations, nb::handle distance,
         nb::handle best_q, long starts, long max_iters, double best) {
        PoseCall call(s, jacobian, arguments, rotation_t, translation, target, joints, trial,
                      error);
        return table(s, call, count, configurations, distance, best_q, starts, max_iters, best);
      },
      nb::arg("search"), nb::arg("jacobian").none(), nb::arg("arguments").none(),
      nb::arg("rotation_t").none(), nb::arg("translation").none(), nb::arg("target").none(),
      nb::arg("joints").none(), nb::arg("trial").none(), nb::arg("error").none(), nb::arg("count"),
      nb::arg("configurations").none(), nb::arg("distance").none(), nb::arg("best_q").none(),
      nb::arg("starts"), nb::arg("max_iters"), nb::arg("best"),
      "search_table(search, ... as search_pose ..., count, configurations, distance, best_q, "
      "starts, max_iters, best) -> (status, iterations, starts made, best |e|): the restart "
      "table's starts (sjt_pin.restarts.NearStarts: configurations (k, nq), distance (k,), "
      "used ones marked +inf) nearest first, each of at most max_iters iterations, count in "
      "all, until one converges; best_q follows every start whose |e| is below best.");
}

}  // namespace sjt
