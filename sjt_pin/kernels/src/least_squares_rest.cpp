// Where the arm rests (controller.hpp): the sufficient decrease of a projected step and its
// Cauchy point, the measured curvature, and the bounded least-squares goal beyond a position
// range (settling against a row: settle.cpp).
#include "controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sjt {

namespace {

// the projection keeps at least this share of the progress of the Cauchy point (the steepest
// feasible progress within a ball of the method's own step size)
constexpr double kSufficient = 0.25;
// 1/s: a step that lowers 1/2 |e_w|^2 by less than this share of |e_w|^2 per second makes no
// progress (StepInfo's STALL_RATE, sjt_pin.step_info)
constexpr double kStallRate = 1e-6;
// the share of a step's first-order decrease of 1/2 |e_w|^2 that the measured second-order
// term may take (trusted_share)
constexpr double kTrust = 0.5;
// range_goal's damping, relative to the first level's mean squared column norm: a floor, and
// a Levenberg-Marquardt term that grows with |e_w| (per task unit). Where a joint sits at its
// range the Gauss-Newton displacement overshoots in the flat valley of the constrained minimum
// (UR3 folded, shoulder lift and elbow at their ranges, 0.26 m beyond reach: the error's
// minimum along it at 0.1-0.25 of its length, 1.6-1.9 rad), and each joint brakes toward its
// own share at its own limits: a joint ten times quicker than the others ran ahead of them,
// uphill, and the arm swung at its speed limit for good. The larger the damping, the shorter
// the displacement and the nearer the gradient J0^T e_w, whose every share lowers the error by
// itself. Measured by `sjt-pin bench settle` (1,440 runs: nine arms, random starts with a
// quarter of the joints at their ranges, reachable targets, targets beyond reach and target
// streams, random per-joint acceleration and jerk limits, four methods), 0.5 against 3:
// swinging for good 36 -> 1 (Bravo 7, whose continuous joints have no speed limit), at rest at
// the end 1,292 -> 1,353, reachable targets reached 537 -> 538 of 972, the median time to
// rest 4.7 -> 5.2 s. On an earlier draw of the same kind 1, 2, 4 and 8 left 15, 3, 3 and 2
// runs swinging; with 8 the arms came to rest later still (a median 5.5 s against 5.0).
// Before, on 30 runs (UR5, Panda, UR10, KUKA iiwa and xArm6, DLS, jerk limits): still moving
// after 12 s in 6 runs with the floor alone (near a singularity the displacement's huge
// self-motion share sent the arm to and fro).
// Beside it, the curvature the last step measured along its own velocity (measured_bend): far
// beyond reach the error bends more than the Gauss-Newton model J0^T J0 says (a hand swung on
// a circle of radius r toward a point e beyond it: r^2 + r e against r^2), and where that is
// more than twice the model, each displacement passed the constrained minimum and the next one
// came back: 18 of 1,980 held-out survey runs (position tasks under acceleration limits,
// 0.1-1 m beyond reach) flipped a joint or two every step at 1e-5 to 2e-3 rad/s for good. With
// the measured curvature along the last step in the model (a secant update, rank one), 13 of
// the 18 rest (5 on their final target). Added to the damping on every direction instead it
// rested all 18, but slowed the motions it did not measure.
// Where a limit gives rows with room (a collision limit's pairs within range), the term stays
// 0.5: with 3, xArm7 behind an obstacle (blocked seed 1, SJT, acceleration limits) came to
// rest at 5.1 s, past the 5 s asked, and UR5 beside a ball driven at it at 0.5 m/s
// (acceleration and jerk limits) took 1.016 times its jerk limit
// (tests/test_collision_braking.py, tests/test_collision_moving.py).
constexpr double kGoalFloor = 1e-6;
constexpr double kGoalDamping = 3.0, kGoalDampingRows = 0.5;

}  // namespace

// The sufficient decrease of trust-region methods. The model is the linearised error after the
// step, m(v) = |a - J0 v|^2 dt^2, a = e_w / dt and the feed-forward (whatever the gains). Its
// Cauchy point (cauchy_point) is the model's first minimum along the projected steepest
// descent within a ball of the method's own step size. Where x0_ lowers the model by less than
// kSufficient of what that point does (the metric of the projection can weigh the joints that
// could carry the task heavily: a joint at its limit then froze the step), x0_ is blended
// toward it: the model is convex, so the step then lowers it by at least that share. A best
// decrease below a stalled step's (kStallRate) counts as none, and the Cauchy point is then 0:
// an x0_ that raises the model gives way to it, and the arm rests at its minimum against the
// limits (the decision no longer turns on whether that decrease rounds to 0 or to 1e-16 of
// |a|^2, which gave the same motion in mm and in m different steps). A Cauchy point that
// breaks a row or lets a held row go is not taken (the projection's own rows stand), nor is
// one where the box does not hold 0 (a joint returning into its range). The Cauchy point is
// cut by the measured curvature as a projected step is (trusted_share), and the decrease the
// stall rule judges is the cut point's. Before that, an x0_
// that lowers the model by less than a resting arm does (kRestRate) gives way to rest; H, hd:
// the held rows and their motion, which the rest keeps.
void Controller::sufficient_decrease(const Eigen::Ref<const RowMatrix>& J0,
                                     const Eigen::Ref<const RowMatrix>& A,
                                     const Eigen::Ref<const Vector>& b,
                                     const Eigen::Ref<const RowMatrix>& H,
                                     const Eigen::Ref<const Vector>& hd, double ball) {
  if (!(ball > 0.0)) return;
  for (Index j = 0; j < nv; ++j)
    if (plo_[j] > 0.0 || phi_[j] < 0.0) return;
  cauchy_point(J0, wanted_, plo_, phi_, ball);
  {
    // (the Cauchy point too, no further than its first-order decrease outweighs the
    // second-order term the last step measured: the model's minimum along the steepest
    // descent lies beyond the error's where the kinematics bend)
    tmp2_.noalias() = J0 * cauchy_;
    const double share = trusted_share(J0, wanted_.dot(tmp2_), tmp2_.squaredNorm(),
                                       cauchy_.squaredNorm());
    if (share < 1.0) cauchy_ *= share;
  }
  const double aa = wanted_.squaredNorm();
  res_ = wanted_;
  res_.noalias() -= J0 * cauchy_;
  double best = aa - res_.squaredNorm();
  if (best < 2.0 * kStallRate * dt_ * aa) {  // (the decrease of a stalled step: none)
    best = 0.0;
    cauchy_.setZero(nv);
  }
  // x0_ no further along its own direction than the model's minimum there, nor than its
  // first-order decrease outweighs the second-order term the last step measured
  tmp2_.noalias() = J0 * x0_;
  const double along = wanted_.dot(tmp2_), curvature = tmp2_.squaredNorm();
  const double share = std::min(along < curvature ? std::max(along, 0.0) / curvature : 1.0,
                                trusted_share(J0, along, curvature, x0_.squaredNorm()));
  if (share < 1.0) {
    xa_ = share * x0_;
    if (feasible(xa_, A, b, plo_, phi_) && held_kept(xa_)) {
      x0_ = xa_;
      tmp2_.noalias() = J0 * x0_;
    }
  }
  res_ = wanted_ - tmp2_;
  double progress = aa - res_.squaredNorm();
  // a step below a resting arm's progress (kRestRate) gives way to the least motion within
  // the limits (0 where 0 is feasible: a row the arm is inside of pushes it out), fully at
  // kRestRate and not at all at twice that, so that the velocity stays continuous in q. Under
  // acceleration limits only where 0 is feasible: each joint brakes toward the projection's
  // answer there, and toward the least motion that keeps the rows a ball driven at Panda's
  // hand at 0.5 m/s got close enough that the rows then took the arm past its acceleration
  // (1.08x) and jerk (1.17x) limits. Not while an escape (or a settling step) is added: its
  // test found the error lower along it, where the linearised model sees little progress
  // (TIAGo's arm 1 m beyond reach, the torso at its range: a settling step whose model
  // progress was 3e-8 of |e_w|^2 a step rested at once, 7e-7 of the error short of where the
  // arm was going), and it yields by itself if the error grows
  const double rest = 2.0 * kRestRate * dt_ * aa;
  if (progress < 2.0 * rest && !escaping) {
    rest_.setZero(nv);
    const bool still = feasible(rest_, A, b, plo_, phi_) && held_kept(rest_);
    if (still || !bounds.smooth) {
      if (!still) {
        xa_.setZero(nv);
        ProjectionReport r = projection_.solve(xa_, lam_low_, Bnone_, plo_, phi_, A, b, H, hd,
                                               rest_);
        report.iterations += r.iterations;
      }
      const double w = std::clamp(progress / rest - 1.0, 0.0, 1.0);
      holding = x0_;
      rested_ = true;
      x0_ = w * x0_ + (1.0 - w) * rest_;
      tmp2_.noalias() = J0 * x0_;
      res_ = wanted_ - tmp2_;
      progress = aa - res_.squaredNorm();
    }
  }
  if (!(best >= 0.0) || progress >= kSufficient * best) return;
  if (!feasible(cauchy_, A, b, plo_, phi_)) return;
  if (!held_kept(cauchy_)) return;
  const double w = progress > 0.0 ? progress / (kSufficient * best) : 0.0;
  x0_ = w * x0_ + (1.0 - w) * cauchy_;
}

// The share t in [0, 1] of a step x (a . J0 x = along, |J0 x|^2 = jj, |x|^2 = xx) whose
// first-order decrease of 1/2 |e_w|^2 is at least twice the second-order term the
// Gauss-Newton model leaves out, -1/2 e_w . d2x(x, x) dt^2 (the residual times the kinematics'
// curvature). The last step measured it along its own velocity u: (J0 - J0_last) u =
// d2x(u, u) dt to first order, and a step x is taken to bend as much per |x|^2. Far beyond
// reach, with a joint at its position range, the joints left free could move the hand only
// across the error, where that term is as large as the first-order decrease (xArm6 from
// pybullet's URDF and Panda, targets 1.5 m straight out from q0: SJT, JP and JT moved the
// hand at 0.3-1.3 m/s at the speed limits, turning back every step or two, for good; KUKA
// iiwa's JT at 10 rad/s). Only a projected step (the method's own stands), and only where the
// term raises the error:  2 t along - t^2 jj >= t^2 bend xx / kTrust.
double Controller::trusted_share(const Eigen::Ref<const RowMatrix>& J0, double along,
                                 double jj, double xx) {
  if (!projected_) return 1.0;
  const double bend = measured_bend(J0);
  if (!(bend > 0.0)) return 1.0;
  const double second = bend * xx / kTrust + jj;
  return second > 0.0 ? std::clamp(2.0 * along / second, 0.0, 1.0) : 1.0;
}

// The second-order term of 1/2 |e_w|^2 that the Gauss-Newton model leaves out, per |u|^2 along
// the last step's velocity u, -e_w . d2x(u, u) / |u|^2, measured as (J0 - J0_last) u = d2x(u, u)
// dt; 0 where there is no last step or the term lowers the error.
double Controller::measured_bend(const Eigen::Ref<const RowMatrix>& J0) {
  if (bend_ >= 0.0) return bend_;  // (measured once a step: run resets it)
  bend_ = 0.0;
  if (!bent_ready_) return bend_;
  const double uu = dq.squaredNorm();
  if (!(uu > 0.0) || bent_.size() != J0.rows()) return bend_;
  bent_now_.noalias() = J0 * dq;
  const double bend =
      -ew_.segment(levels[0].begin, J0.rows()).dot(bent_now_ - bent_) / (dt_ * uu);
  if (bend > 0.0) bend_ = bend;
  return bend_;
}

// Under acceleration limits each joint brakes so that it can stop at the displacement the
// first level's feedback asks of it (fb / K), and approaches the feedback's velocity. Where that
// displacement takes a joint past its position range, the others' shares of it assume a motion
// the range forbids: chasing them, the arm passed the constrained minimum of the error and
// turned back, again and again (held targets beyond a position range under jerk limits, 30
// runs on UR5, Panda, UR10, KUKA iiwa and xArm6: 24 still moved after 12 s, at up to
// 2.5 rad/s). There the first level's feedback is instead K times the damped least-squares
// displacement within the ranges (Levenberg-Marquardt with bounds),
//     min |J0 d - e_w|^2 + mu |d|^2   s.t.   lower - q <= d <= upper - q,
// solved as the point nearest its unconstrained minimiser in the metric mu I + J0^T J0, the
// rows weighted by their gains as in the method's feedback, the held rows (contacts) kept at
// the motion the method asks of them as equalities. At a constrained stationary point of the
// error it is 0, and every joint brakes to rest there. The lower levels are then computed on
// it. The general rows whose `room` is given (A d <= room: a collision pair's distance less its
// margin; NaN or inf: a row of velocity only) bound it too, and one the displacement breaks
// also calls for it: an arm whose target lies behind an obstacle slid along it under
// acceleration limits (16 of 18 blocked scenes on KUKA iiwa, xArm6 and UR3 still moved after
// 8 s; with the room, none). A row whose bound is its limit's damper of its room (`dampers`: a
// collision pair's) bounds it by min(room, b / K), what that bound lets the gain cover (with
// room alone, xArm7 slid along a table's margin at 2.5 rad/s, and its jerk limit yielded 8
// times); a row the stage braked itself (a user's, whose bound may be a speed cap) by its room
// alone: b / K, 0.1 mm for a floor approached at 0.1 m/s, or one step at the braked speed, sent
// the arm nowhere, and Panda, UR5 and Kinova never left their start 5 cm above two floors they
// were sent through (27 of 72 runs; with the room alone 2, and 64 rest on the floors).
// True: it replaced the feedback (its box holds 0: a joint outside its range returns by the
// position bounds; a row's room is at least 0: a pair inside its margin moves out by its
// velocity rows).
bool Controller::range_goal(const Eigen::Ref<const RowMatrix>& J0, const double* q, double K,
                            bool user, const Eigen::Ref<const RowMatrix>& A,
                            const Eigen::Ref<const Vector>& b, const double* room,
                            const double* dampers) {
  // (a joint outside its range counts only where the displacement takes it further out; a
  // row already broken, only where the displacement breaks it further)
  bool crosses = false;
  for (const PositionRange& r : bounds.ranges)
    crosses = crosses || (moving[r.v] != 0.0 && leaves_range(r, q[r.q], fb0_[r.v] / K));
  const Index k = room ? A.rows() : 0;
  // rows with room (a collision limit's pairs within range) bound the displacement, keep the
  // lighter damping and leave the measured curvature out (the last two said why where set)
  const bool rows_with_room = k > 0;
  goal_room_.resize(k);
  for (Index i = 0; i < k; ++i) {
    const double cap = dampers == nullptr || dampers[i] != 0.0 ? b[i] / K : kInf;
    goal_room_[i] = std::isfinite(room[i]) ? std::max(std::min(room[i], cap), 0.0) : kInf;
    if (!crosses && std::isfinite(goal_room_[i])) {
      const double closing = A.row(i).dot(fb0_) / K;
      crosses = closing > goal_room_[i];
    }
  }
  if (!crosses) return false;
  const Level& L0 = levels[0];
  const Index r0 = J0.rows(), targets = L0.targets, held = r0 - targets;
  // the rows' own gains weigh them as in the method's feedback (K e_w, over the mean gain)
  goal_e_ = ew_.segment(L0.begin, r0);
  if (!user) goal_e_.array() *= gains.segment(L0.begin, r0).array() * (top.gain / K);
  // (where rows with room bind it, times the factor a failed line raised: raise_damping)
  const double term = rows_with_room ? goal_damping * kGoalDampingRows : kGoalDamping;
  const double mu = (kGoalFloor + term * goal_e_.head(targets).norm()) *
                    std::max(J0.squaredNorm() / static_cast<double>(nv), 1e-300);
  // the curvature the last step measured along its own velocity u, as a row sqrt(bend) u^T / |u|
  // with no error of its own: the model's curvature along u is then the error's (a secant
  // update of the Gauss-Newton model along the last step). Not where a limit gives rows with
  // room (a collision limit's pairs within range): Panda driven fast past a ball (DLS,
  // acceleration and jerk limits) came within 9.25 mm of its 10 mm margin with it
  // (tests/test_collision_braking.py holds it to 9.9 mm)
  const double bend = rows_with_room ? 0.0 : measured_bend(J0);
  const Index extra = bend > 0.0 ? 1 : 0;
  goal_model_.resize(r0 + extra, nv);
  goal_model_.topRows(r0) = J0;
  goal_e_.conservativeResize(r0 + extra);
  if (extra) {
    goal_model_.row(r0) = (std::sqrt(bend) / dq.norm()) * dq.transpose();
    goal_e_[r0] = 0.0;
  }
  goal_gram_.noalias() = goal_model_ * goal_model_.transpose();
  goal_gram_.diagonal().array() += mu;
  goal_llt_.compute(goal_gram_);
  goal_y_ = goal_llt_.solve(goal_e_);
  goal_xb_.noalias() = goal_model_.transpose() * goal_y_;
  goal_lam_.resize(nv);
  for (Index j = 0; j < nv; ++j) goal_lam_[j] = moving[j] != 0.0 ? mu : kInf;
  range_box(q, goal_lo_, goal_hi_);
  // the held rows (contacts) keep the motion the method asks of them, as equalities
  const auto C = J0.middleRows(targets, held);
  goal_d_.noalias() = C * fb0_;
  goal_d_ /= K;
  goal_.resize(nv);
  const ProjectionReport report_goal =
      rows_with_room
          ? projection_.solve(goal_xb_, goal_lam_, goal_model_, goal_lo_, goal_hi_, A, goal_room_,
                              C, goal_d_, goal_)
          : projection_.solve(goal_xb_, goal_lam_, goal_model_, goal_lo_, goal_hi_, Bnone_,
                              goal_y_.head(0), C, goal_d_, goal_);
  if (!report_goal.converged || !goal_.allFinite()) return false;
  goal_rows_ = report_goal.rows_active > 0;
  goal_dampers_ = false;
  for (Index i = 0; goal_rows_ && i < k; ++i)
    goal_dampers_ = goal_dampers_ ||
                    ((dampers == nullptr || dampers[i] != 0.0) && std::isfinite(goal_room_[i]) &&
                     A.row(i).dot(goal_) >= goal_room_[i] - 1e-9 * (1.0 + goal_room_[i]));
  method_top_ = fb0_ + ff0_;
  fb0_ = K * goal_;
  return true;
}

// The generalized Cauchy point (Byrd, Lu, Nocedal and Zhu 1995, section 4) of |a - J0 v|^2
// within the box (lo, hi, which holds 0) and |v| <= ball: along v(s) = clip(s d, lo, hi),
// d = J0^T a, segment by segment between the joints' breakpoints (where each reaches its
// bound), the first minimum of the quadratic along v(s), or where v(s) leaves the ball. Into
// cauchy_.
void Controller::cauchy_point(const Eigen::Ref<const RowMatrix>& J0, const Vector& a,
                              const Vector& lo, const Vector& hi, double ball) {
  descent_.noalias() = J0.transpose() * a;
  const Vector& d = descent_;
  breaks_.clear();
  free_ = d;
  for (Index j = 0; j < nv; ++j) {
    const double bound = d[j] > 0.0 ? hi[j] : lo[j];
    const double t = d[j] != 0.0 ? bound / d[j] : kInf;
    if (!(t > 0.0)) free_[j] = 0.0;  // at its bound already (d_j = 0: t is inf, free_j is 0)
    else if (std::isfinite(t)) breaks_.emplace_back(t, j);
  }
  std::sort(breaks_.begin(), breaks_.end());
  cauchy_.setZero(nv);
  res_ = a;                         // a - J0 v
  jd_.noalias() = J0 * free_;       // J0 d_F
  double vv = 0.0, vd = 0.0, dd = free_.squaredNorm(), s = 0.0;
  const double rr = ball * ball;
  std::size_t k = 0;
  while (dd > 0.0) {
    const double next = k < breaks_.size() ? breaks_[k].first : kInf;
    const double jj = jd_.squaredNorm(), slope = res_.dot(jd_);
    if (!(slope > 0.0)) break;                      // the model no longer falls along the path
    double tau = jj > 0.0 ? slope / jj : kInf;      // the segment's minimum
    const double disc = vd * vd - dd * (vv - rr);   // where |v + tau d_F| = ball
    tau = std::min(tau, disc > 0.0 ? (std::sqrt(disc) - vd) / dd : 0.0);
    if (tau <= next - s) {
      cauchy_ += tau * free_;
      return;
    }
    const double step = next - s;                   // on to the breakpoint: its joint stops
    cauchy_ += step * free_;
    res_ -= step * jd_;
    s = next;
    for (; k < breaks_.size() && breaks_[k].first <= s; ++k) {
      const Index j = breaks_[k].second;
      cauchy_[j] = d[j] > 0.0 ? hi[j] : lo[j];
      jd_ -= free_[j] * J0.col(j);
      dd -= free_[j] * free_[j];
      free_[j] = 0.0;
    }
    if (k == breaks_.size()) return;  // every joint at its bound (the box is finite: capped)
    vv = cauchy_.squaredNorm();
    vd = cauchy_.dot(free_);
  }
}

// The box of displacements within the position ranges from q, lower - q <= d <= upper - q, widened
// to hold 0 (a joint outside its range returns by the position bounds); unbounded elsewhere.
void Controller::range_box(const double* q, Vector& lo, Vector& hi) const {
  lo.setConstant(nv, -kInf);
  hi.setConstant(nv, kInf);
  for (const PositionRange& r : bounds.ranges) {
    lo[r.v] = std::min(r.lower - q[r.q], 0.0);
    hi[r.v] = std::max(r.upper - q[r.q], 0.0);
  }
}

// A joint a bounded displacement d holds at its range end (d at lo or hi) is held by the
// range, whatever bound (the braking toward that displacement) is the tighter one at rest there.
void Controller::held_by_ranges(const Vector& d, const Vector& lo, const Vector& hi) {
  for (const PositionRange& r : bounds.ranges) {
    const Index j = r.v;
    if (d[j] >= hi[j] && box.hi_by[j] == kBraking) box.hi_by[j] = kPosition;
    if (d[j] <= lo[j] && box.lo_by[j] == kBraking) box.lo_by[j] = kPosition;
  }
}

// resting at a minimum the curvature test found (run): the first level's feedback projected
// onto the directions other than the minimum's flat ones (rest_keep's first rest_rank columns);
// out of line, so that the step that does not rest compiles as before (inlined, it cost
// 200-joint chains 30 % of their step)
void Controller::rest_along_flat() {
  const Index r = std::clamp<Index>(rest_rank, 0, nv);
  const Eigen::Map<const RowMatrix> kept(rest_keep.data(), nv, r);
  rest_coef_.head(r).noalias() = kept.transpose() * fb0_;
  fb0_.noalias() = kept * rest_coef_.head(r);
}

}  // namespace sjt
