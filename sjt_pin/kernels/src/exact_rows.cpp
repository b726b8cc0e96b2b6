// A pose error's exact rows (controller.hpp): the CLIK rows J of a log6 error, Jlog6 J from a
// rest at a position range short of the target on, until the target is reached or replaced.
#include "controller.hpp"

#include <cmath>

#include "lie.hpp"

namespace sjt {

void Controller::set_log6_rows(const Eigen::Matrix<int64_t, Eigen::Dynamic, 1>& rows) {
  const Level& L0 = levels[0];
  std::vector<Index> kept;
  for (Index k = 0; k < rows.size(); ++k) {
    if (rows[k] < L0.begin || rows[k] + 6 > L0.begin + L0.targets)
      fail("a pose error's rows must be 6 target rows of the first level");
    kept.push_back(static_cast<Index>(rows[k]));
  }
  log6_rows_ = kept;
  jlog6_.setZero(6, 6);
  exact6_.setZero(6, nv);
}

// The first level's pose errors e = log6(N) with their exact rows G J, G = Jlog6(N^-1), and
// their feed-forward G ff (the frame's twist that follows the target, in LOCAL axes: then
// e_dot = -G (J q_dot - ff) exactly), into `out` (run: Jw_, first = 0; first_rows: the first
// level's rows, first = its first row). The CLIK rows J give the error's rate only to first
// order near the target (the paper's Lyapunov argument for D J^T, eq. 22, takes
// e_dot = -J q_dot): far from it SE(3)'s logarithm couples the position rows with the
// rotation, and J^T e is not the error's gradient. run() takes these rows from a rest at a
// position range on (watch_rest), where the CLIK model can be stationary while the error still
// falls.
void Controller::exact_rows(const Eigen::Ref<const RowMatrix>& J,
                            const Eigen::Ref<const Vector>& e, const double* ff_in,
                            Eigen::Ref<RowMatrix> out, Index first) {
  for (const Index r : log6_rows_) {
    jlog6_inverse(e.data() + r, MatrixMap(jlog6_.data(), 6, 6));
    exact6_.noalias() = jlog6_ * J.middleRows(r, 6);
    out.middleRows(r - first, 6).noalias() =
        sqrt_weight.segment(r, 6).asDiagonal() * exact6_ * moving.asDiagonal();
    if (ff_in) {
      const Eigen::Map<const Eigen::Matrix<double, 6, 1>> f(ff_in + r);
      ffw_.segment(r, 6).noalias() =
          sqrt_weight.segment(r, 6).cwiseProduct(jlog6_ * f);
    }
  }
}

// Whether the next steps take the pose errors' exact rows (exact_rows): from a rest held by a
// position range (the stage changed the method's step, a joint ends the step within
// kRangeTol of its range, and the step lowered 1/2 |e_w|^2 by less than kRestRate of it a
// second) kStillSteps steps long, short of the target, outside the saddle escape's watch (a
// stall of the method's own, which its curvature test answers in the CLIK model); until |e_w|
// is below kExactTo times the converged floor. (Not at a rest held by collision rows alone:
// there the arm slid on along the obstacle, xArm7 behind one resting at 7.8 s instead of 1.6.)
void Controller::watch_rest(int status, const double* q, const Eigen::Ref<const Vector>& step) {
  const Level& L0 = levels[0];
  const auto ew0 = ew_.segment(L0.begin, L0.targets);
  const double sq = ew0.squaredNorm();
  if (exact) {
    exact = sq >= kExactTo * kExactTo * stall_floor;
  } else {
    double rate = ew0.dot(bent_.head(L0.targets));
    if (ff_sq > 0.0) rate -= ew0.dot(ffw_.segment(L0.begin, L0.targets));
    bool resting = (status & kConstrained) && !escaping && stall_run < 0.0 &&
                   sq > kExactFrom * kExactFrom * stall_floor && std::abs(rate) < kRestRate * sq;
    if (resting) {
      bool at_range = false;
      for (const PositionRange& r : bounds.ranges) {
        const double x = q[r.q] + step[r.v];
        at_range = at_range || x <= r.lower + kRangeTol || x >= r.upper - kRangeTol;
      }
      resting = at_range;
    }
    still = resting ? still + 1.0 : 0.0;
    exact = still >= kStillSteps;
    if (exact) still = 0.0;
  }
  if (exact) {  // the error the next step expects of this one's motion (keeps_exact)
    expected = ew0 - dt_ * bent_.head(L0.targets);
    if (ff_sq > 0.0) expected += dt_ * ffw_.segment(L0.begin, L0.targets);
  }
}

// Whether this step takes the exact rows: those of a rest (watch_rest) belong to its target,
// and a new one (the first level's weighted error off the one the last step expects by more
// than kJump of itself: a target that jumped, not one that moves) starts again in the CLIK
// rows. (Kept for the next ones, the exact rows changed the basins of the targets that followed
// a rest: TALOS's arm and Z1 on the settle bench's streams, 6 fewer targets reached.)
bool Controller::keeps_exact(const Eigen::Ref<const Vector>& e) {
  if (!exact) return false;
  const Level& L0 = levels[0];
  double off = 0.0, size = 0.0;
  for (Index i = 0; i < L0.targets; ++i) {
    const double ew = sqrt_weight[L0.begin + i] * e[L0.begin + i];
    off += (ew - expected[i]) * (ew - expected[i]);
    size += ew * ew;
  }
  if (off > kJump * kJump * size) exact = false;
  return exact;
}

}  // namespace sjt
