// The Python side of the set-point search (search.hpp): sjt_pin.kernels.SetPointSearch, its
// parameters, the options of a solve, and its current point as read-only numpy views.
#include <cmath>

#include "registry.hpp"
#include "search.hpp"

namespace sjt {

void register_search(nb::module_& m) {
  m.attr("CONTINUE") = static_cast<int>(kContinue);
  m.attr("CONVERGED") = static_cast<int>(kConverged);
  m.attr("SEARCH_STALLED") = static_cast<int>(kSearchStalled);
  using S = SetPointSearch;
  nb::class_<S>(m, "SetPointSearch",
                "SetPointSearch(sqrt_weight, mask, nq, limit_q, limit_v, lower, upper, *, "
                "damping, column_tol, length, scaled, identity_rows): the set-point search of "
                "solve() (Levenberg-Marquardt on SJT's normalised columns within the joint "
                "limits): its parameters, the options of a solve, the state of a start and its "
                "current point (J, e, q: read-only views) and next step (step).")
      .def(nb::init<nb::handle, nb::handle, Index, nb::handle, nb::handle, nb::handle, nb::handle,
                    double, double, double, bool, Index>(),
           nb::arg("sqrt_weight").none(), nb::arg("mask").none(), nb::arg("nq"),
           nb::arg("limit_q").none(), nb::arg("limit_v").none(), nb::arg("lower").none(),
           nb::arg("upper").none(), nb::kw_only(), nb::arg("damping"), nb::arg("column_tol"),
           nb::arg("length") = 0.0, nb::arg("scaled") = false, nb::arg("identity_rows") = 0)
      .def_ro("m", &S::m)
      .def_ro("n", &S::n)
      .def_ro("nq", &S::nq)
      .def_ro("damping", &S::damping, "mu: the damping's floor mu^2 (task units)")
      .def_ro("column_tol", &S::column_tol, "columns of |W J_j|^2 at most this are left out")
      .def_ro("length", &S::length, "SJT's floor under the column norms (m)")
      .def_ro("scaled", &S::scaled, "whether the columns are scaled (SJT)")
      .def_ro("identity_rows", &S::identity_rows, "n when the rows end with a posture's")
      .def_rw("tol", &S::tol, "a start succeeds when |e| (target rows) is at most this")
      .def_rw("max_step", &S::max_step, "the largest joint motion of one iteration (rad, m)")
      .def_rw("error_rows", &S::error_rows, "the target rows (|e| is over these)")
      .def_rw("stale_iters", &S::stale_iters)
      .def_rw("progress", &S::progress)
      .def_rw("held_iters", &S::held_iters)
      .def_rw("held_progress", &S::held_progress)
      .def_rw("nu_start", &S::nu_start)
      .def_prop_ro(
          "f", [](const S& s) { return s.state.f; }, "|W e|^2 / 2 at the current point")
      .def_prop_ro("e_sq", [](const S& s) { return s.state.e_sq; })
      .def_prop_ro(
          "error", [](const S& s) { return std::sqrt(s.state.e_sq); },
          "|e| over the target rows at the current point")
      .def_prop_ro("nu", [](const S& s) { return s.state.nu; })
      .def_prop_ro("best", [](const S& s) { return s.state.best; })
      .def_prop_ro("held_best", [](const S& s) { return s.state.held_best; })
      .def_prop_ro("iterations", [](const S& s) { return s.state.iterations; })
      .def_prop_ro("stale", [](const S& s) { return s.state.stale; })
      .def_prop_ro("held_stale", [](const S& s) { return s.state.held_stale; })
      .def_prop_ro("rejected", [](const S& s) { return s.state.rejected; })
      .def_prop_ro("quick", [](const S& s) { return s.state.quick; })
      .def_prop_ro("J",
                   [](nb::handle self) {
                     S& s = nb::cast<S&>(self);
                     return numpy_view(s.J().data(), s.m, s.n, self, Access::read);
                   })
      .def_prop_ro("e",
                   [](nb::handle self) {
                     S& s = nb::cast<S&>(self);
                     return numpy_view(s.e().data(), s.m, -1, self, Access::read);
                   })
      .def_prop_ro("q",
                   [](nb::handle self) {
                     S& s = nb::cast<S&>(self);
                     return numpy_view(s.q().data(), s.nq, -1, self, Access::read);
                   })
      .def_prop_ro(
          "step",
          [](nb::handle self) {
            S& s = nb::cast<S&>(self);
            return numpy_view(s.step().data(), s.n, -1, self, Access::write);
          },
          "the next step from the current point (writable: a caller's limits correct it)")
      .def("start", &S::start, nb::arg("quick") = true,
           "start(quick=True): a new start's state (quick: with the quick stall test)")
      .def(
          "iterate",
          [](S& s, nb::handle J, nb::handle e, nb::handle q) {
            Array Ja(J, "J", 2), ea(e, "e", 1), qa(q, "q", 1);
            Ja.shape(s.m, s.n);
            ea.length(s.m);
            qa.length(s.nq);
            return s.iterate(Ja.data(), ea.data(), qa.data());
          },
          nb::arg("J").none(), nb::arg("e").none(), nb::arg("q").none(),
          "iterate(J, e, q) -> status: one iteration at the trial point q (its rows J (m, n) "
          "and error e (m,)): CONVERGED, SEARCH_STALLED, or CONTINUE with the next step in "
          "step.");
}

}  // namespace sjt
