// The Python side of the controller (controller.hpp): sjt_pin.kernels.Controller, its typed
// parameters (MethodParameters) and its state and results as named numpy views.
#include <nanobind/eigen/dense.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <array>
#include <optional>
#include <string>

#include "controller.hpp"
#include "registry.hpp"

namespace sjt {

namespace {

using ReadView = nb::ndarray<nb::numpy, const double, nb::ndim<1>>;
using WriteView = nb::ndarray<nb::numpy, double, nb::ndim<1>>;
using CodeView = nb::ndarray<nb::numpy, const int8_t, nb::ndim<1>>;
using WarmTuple = std::tuple<Vector, std::vector<int>, Index, Index, Index>;

template <class View, class T>
View view(Controller& c, T* data, Index n) {
  size_t shape[1] = {static_cast<size_t>(n)};
  return View(data, 1, shape, nb::find(&c));
}

// an optional checked array of n entries (None: null), held in `storage`
const double* optional(nb::handle object, const char* name, Index n, std::optional<Array>& storage) {
  if (object.is_none()) return nullptr;
  storage.emplace(object, name, 1);
  storage->length(n);
  return storage->data();
}

// run()'s `matrix`: a user method's M (nv x r0) of the first level's weighted rows, row-major.
// `matrix` is M (a float64 array of C or Fortran order, as the boundary takes arrays), or the
// method's function, called here with those rows (a new (r0, nv) array, first_rows): this
// call is then the door for what the user's function returns, and takes it as the solver
// always has, a float64 array of C or Fortran order (J.T) as it is and anything else through
// numpy.ascontiguousarray(M, dtype=float) (a list, float32). Its shape and that it is finite
// are checked (ValueError naming it); Fortran order is copied into the controller's row-major
// buffer. `keep` and `storage` hold what the returned pointer reads.
const double* user_matrix(Controller& c, const Array& J, const Array& e, nb::handle matrix,
                          nb::object& keep, std::optional<Array>& storage) {
  keep = nb::borrow(matrix);
  if (PyCallable_Check(matrix.ptr())) {
    NewArray rows = new_array(c.levels[0].end - c.levels[0].begin, c.nv);
    c.first_rows(J.matrix(), e.vector(), rows.data);
    keep = matrix(rows.array);
    if (!plain_array(keep, 2, Order::any)) {
      const bool array = ndim_of(keep) >= 0;
      const std::string type = nb::type_name(keep.type()).c_str();
      try {
        keep = nb::module_::import_("numpy").attr("ascontiguousarray")(
            keep, nb::arg("dtype") = nb::handle(reinterpret_cast<PyObject*>(&PyFloat_Type)));
      } catch (nb::python_error& error) {
        nb::raise_from(error, PyExc_TypeError,
                       "the method's matrix M(J) must be a 2-D array of floats, got %s",
                       type.c_str());
      }
      if (!array && ndim_of(keep) != 2)  // (an array's own shape is named below)
        throw nb::type_error(("the method's matrix M(J) must be a 2-D array of floats, got " +
                              type).c_str());
    }
  }
  storage.emplace(keep, "the method's matrix M(J)", 2, Access::read, Order::any);
  storage->shape(c.nv, c.levels[0].end - c.levels[0].begin);
  storage->finite();
  if (storage->row_major()) return storage->data();
  c.user_matrix = storage->strided();  // (the same size: no allocation)
  return c.user_matrix.data();
}

Controller make(const MethodParameters& method, Index rows, Index nv, Index nq, double dt,
                const Vector& sqrt_weight, const Vector& gains, const Vector& moving,
                Index error_rows, const std::vector<std::tuple<Index, Index, bool, Index>>& levels,
                const Vector& speed, const Eigen::Matrix<int64_t, Eigen::Dynamic, 1>& range_q,
                const Eigen::Matrix<int64_t, Eigen::Dynamic, 1>& range_v, const Vector& lower,
                const Vector& upper, const Vector& recovery, nb::object acceleration,
                nb::object jerk, double stall_ratio, double stall_floor,
                const Vector& rank_scale) {
  if (!(dt > 0.0) || !std::isfinite(dt)) fail("dt must be a finite number > 0 (s)");
  if (nv <= 0 || rows < 0 || nq < nv) fail("rows, nv and nq do not fit");
  std::vector<Level> ls;
  for (const auto& [begin, end, identity, targets] : levels) ls.push_back(Level{begin, end, identity, targets});
  BoundsConfig bounds;
  bounds.nv = nv;
  bounds.speed = speed;
  bounds.moving = moving;
  const Index count = range_q.size();
  if (range_v.size() != count || lower.size() != count || upper.size() != count ||
      recovery.size() != count)
    fail("the position ranges' arrays must have one length");
  for (Index k = 0; k < count; ++k)
    bounds.ranges.push_back(PositionRange{range_q[k], range_v[k], lower[k], upper[k], recovery[k]});
  if (!acceleration.is_none()) {
    bounds.smooth = true;
    bounds.acceleration = nb::cast<Vector>(acceleration);
    bounds.jerk = jerk.is_none() ? Vector::Constant(nv, std::numeric_limits<double>::infinity())
                                 : nb::cast<Vector>(jerk);
  }
  return Controller(method, rows, nv, nq, dt, sqrt_weight, gains, moving, error_rows, ls, bounds,
                    stall_ratio, stall_floor, rank_scale);
}

}  // namespace

void register_controller(nb::module_& m) {
  nb::enum_<Family>(m, "Family", "The CLIK mappings' two families.")
      .value("transpose", Family::transpose, "JT (eq. 10) and SJT (eq. 21), and their damped forms")
      .value("least_squares", Family::least_squares, "JP (eq. 8) and DLS");

  nb::class_<MethodParameters>(m, "MethodParameters",
                               "A method's parameters, by name (see sjt_pin.methods).")
      .def(nb::init<>())
      .def_rw("family", &MethodParameters::family)
      .def_rw("scaled", &MethodParameters::scaled, "SJT's column scaling D (False: JT)")
      .def_rw("damped_feedback", &MethodParameters::damped_feedback)
      .def_rw("damped_feedforward", &MethodParameters::damped_feedforward)
      .def_rw("mu", &MethodParameters::mu, "mu of the damped solve; DLS's lambda (task units)")
      .def_rw("column_tol", &MethodParameters::column_tol, "task units^2")
      .def_rw("length2", &MethodParameters::length2, "SJT's floor l^2 (task units^2)")
      .def_rw("lm", &MethodParameters::lm, "the Levenberg-Marquardt weight")
      .def_rw("rcond", &MethodParameters::rcond)
      .def_rw("auto_gain", &MethodParameters::auto_gain)
      .def_rw("gain_factor", &MethodParameters::gain_factor);

  nb::class_<Controller>(m, "Controller",
                         "One CLIK step after the tasks: method, priority levels, limits, "
                         "projection (sjt_pin/kernels/src/controller.hpp).")
      .def(nb::new_(&make), nb::arg("method"), nb::arg("rows"), nb::arg("nv"), nb::arg("nq"),
           nb::arg("dt"), nb::arg("sqrt_weight"), nb::arg("gains"), nb::arg("moving"),
           nb::arg("error_rows"), nb::arg("levels"), nb::arg("speed"), nb::arg("range_q"),
           nb::arg("range_v"), nb::arg("lower"), nb::arg("upper"), nb::arg("recovery"),
           nb::arg("acceleration").none(), nb::arg("jerk").none(), nb::arg("stall_ratio"),
           nb::arg("stall_floor"), nb::arg("rank_scale"))
      .def(
          "run",
          [](Controller& c, nb::handle J, nb::handle e, nb::handle ff, nb::handle q,
             nb::handle step, nb::handle matrix, nb::handle lower,
             nb::handle upper, nb::handle A, nb::handle b, nb::handle room,
             nb::handle needs, nb::handle dampers) -> int {
            Array Ja(J, "J", 2), ea(e, "e", 1), qa(q, "q", 1), sa(step, "step", 1, Access::write);
            Ja.shape(c.m, c.nv);
            ea.length(c.m);
            qa.length(c.nq);
            sa.length(c.nv);
            std::optional<Array> s1, s2, s3, s4;
            const double* ffp = optional(ff, "ff", c.m, s1);
            const double* mp = nullptr;
            nb::object given;
            if (!matrix.is_none()) mp = user_matrix(c, Ja, ea, matrix, given, s2);
            const double* lo = optional(lower, "lower", c.nv, s3);
            const double* hi = optional(upper, "upper", c.nv, s4);
            if ((lo == nullptr) != (hi == nullptr)) fail("lower and upper come together");
            if (lo) {
              for (Index j = 0; j < c.nv; ++j)
                if (std::isnan(lo[j]) || std::isnan(hi[j]))
                  fail("a limit's bounds contain NaN (inf: no bound)");
            }
            if (A.is_none() != b.is_none()) fail("A and b come together");
            if (!A.is_none()) {
              Array Aa(A, "A", 2), ba(b, "b", 1);
              Aa.shape(ba.size(), c.nv);
              Aa.finite();
              ba.no_nan();
              std::optional<Array> s5, s6, s7;
              const double* rp = optional(room, "room", ba.size(), s5);
              const double* np = optional(needs, "needs", ba.size(), s6);
              const double* dp = optional(dampers, "dampers", ba.size(), s7);
              return c.run(Ja.matrix(), ea.vector(), ffp, qa.data(), sa.vector(), mp, lo,
                           hi, Aa.matrix(), ba.vector(), rp, np, dp);
            }
            if (!room.is_none() || !needs.is_none() || !dampers.is_none())
              fail("room, needs and dampers come with rows A and b");
            RowMatrix none(0, c.nv);
            Vector nob(0);
            return c.run(Ja.matrix(), ea.vector(), ffp, qa.data(), sa.vector(), mp, lo, hi,
                         none, nob);
          },
          nb::arg("J"), nb::arg("e"), nb::arg("ff").none(), nb::arg("q"), nb::arg("step"),
          nb::arg("matrix").none(), nb::arg("lower").none(),
          nb::arg("upper").none(), nb::arg("A").none(), nb::arg("b").none(),
          nb::arg("room").none() = nb::none(), nb::arg("needs").none() = nb::none(),
          nb::arg("dampers").none() = nb::none(),
          "run(J, e, ff, q, step, matrix, lower, upper, A, b, room=None, needs=None, "
          "dampers=None) -> "
          "status: one step (matrix: a user method's M(J) of the first level's weighted rows, "
          "or its function of those rows, called with a new array of them; room: the "
          "displacement each row allows, A d <= room, NaN where a row bounds velocity only; "
          "needs: NaN where a row's bound is what its limit needs, else the row is given up "
          "and kept only within the acceleration and jerk limits; dampers: 1 where a row's "
          "bound is its limit's damper of its room, 0 where the stage braked it (its bound "
          "says nothing of the room), None: 1 for every row); None for what a step does not "
          "have.")
      .def("set_dt", &Controller::set_dt)
      .def("set_gains", &Controller::set_gains, nb::arg("gains"), nb::arg("auto_gain"),
           nb::arg("factor"))
      .def("set_speed", &Controller::set_speed, nb::arg("speed"))
      .def("set_log6_rows", &Controller::set_log6_rows, nb::arg("rows"),
           "the first rows of the first level's pose errors (log6, 6 target rows each), whose "
           "exact rows Jlog6 J the step takes from a rest at a position range short of the "
           "target")
      .def("reset", &Controller::reset)
      .def_prop_ro("dt", &Controller::dt)
      .def_prop_ro("dq", [](Controller& c) { return view<WriteView>(c, c.dq.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("ddq", [](Controller& c) { return view<WriteView>(c, c.ddq.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("escape_velocity",
                   [](Controller& c) { return view<WriteView>(c, c.escape_velocity.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_rw("escaping", &Controller::escaping)
      .def_rw("stall_run", &Controller::stall_run)
      .def_rw("stall_wait", &Controller::stall_wait)
      .def_rw("resting", &Controller::resting)
      .def_rw("start_error", &Controller::start_error)
      .def_rw("start_run", &Controller::start_run)
      .def_rw("least_e_sq", &Controller::least_e_sq)
      .def_rw("least_age", &Controller::least_age)
      .def_rw("pushed", &Controller::pushed)
      .def_rw("damped_error", &Controller::damped_error)
      .def_rw("damping_raises", &Controller::damping_raises)
      .def_rw("goal_damping", &Controller::goal_damping)
      .def_rw("rest_rank", &Controller::rest_rank)
      .def_prop_ro("rest_keep",
                   [](Controller& c) { return view<WriteView>(c, c.rest_keep.data(), c.nv * c.nv); },
                   nb::rv_policy::reference_internal)
      .def_rw("exact", &Controller::exact)
      .def_rw("still", &Controller::still)
      .def_prop_ro("expected",
                   [](Controller& c) { return view<WriteView>(c, c.expected.data(), c.expected.size()); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("exact_step", [](Controller& c) { return c.exact_step; })
      .def_prop_ro("desired", [](Controller& c) { return view<ReadView>(c, c.desired.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("desired_top",
                   [](Controller& c) { return view<ReadView>(c, c.desired_top.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("stall_floor_sq", [](Controller& c) { return c.stall_floor; })
      .def_prop_ro("feedback", [](Controller& c) { return view<ReadView>(c, c.fb.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("feedforward", [](Controller& c) { return view<ReadView>(c, c.ff.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("velocity", [](Controller& c) { return view<ReadView>(c, c.velocity.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("holding", [](Controller& c) { return view<ReadView>(c, c.holding.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("alpha", [](Controller& c) { return view<ReadView>(c, c.top.alpha.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("lower", [](Controller& c) { return view<ReadView>(c, c.box.lo.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("upper", [](Controller& c) { return view<ReadView>(c, c.box.hi.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("lower_by", [](Controller& c) { return view<CodeView>(c, c.box.lo_by.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("upper_by", [](Controller& c) { return view<CodeView>(c, c.box.hi_by.data(), c.nv); },
                   nb::rv_policy::reference_internal)
      .def_prop_ro("torn", [](Controller& c) {
             return nb::ndarray<nb::numpy, const uint8_t, nb::ndim<1>>(
                 c.box.torn.data(), 1, std::array<size_t, 1>{static_cast<size_t>(c.nv)}.data(),
                 nb::find(&c));
           }, nb::rv_policy::reference_internal)
      .def_prop_ro("rows_active", [](Controller& c) { return c.rows_active; })
      .def_prop_ro("e_sq", [](Controller& c) { return c.e_sq; })
      .def_prop_ro("ew_sq", [](Controller& c) { return c.top.ew_sq; })
      .def_prop_ro("ff_sq", [](Controller& c) { return c.ff_sq; })
      .def_prop_ro("gain", [](Controller& c) { return c.top.gain; })
      .def_prop_ro("loop_bound", [](Controller& c) { return c.top.loop_bound; })
      .def_prop_ro("stall", [](Controller& c) { return c.top.stall; })
      .def_prop_ro("trace", [](Controller& c) { return c.top.trace; })
      .def_prop_ro("regular", [](Controller& c) { return c.regular; })
      .def_prop_ro("task_scale", [](Controller& c) { return c.task_scale; })
      .def_prop_ro("posture_share", [](Controller& c) { return c.posture_share; })
      .def_prop_ro("kept", [](Controller& c) { return c.kept; })
      .def_prop_rw(
          "warm_state",
          [](Controller& c) {
            const Projection::WarmState w = c.nearest.warm_state();
            return WarmTuple(w.y, w.working, w.n, w.r, w.c);
          },
          [](Controller& c, const WarmTuple& state) {
            const auto& [y, working, n, r, rows_c] = state;
            // (n < 0: none, the next solve starts cold; else this controller's joints, a
            // finite dual point of r + c entries, distinct row indices >= 0)
            std::vector<int> rows = working;
            std::sort(rows.begin(), rows.end());
            const bool fits =
                n < 0 || (n == c.nv && r >= 0 && rows_c >= 0 && y.size() == r + rows_c &&
                          y.allFinite() && (rows.empty() || rows.front() >= 0) &&
                          std::adjacent_find(rows.begin(), rows.end()) == rows.end());
            if (!fits) fail("warm_state: the projection's state does not fit this controller");
            c.nearest.set_warm_state(Projection::WarmState{y, working, n, r, rows_c});
          },
          "The first level's projection's warm start (dual point, working rows, shape), which "
          "copies carry.")
      .def_prop_rw(
          "curvature_memory", [](Controller& c) { return c.curvature_memory(); },
          [](Controller& c, const std::tuple<bool, Vector>& state) {
            const auto& [ready, bent] = state;
            if (!bent.allFinite()) fail("curvature_memory: a finite vector");
            c.set_curvature_memory(ready, bent);
          },
          "The last step's task motion J0 dq and whether there is one (the curvature the next "
          "step measures), which copies carry.")
      .def_prop_ro("iterations", [](Controller& c) { return c.report.iterations; })
      .def_prop_ro("converged", [](Controller& c) { return c.report.converged; });
}

}  // namespace sjt
