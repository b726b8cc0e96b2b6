// Braking beside acceleration limits (sjt_pin/limits/collision.py, "Acceleration limits"): the
// damper rows' bounds cut to closing speeds the arm can stop (stoppable_rows), and each pair's
// influence grown to the distance within which a row may have to start braking (braking_reach).
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include "array.hpp"
#include "braking.hpp"
#include "registry.hpp"

namespace sjt {

namespace {

// The closing speed v >= 0 a row can hold for tau and still brake to rest at a within the
// excess h (m): v tau + v^2 / (2 a) = |h|, signed as h (a row inside its margin separates)
double stoppable_speed(double h, double a, double tau) {
  double v = std::sqrt(a * tau * a * tau + 2.0 * a * std::fabs(h)) - a * tau;
  return h >= 0.0 ? v : -v;
}

// The arm's limits of a stoppable_rows or braking_reach call: per joint (N,), jerks optional
struct ArmLimits {
  Array accelerations;
  std::optional<Array> jerks;
};

ArmLimits arm_limits(nb::handle accelerations, nb::handle jerks, Index N, const char* who,
                     const char* accelerations_name = "accelerations",
                     const char* jerks_name = "jerks") {
  ArmLimits limits{Array(accelerations, accelerations_name, 1), std::nullopt};
  if (!jerks.is_none()) limits.jerks.emplace(jerks, jerks_name, 1);
  if (limits.accelerations.size() != N || (limits.jerks && limits.jerks->size() != N)) {
    std::ostringstream out;
    out << who << ": " << accelerations_name << " and " << jerks_name
        << " must hold one number per joint (" << N << "): they do not fit ("
        << accelerations_name << " " << limits.accelerations.size() << ")";
    fail(out.str());
  }
  return limits;
}

}  // namespace

void register_collision_braking(nb::module_& m) {
  m.def(
      "stoppable_rows",
      [](nb::handle A_obj, nb::handle b_obj, nb::handle dq_obj, nb::handle ddq_obj,
         nb::handle accelerations, nb::handle jerks, double rate, double dt, double share,
         double slack, nb::handle reach_accelerations, nb::handle reach_jerks,
         nb::handle carried_obj, nb::handle speeds_obj, nb::handle needs_obj,
         nb::handle room_obj) {
        if (!(rate > 0.0 && dt > 0.0 && share > 0.0 && share <= 1.0 && slack >= 0.0))
          fail("stoppable_rows: rate and dt must be > 0, share in (0, 1], slack >= 0");
        const Array A(A_obj, "A", 2);
        Array b(b_obj, "b", 1, Access::write);
        Array dq(dq_obj, "dq", 1);
        Array ddq(ddq_obj, "ddq", 1);
        const Index k = A.rows(), N = A.cols();
        if (b.size() != k || dq.size() != N || ddq.size() != N) {
          std::ostringstream out;
          out << "stoppable_rows: A (k, N), b (k,), dq, ddq, accelerations and jerks (N,) do "
              << "not fit: A (" << k << ", " << N << "), b (" << b.size() << ",), dq ("
              << dq.size() << ",), ddq (" << ddq.size() << ",)";
          fail(out.str());
        }
        std::optional<Array> carried, speeds, needs, room;
        if (!carried_obj.is_none()) carried.emplace(carried_obj, "carried", 1);
        if (!room_obj.is_none()) {
          if (!carried_obj.is_none() || !speeds_obj.is_none() || !needs_obj.is_none())
            fail("stoppable_rows: room (a user's rows) comes without carried, speeds and needs "
                 "(a collision limit's moving obstacles)");
          room.emplace(room_obj, "room", 1);
        }
        if (!speeds_obj.is_none()) speeds.emplace(speeds_obj, "speeds", 2);
        if (!needs_obj.is_none()) needs.emplace(needs_obj, "needs", 1, Access::write);
        if ((carried && carried->size() != k) || (needs && needs->size() != k) ||
            (room && room->size() != k) ||
            (speeds && (speeds->rows() != 2 || speeds->cols() != N))) {
          std::ostringstream out;
          out << "stoppable_rows: carried, needs and room must hold one number per row (" << k
              << ") and speeds (2, " << N << ") two per joint: they do not fit";
          fail(out.str());
        }
        ArmLimits limits = arm_limits(accelerations, jerks, N, "stoppable_rows");
        const bool jerk = limits.jerks.has_value();
        // the joints' own limits, which bound what this step can reach (the budget above may
        // be a share of them)
        std::optional<ArmLimits> own;
        if (!reach_accelerations.is_none() || !reach_jerks.is_none()) {
          const bool acc_own = !reach_accelerations.is_none();
          const bool jerk_own = !reach_jerks.is_none();
          own.emplace(arm_limits(acc_own ? reach_accelerations : accelerations,
                                 jerk_own ? reach_jerks : jerks, N, "stoppable_rows (reach)",
                                 acc_own ? "reach_accelerations" : "accelerations",
                                 jerk_own ? "reach_jerks" : "jerks"));
        }
        const ArmLimits& reach = own ? *own : limits;
        const bool boxes = jerk && reach.jerks.has_value();
        auto rows = A.matrix();
        const double* acc = limits.accelerations.data();
        const double* jl = jerk ? limits.jerks->data() : nullptr;
        const double* racc = reach.accelerations.data();
        const double* rjl = boxes ? reach.jerks->data() : nullptr;
        const double* v0 = dq.data();
        const double* a0 = ddq.data();
        const Array* vmax = speeds ? &*speeds : nullptr;  // (down, then up: row 0, row 1)
        auto bound = b.vector();
        for (Index i = 0; i < k; ++i) {
          // along row i the closing speed s changes at up to a (m/s^2), that rate at up to j;
          // within the joints' acceleration and jerk boxes this step, its acceleration lies
          // in [least, most]; the joints' speeds (speed limits, range braking) let it retreat
          // at up to retreat (m/s)
          double a = 0.0, j = 0.0, s = 0.0, sd = 0.0, least = 0.0, most = 0.0, retreat = 0.0;
          double lever_sq = 0.0;  // |A_i|^2
          double full = 0.0;  // s until every joint of the row brakes it at its limit
          double rise = 0.0;  // the row's largest acc_j / jerk_j (s)
          for (Index c = 0; c < N; ++c) {
            const double w = rows(i, c);
            if (w == 0.0) continue;
            lever_sq += w * w;
            a += std::fabs(w) * acc[c];
            if (jerk) {
              j += std::fabs(w) * jl[c];
              const double braking = w > 0.0 ? -a0[c] : a0[c];  // (its share of -A_i ddq)
              if (braking < acc[c]) full = std::max(full, (acc[c] - braking) / jl[c]);
              rise = std::max(rise, acc[c] / jl[c]);
            }
            if (vmax) retreat += std::fabs(w) * (*vmax)(w > 0.0 ? 0 : 1, c);
            s += w * v0[c];
            sd += w * a0[c];
            if (boxes) {
              // (an empty box, the limits having yielded last step, counts as its nearer end)
              const double lo = std::max(-racc[c], a0[c] - rjl[c] * dt);
              const double hi = std::min(racc[c], a0[c] + rjl[c] * dt);
              least += w > 0.0 ? w * std::min(lo, hi) : w * std::max(lo, hi);
              most += w > 0.0 ? w * std::max(lo, hi) : w * std::min(lo, hi);
            }
          }
          // the bound rises by what the pair's other side moves away (carried: an obstacle's
          // normal velocity; the row bounds the relative closing speed s + u, u = -carried)
          const double shift = carried ? carried->data()[i] : 0.0;
          if (needs) needs->data()[i] = std::numeric_limits<double>::quiet_NaN();
          // a row given its room (a user's: A d <= room_i) keeps its own bound, cut below it
          // only to what the arm can stop within that room; a row without room there (NaN,
          // inf) bounds velocity only and is left as it is
          const bool given = room.has_value();
          const double room_i = given ? room->data()[i] : 0.0;
          if (given && !std::isfinite(room_i)) continue;
          if (!(a > 0.0) || !std::isfinite(a)) {  // no joint moves it, or no limit
            bound[i] += shift;
            continue;
          }
          // The row's deceleration, each joint ramping its own to its limit at its jerk limit,
          // is sum_j |A_ij| min(acc_j, c_j + jerk_j t) from -A_i ddq = sum_j |A_ij| c_j: concave
          // in t, and a from `full` on, so above its chord, -A_i ddq + t (a + A_i ddq) / full.
          // Summed jerks (j_i) ramp faster than that where some joints already brake at their
          // limit (their jerk gives nothing) or speed the row up: the row's jerk is the chord's
          // where it is slower. (xArm7's wrist link, jerk limits 173 times the acceleration
          // limits, closed on a ring's hull at 180 mm/s and braked at half the rate the summed
          // jerks promised: it crossed the margin by 0.8 mm, and the limits yielded.)
          if (full > 0.0 && a + sd > 0.0) j = std::min(j, (a + sd) / full);
          const bool jerk_row = jerk && j > 0.0 && std::isfinite(j);
          // s to reach a at that jerk, at most the time each joint takes from its limit one
          // way to its limit the other (braking_reach's)
          const double ramp = jerk_row ? std::min(a / j, 2.0 * rise) : 0.0;
          const double damper = bound[i], h = given ? room_i : damper / rate;
          const double r0 = jerk_row ? std::max(-share * a, sd - share * j * dt) : -share * a;
          // nor faster than the joints' boxes let it drop this step (a joint at its
          // acceleration limit, or held by its jerk limit, gives less than its share)
          const double r = boxes && std::isfinite(least) ? std::max(r0, least) : r0;
          // a row at or inside its margin whose lever is too short to push its pair out
          // (damper_rows: kPushLever) keeps it from closing, from braking as fast as the share
          // of the limits lets it
          const bool held = !given && damper <= 0.0 && lever_sq < kPushLever * kPushLever;
          // the bound on the closing speed of the arm's side of a pair whose other side comes
          // at u: it is the arm's speed that brakes, the obstacle's stays (the relative
          // closing speed s + u)
          const auto cut = [&](double u) {
            const double s_rel = s + u;
            if (held) return std::max(s_rel + r * dt, 0.0) - u;
            double v = stoppable_speed(h, share * a, dt + ramp);
            // a bound above the closing speed lets the row speed up toward its margin, and
            // under a jerk limit that acceleration takes time to ramp out: the fastest
            // closing speed this step can reach is kept only if, from it and the acceleration
            // that reaching it takes, the pair braking at the share of the limits still
            // stops within h
            if (jerk_row && boxes && std::isfinite(most) && h >= 0.0 && v > s_rel) {
              const double top = std::min(v, s_rel + dt * most);
              if (top > s_rel) {
                const double x =
                    largest_stoppable(s_rel, top, s_rel, h, dt, share * a, share * j);
                if (x < top) v = x;
              }
            }
            double out = given ? v : h >= 0.0 ? std::min(damper, v) : std::max(damper, v);
            // ... as long as the pair, braking at the whole limits, stops margin - slack
            // apart: under a jerk limit from the acceleration this step's speed leaves (x -
            // s) / dt, ramped to a_i at j_i (largest_stoppable), not as if held for the whole
            // ramp a_i / j_i first (with a ramp of 20 ms, a pair closing at 95 mm/s 2 mm from
            // its margin and already braking could stop within 1.3 mm, the held model said
            // 2.1: the row asked more than the boxes give and the jerk limit yielded, 4.1
            // times); else the fastest speed from which it does (the margin wins)
            const double drop = s_rel + r * dt, held = stoppable_speed(h + slack, a, dt + ramp);
            out = std::max(out, jerk_row ? largest_stoppable(std::min(drop, held), drop, s_rel,
                                                             h + slack, dt, a, j)
                                         : std::min(drop, held));
            // inside the margin (a start there): the pair separates as fast as the share of
            // the limits lets its closing speed drop, not at once
            if (h < 0.0) out = std::max(out, drop);
            return out - u;  // (the arm's closing speed)
          };
          const double u = -shift;
          if (given) {
            bound[i] = std::min(bound[i], cut(u));
          } else if (vmax && u > retreat) {
            // outrun: the obstacle comes faster than the arm can retreat along the row within
            // its speed limits and ranges, so no yielding of the acceleration and jerk limits
            // holds the margin: its approach counts up to that retreat, and needs says what the
            // margin would need (below the bound: the stage keeps the row within those limits)
            bound[i] = cut(retreat);
            if (needs) needs->data()[i] = cut(u);
          } else {
            bound[i] = cut(u);
          }
        }
      },
      nb::arg("A"), nb::arg("b"), nb::arg("dq"), nb::arg("ddq"), nb::arg("accelerations"),
      nb::arg("jerks").none(), nb::arg("rate"), nb::arg("dt"), nb::arg("share"),
      nb::arg("slack"), nb::arg("reach_accelerations").none() = nb::none(),
      nb::arg("reach_jerks").none() = nb::none(), nb::arg("carried").none() = nb::none(),
      nb::arg("speeds").none() = nb::none(), nb::arg("needs").none() = nb::none(),
      nb::arg("room").none() = nb::none(),
      "stoppable_rows(A, b, dq, ddq, accelerations, jerks, rate, dt, share, slack,\n"
      "reach_accelerations=None, reach_jerks=None, carried=None, speeds=None, needs=None,\n"
      "room=None):\n"
      "the damper rows' bounds (in place) made ones an arm with acceleration (and jerk) limits\n"
      "can keep. Along row i the closing speed s_i = A_i q_dot changes at up to a_i = sum_j\n"
      "|A_ij| accelerations_j (m/s^2), and that rate at up to j_i = sum_j |A_ij| jerks_j (m/s^3;\n"
      "jerks None: no limit), or where slower the chord (a_i + A_i ddq) / T_i of the row's\n"
      "deceleration as each joint ramps its own from -sign(A_ij) ddq_j to its limit, the last\n"
      "one at T_i. With h = b_i / rate the row's excess over its margin (m; rate =\n"
      "gain / dt), in the relative closing speed c_i = s_i + u_i of a pair whose other side\n"
      "comes at u_i = -carried_i (m/s; carried None: 0), and the bound returned on s_i:\n"
      "  - b_i = min(b_i, v(h)) - u_i, v the closing speed that, held for tau = dt + min(a_i /\n"
      "    j_i, 2 max_j accelerations_j / jerks_j over the row's joints) and\n"
      "    then braked at a = share a_i (j = share j_i), covers h: v tau + v^2 / (2 a) = h (a\n"
      "    row inside its margin separates no faster than v(|h|)); with jerks, where v > c_i,\n"
      "    the fastest closing speed x this step can reach (its acceleration at most the row's\n"
      "    largest within the joints' boxes [max(-R, ddq - Rj dt), min(R, ddq + Rj dt)], R, Rj\n"
      "    the reach limits) must also stop within h from the acceleration (x - c_i) / dt that\n"
      "    reaching it takes: x dt + stopping_distance(x, (x - c_i) / dt, share a_i, share\n"
      "    j_i) <= h, else v = largest_stoppable(...);\n"
      "  - b_i = max(b_i, min(c_i + r dt, V(h + slack)) - u_i), r = max(-a, A_i ddq - j dt)\n"
      "    from the previous step's velocity dq and acceleration ddq, with jerks also at least\n"
      "    the row's least acceleration within the joints' boxes, V as v at the whole a_i (with\n"
      "    jerks: the largest x <= c_i + r dt whose stop from the acceleration (x - c_i) / dt at\n"
      "    the whole a_i and j_i fits, largest_stoppable, at least min(c_i + r dt, v(h + slack))\n"
      "    at the whole a_i): a row whose closing speed jumps asks it to drop no faster than\n"
      "    its share of the limits (and the boxes) allows, while its pair, braking at a_i,\n"
      "    stays at least margin - slack apart;\n"
      "  - b_i = max(b_i, c_i + r dt - u_i) inside the margin (h < 0): the pair separates as\n"
      "    fast as that share lets its closing speed drop; b_i = max(c_i + r dt, 0) - u_i at or\n"
      "    inside it (b_i <= 0) where |A_i| < PUSH_LEVER (damper_rows): the pair stops closing;\n"
      "  - outrun (speeds (2, N) given: how fast each joint can move down, then up; u_i >\n"
      "    sum_j |A_ij| speeds[A_ij > 0 ? 0 : 1, j], the fastest the row can retreat: no\n"
      "    retreat keeps the margin, whatever the acceleration and jerk limits give): the bound\n"
      "    as above with u_i cut to that retreat, and needs_i (needs (k,), if given; NaN for\n"
      "    every other row) the bound as above, below it: the row is given up, the stage keeps\n"
      "    it within the acceleration and jerk limits, never yielding them for it.\n"
      "The row's j_i and tau bound what its joints give, each at its own limits.\n"
      "room (k,), if given (without carried, speeds and needs): the rows are a user's, A d <=\n"
      "room_i for a displacement d (NaN, inf: a row of velocity only, left as it is):\n"
      "h = room_i (rate unused) and b_i = min(b_i, B_i), B_i the bound above for a damper\n"
      "without a bound of its own: the row's own bound is\n"
      "kept, cut below it only to closing speeds the arm can stop within room_i, never faster\n"
      "than the limits let it drop.\n"
      "reach_accelerations and reach_jerks (each None: accelerations, jerks) are the joints' own\n"
      "limits where the budget given is a share of them.\n"
      "A (k, N), b, carried, needs (k,), dq, ddq, accelerations, jerks and the reach limits\n"
      "(N,), speeds (2, N).");

  m.def(
      "braking_reach",
      [](nb::handle lever_obj, nb::handle dq_obj, nb::handle accelerations, nb::handle jerks,
         double dt, double share, double influence, double margin, nb::handle out_obj) {
        if (!(dt > 0.0 && share > 0.0 && share <= 1.0 && std::isfinite(influence) &&
              std::isfinite(margin)))
          fail("braking_reach: dt must be > 0, share in (0, 1], influence and margin finite");
        const Array lever(lever_obj, "lever", 2);
        Array dq(dq_obj, "dq", 1);
        Array out(out_obj, "out", 1, Access::write);
        const Index npairs = lever.rows(), N = lever.cols();
        if (dq.size() != N || out.size() != npairs) {
          std::ostringstream msg;
          msg << "braking_reach: lever (npairs, N), dq, accelerations, jerks (N,) and out "
              << "(npairs,) do not fit: lever (" << npairs << ", " << N << "), dq ("
              << dq.size() << ",), out (" << out.size() << ",)";
          fail(msg.str());
        }
        ArmLimits limits = arm_limits(accelerations, jerks, N, "braking_reach");
        const double* acc = limits.accelerations.data();
        const double* jerk = limits.jerks ? limits.jerks->data() : nullptr;
        double tau = dt;  // (and the ramp stoppable_rows holds the speed for: at most 2 a / j)
        for (Index j = 0; j < N; ++j)
          if (jerk && jerk[j] > 0.0 && std::isfinite(jerk[j]) && std::isfinite(acc[j]))
            tau = std::max(tau, dt + 2.0 * acc[j] / jerk[j]);
        auto L = lever.matrix();
        for (Index k = 0; k < npairs; ++k) {
          // s: the pair's closing speed bound after this step, T: the joints' time to stop
          double s = 0.0, T = 0.0;
          for (Index j = 0; j < N; ++j) {
            double l = L(k, j);
            if (!(l > 0.0) || !(acc[j] > 0.0) || !std::isfinite(acc[j])) continue;
            double w = std::fabs(dq.data()[j]) + acc[j] * dt;
            s += l * w;
            T = std::max(T, w / acc[j]);
          }
          out.data()[k] = std::max(influence, margin + s * (tau + T / (2.0 * share)));
        }
      },
      nb::arg("lever"), nb::arg("dq"), nb::arg("accelerations"), nb::arg("jerks").none(),
      nb::arg("dt"), nb::arg("share"), nb::arg("influence"), nb::arg("margin"), nb::arg("out"),
      "braking_reach(lever, dq, accelerations, jerks, dt, share, influence, margin, out): each\n"
      "pair's influence (m) for a step of an arm with acceleration (and jerk) limits: out_k =\n"
      "max(influence, margin + s_k (tau + T_k / (2 share))), the distance within which a damper\n"
      "row may have to start braking the pair. With w_j = |dq_j| + accelerations_j dt (a\n"
      "joint's speed after this step at most), s_k = sum_j lever_kj w_j bounds the pair's\n"
      "closing speed (lever (npairs, N): m per unit of q_dot_j), T_k = max_j w_j /\n"
      "accelerations_j over the joints that move it, tau = dt + 2 max_j accelerations_j /\n"
      "jerks_j (the longest ramp stoppable_rows holds a speed for; jerks None: dt).");
}

}  // namespace sjt
