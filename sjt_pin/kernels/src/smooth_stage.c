/* The acceleration and jerk stage of a kernel step (the constraint stage, compiled). */

#include "kernels.h"

/* The stage's vectors in work (n each, SM_* parts of sjt_pin/kernels/layout.py): the motion
 * state, the limits, the boxes and the codes of the limits that set them, and scratch. */
typedef struct {
    double *pdq, *pddq;                   /* previous velocity (rad/s) and acceleration */
    double *A, *Jk, *vj, *BA, *BJ;        /* accel., jerk, jerk's speed, braking accel./jerk */
    double *hlo, *hhi, *slo, *shi;        /* hard and smoothness boxes (rad/s) */
    double *hlb, *hhb, *slb, *shb;        /* the L_* code that set each bound, -1 none */
    double *desired, *out, *torn;         /* velocity before smoothing, result, hard box won */
    double *dqff, *save;                  /* feed-forward velocity / line base; saved gains */
} Stage;

/* -- the acceleration and jerk stage, compiled (sjt_pin/constraints.py and sjt_pin/limits are
 * its reference: Solver._constrain, _brake_feedback, ConstraintStage.box/enforce, smooth,
 * PositionLimit.bounds, braking_speed, stopping_distance, AccelerationLimit, JerkLimit) --- */

/* Distance (rad or m) to stop from velocity w > 0 with acceleration a0 along it, braking at the
 * acceleration limit A reached and left at the jerk limit J (inf: instantly); see
 * sjt_pin/limits/position.py, stopping_distance. */
static double stopping_distance_c(double w, double a0, double A, double J)
{
    int finite = isfinite(J);
    double inv_j = finite ? 1.0 / J : 0.0, jerk = finite ? J : 0.0;
    double up = dmax(a0, 0.0);  /* speeding up: ramp a0 down to 0 first */
    double t0 = up * inv_j;
    double d0 = w * t0 + up * t0 * t0 / 3.0;
    w = w + 0.5 * up * up * inv_j;
    double beta = dmax(-a0, 0.0);  /* already braking at beta */
    if (beta * beta >= 2.0 * jerk * w) {  /* the velocity reaches 0 while it ramps down */
        double ts = (beta - sqrt(dmax(beta * beta - 2.0 * jerk * w, 0.0))) * inv_j;
        return d0 + (w * ts - 0.5 * beta * ts * ts + jerk * ts * ts * ts / 6.0);
    }
    /* trapezoid: move beta to A, hold A, ramp A -> 0 */
    double sign = beta > A ? 1.0 : -1.0;
    double t1 = fabs(A - beta) * inv_j;
    double d1 = w * t1 - 0.5 * beta * t1 * t1 + sign * jerk * t1 * t1 * t1 / 6.0;
    double v1 = w - beta * t1 + 0.5 * sign * jerk * t1 * t1;
    double v2 = 0.5 * A * A * inv_j;
    if (v1 >= v2) {
        double t2 = dmax(v1 - v2, 0.0) / A;
        return d0 + (d1 + v1 * t2 - 0.5 * A * t2 * t2 + A * A * A * inv_j * inv_j / 6.0);
    }
    /* triangle: a peak a_p, then back to 0 */
    double a_p = sqrt(dmax(w * jerk + 0.5 * beta * beta, 0.0));
    double ta = (a_p - beta) * inv_j;
    return d0 + (w * ta - 0.5 * beta * ta * ta - jerk * ta * ta * ta / 6.0
                 + a_p * a_p * a_p * inv_j * inv_j / 6.0);
}

/* x dt + stopping_distance(x, (x - v) / dt) - room: > 0 where a velocity x toward a point
 * room away cannot stop before it (sjt_pin/limits/position.py, _overshoot) */
static double overshoot_c(double x, double v, double room, double dt, double A, double J)
{
    double d = x > 0.0 ? stopping_distance_c(dmax(x, 0.0), (x - v) / dt, A, J) : 0.0;
    return x * dt + d - room;
}

/* The largest velocity toward a point `room` away after which a joint can still stop before it
 * within the acceleration limit A and (with has_jerk) the jerk limit J; v is its previous
 * velocity toward that point: the root of the overshoot by regula falsi with the Illinois
 * modification (sjt_pin/limits/position.py, braking_speed). */
static double braking_speed_c(double room, double v, double dt, double A, double J,
                              int has_jerk)
{
    if (!isfinite(A)) return INFINITY;
    room = dmax(room, 0.0);
    if (!has_jerk) return ramp_speed(A, room, dt);
    double top = fabs(v) + 2.0 * A * dt;
    if (!(room < top * dt + stopping_distance_c(top, 2.0 * A, A, J))) return INFINITY;
    double low = v - 2.0 * A * dt, high = v + 2.0 * A * dt;
    double f_hi = overshoot_c(high, v, room, dt, A, J);
    if (f_hi <= 0.0) return INFINITY;  /* the fastest step fits: no bound */
    double f_lo = overshoot_c(low, v, room, dt, A, J);
    if (f_lo > 0.0) return low;  /* nothing fits: the slowest step */
    double lo = low, hi = high;
    if (low <= 0.0 && high > 0.0) {  /* x <= 0 fits; just above 0 the overshoot may jump */
        double f_zero = stopping_distance_c(0.0, -v / dt, A, J) - room;
        if (f_zero > 0.0) return 0.0;
        lo = 0.0;
        f_lo = f_zero;
    }
    double tol = (high - low) * BRAKING_TOL, side = 0.0;
    for (int i = 0; i < BRAKING_STEPS && hi - lo > tol; i++) {
        double x = lo - f_lo * (hi - lo) / (f_hi - f_lo);
        if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
        double fx = overshoot_c(x, v, room, dt, A, J);
        if (fx <= 0.0) {
            if (side < 0.0) f_hi = 0.5 * f_hi;
            lo = x;
            f_lo = fx;
            side = -1.0;
        } else {
            if (side > 0.0) f_lo = 0.5 * f_lo;
            hi = x;
            f_hi = fx;
            side = 1.0;
        }
    }
    return lo;
}

static Stage stage_parts(double *work, Py_ssize_t n)
{
    double *S = work + (Py_ssize_t)work[P_SMOOTH];
    Stage st = {
        S + SM_DQ * n, S + SM_DDQ * n,
        S + SM_ACC * n, S + SM_JERK * n, S + SM_JERK_SPEED * n, S + SM_BRAKE_ACC * n,
        S + SM_BRAKE_JERK * n,
        S + SM_HARD_LO * n, S + SM_HARD_HI * n, S + SM_SOFT_LO * n, S + SM_SOFT_HI * n,
        S + SM_HARD_LO_BY * n, S + SM_HARD_HI_BY * n, S + SM_SOFT_LO_BY * n,
        S + SM_SOFT_HI_BY * n,
        S + SM_DESIRED * n, S + SM_OUT * n, S + SM_TORN * n,
        S + SM_FF * n, S + SM_GAINS * n,
    };
    return st;
}

/* Narrow [*lo, *hi] to [lo_new, hi_new] where that is tighter, noting `code` (an L_* limit) as
 * what set each side. */
static inline void tighten(double *lo, double *hi, double *lo_by, double *hi_by, double lo_new,
                           double hi_new, double code)
{
    if (lo_new > *lo) {
        *lo = lo_new;
        *lo_by = code;
    }
    if (hi_new < *hi) {
        *hi = hi_new;
        *hi_by = code;
    }
}

/* Step 1 (Solver._brake_feedback): the feedback part of out (rad/s; out minus the feed-forward
 * velocity dqff, the method's map of ff plus the escape) slowed by sigma <= 1 so that a stop at
 * the target, 1/k of the feedback away (k the mean gain, 1/s), fits the acceleration limits:
 * sigma = ramp_speed(a_min, 1, dt) / rate. Returns sigma, the gain factor of SNS's re-solves. */
static double brake_feedback(int kind, Mat J, const double *e, const double *ff, int has_ff,
                             const double *mask, double *work, const Stage *st, int escaping)
{
    Py_ssize_t n = J.n, m = J.m;
    double dt = work[P_DT], *out = st->out, *dqff = st->dqff;
    Py_ssize_t extra = (Py_ssize_t)work[P_EXTRA];
    if (has_ff) {  /* (without a feed-forward the method maps 0 to 0: no solve) */
        core_scaled(kind, J, e, ff, has_ff, mask, work, dqff, 0.0, st->save);
    } else {
        for (Py_ssize_t j = 0; j < n; j++) dqff[j] = 0.0;
    }
    for (Py_ssize_t j = 0; j < n; j++)
        dqff[j] = escaping ? (dqff[j] + dt * work[extra + j]) / dt : dqff[j] / dt;
    Py_ssize_t rows_e = (Py_ssize_t)work[P_ERROR_ROWS];
    const double *gains = work + (Py_ssize_t)work[P_ROWS] + m;
    double k = 0.0;
    for (Py_ssize_t i = 0; i < rows_e; i++) k += gains[i];
    k /= (double)rows_e;
    if (work[P_GAIN_MODE] != GAIN_FIXED) k *= work[INFO + I_GAIN];
    if (!(k > 0.0)) return 1.0;
    double size = 0.0, dot = 0.0, a_min = INFINITY;
    for (Py_ssize_t j = 0; j < n; j++) {
        double fb = out[j] - dqff[j], d = fb / k;
        size += d * d;
        dot += fb * d;
        if (fabs(d) > 0.0) a_min = dmin(a_min, st->A[j] / fabs(d));
    }
    double rate = size > 0.0 ? dot / size : 0.0;
    if (!(rate > 0.0)) return 1.0;
    double allowed = isfinite(a_min) ? ramp_speed(a_min, 1.0, dt) : INFINITY;
    double sigma = dmin(1.0, dmax(allowed, 0.0) / rate);
    if (!(sigma < 1.0)) return 1.0;
    for (Py_ssize_t j = 0; j < n; j++) out[j] = dqff[j] + sigma * (out[j] - dqff[j]);
    return sigma;
}

/* The speed (rad/s or m/s) toward the range of a joint outside it (`above`: past its upper
 * limit): its velocity toward the range plus one step of a push at the braking acceleration BA;
 * with jerk limits the push also grows from the acceleration aa by at most BJ dt and stays small
 * enough to ramp back to 0 before the cap (p dt / 2 + p^2 / (2 BJ) <= the gap to it); at most
 * the recovery speed `rec` and never past the range's other side (`room` away) in one step. */
static double recovery_speed(int above, double room, double rec, double vv, double aa,
                             double BA, double BJ, double dt, int has_jerk)
{
    double toward = above ? -vv : vv;
    double cap = dmin(rec, room / dt);
    double push = BA;
    if (has_jerk && isfinite(BJ)) {
        double gap = dmax(cap - toward, 0.0);
        push = dmin(dmin(BA, dmax(above ? -aa : aa, 0.0) + BJ * dt),
                    sqrt((0.5 * BJ * dt) * (0.5 * BJ * dt) + 2.0 * BJ * gap) - 0.5 * BJ * dt);
    }
    return dmin(cap, toward + push * dt);
}

/* Step 2, the hard box's positions (PositionLimit.bounds): a joint inside its range may move at
 * most as fast as it can still brake to a stop at either limit (braking_speed_c, within the
 * braking acceleration and jerk) and never past it in one step; outside, it returns at
 * recovery_speed. Bounds in rad/s (m/s), codes L_POSITION. */
static void position_box(const double *q, const double *work, const Stage *st, int has_jerk)
{
    double dt = work[P_DT];
    Py_ssize_t count = (Py_ssize_t)work[P_BOX_COUNT];
    for (Py_ssize_t c = 0; c < count; c++) {
        BoxEntry b = box_entry(q, work, c);
        Py_ssize_t v = b.v;
        double room_up = b.upper - b.x, room_down = b.x - b.lower, vv = st->pdq[v];
        double BA = st->BA[v], BJ = st->BJ[v];
        double up = dmin(braking_speed_c(room_up, vv, dt, BA, BJ, has_jerk), room_up / dt);
        double lw = -dmin(braking_speed_c(room_down, -vv, dt, BA, BJ, has_jerk),
                          room_down / dt);
        int above = room_up < 0.0, below = room_down < 0.0;
        if (above || below) {  /* back toward the range, a ramp within the limits */
            double back = recovery_speed(above, above ? room_down : room_up,
                                         b.back, vv, st->pddq[v], BA, BJ,
                                         dt, has_jerk);
            lw = up = above ? -back : back;
        }
        tighten(st->hlo + v, st->hhi + v, st->hlb + v, st->hhb + v, lw, up, L_POSITION);
    }
}

/* Step 2, the hard box (rad/s): position braking (position_box), speeds (L_VELOCITY), and
 * joints the solver does not move held at rest. Returns whether out lies inside it. */
static int hard_box(const double *q, const double *mask, const double *work, const Stage *st,
                    Py_ssize_t n, int has_jerk)
{
    for (Py_ssize_t j = 0; j < n; j++) {
        st->hlo[j] = -INFINITY;
        st->hhi[j] = INFINITY;
        st->hlb[j] = st->hhb[j] = -1.0;
    }
    position_box(q, work, st, has_jerk);
    int inside = 1;
    for (Py_ssize_t j = 0; j < n; j++) {
        double vmax = speed_limit(work, j);
        tighten(st->hlo + j, st->hhi + j, st->hlb + j, st->hhb + j, -vmax, vmax, L_VELOCITY);
        if (mask[j] == 0.0) {  /* joints the solver does not move stay at rest */
            st->hlo[j] = dmin(st->hlo[j], 0.0);
            st->hhi[j] = dmax(st->hhi[j], 0.0);
        }
        if (st->out[j] < st->hlo[j] - BOUND_TOL || st->out[j] > st->hhi[j] + BOUND_TOL)
            inside = 0;
    }
    return inside;
}

/* Step 3, the smoothness box (rad/s, smoothness_limits around the previous velocity and
 * acceleration), each bound's limit, and the joints whose limits contradicted each other
 * marked in torn. */
static void smoothness_bounds(const double *work, const Stage *st, Py_ssize_t n, int has_jerk)
{
    double dt = work[P_DT];
    for (Py_ssize_t j = 0; j < n; j++)
        st->torn[j] = smoothness_limits(st->pdq[j], st->pddq[j], st->A[j], st->Jk[j], st->vj[j],
                                        dt, has_jerk, st->slo + j, st->shi + j, st->slb + j,
                                        st->shb + j);
}

/* Step 5 (ConstraintStage.smooth): the velocity moves from the smoothness box's centre (within
 * the hard box where both meet) toward out along a line, as far tau in [0, 1] as the smoothness
 * box allows, its bounds first narrowed so that with jerk limits out is reached without
 * overshooting it (ramp_speed of the gap); the hard box wins where it clips the result (marked
 * in torn, as are the joints whose smoothness limits contradicted each other). Writes desired
 * (out before), dqff (the line's base), out and step (rad). */
static void smooth_line(const double *work, const Stage *st, Py_ssize_t n, int has_jerk,
                        double *step)
{
    double dt = work[P_DT], tau = 1.0;
    double *slo = st->slo, *shi = st->shi, *out = st->out, *base = st->dqff;
    for (Py_ssize_t j = 0; j < n; j++) {
        st->desired[j] = out[j];
        if (has_jerk && isfinite(st->Jk[j])) {
            double gap = out[j] - st->pdq[j];
            double a_max = ramp_speed(st->Jk[j], fabs(gap), dt);
            double room = isfinite(a_max) ? dt * a_max : INFINITY;
            double lo = gap < 0.0 ? st->pdq[j] - room : -INFINITY;
            double hi = gap > 0.0 ? st->pdq[j] + room : INFINITY;
            slo[j] = dmax(slo[j], dmin(lo, shi[j]));
            shi[j] = dmin(shi[j], dmax(hi, slo[j]));
        }
        double l = isfinite(slo[j]) ? slo[j] : shi[j], u = isfinite(shi[j]) ? shi[j] : slo[j];
        double b = 0.5 * (l + u);
        if (!isfinite(b)) b = out[j];
        double both_lo = dmax(slo[j], st->hlo[j]), both_hi = dmin(shi[j], st->hhi[j]);
        if (both_lo <= both_hi) b = dmin(dmax(b, both_lo), both_hi);
        base[j] = b;
        double change = out[j] - b;
        double room = change > 0.0 ? (shi[j] - b) / change
                      : change < 0.0 ? (slo[j] - b) / change : INFINITY;
        tau = dmin(tau, room);
    }
    tau = dmin(dmax(tau, 0.0), 1.0);
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = base[j] + tau * (out[j] - base[j]);
        st->torn[j] = v < st->hlo[j] || v > st->hhi[j] || st->torn[j] != 0.0 ? 1.0 : 0.0;
        out[j] = dmin(dmax(v, st->hlo[j]), st->hhi[j]);
        step[j] = out[j] * dt;
    }
}

/* Step 6: the motion state for the next step, the velocity (rad/s) and acceleration (rad/s^2)
 * the step (rad) commands. */
static void motion_state(const double *step, double dt, const Stage *st, Py_ssize_t n)
{
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = step[j] / dt;
        st->pddq[j] = (v - st->pdq[j]) / dt;
        st->pdq[j] = v;
    }
}

/* The acceleration/jerk stage on the method's step (rad, overwritten): the feedback slowed so
 * that every joint can stop where the error says the target is; the hard box (position braking
 * within the acceleration and jerk limits, speeds) and the smoothness box (acceleration, jerk,
 * the jerk's approach to the speed limits); SNS on the hard box; the move from the previous
 * velocity toward the result along a line as far as the smoothness box allows, the hard box
 * winning; exactly onto a position limit; and the motion state (previous velocity and
 * acceleration) updated. The boxes, the limits that set them (L_* codes, -1 none), the
 * velocity before smoothing and the joints where the hard box won stay in work for StepInfo.
 * Returns CLAMPED / SCALED as saturate_c. */
int smooth_stage_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
                   const double *q, const double *mask, double *work, double *step,
                   int escaping)
{
    Py_ssize_t n = J.n;
    double dt = work[P_DT];
    Stage st = stage_parts(work, n);
    double *held = work + (Py_ssize_t)work[P_CLAMPED];
    int has_jerk = work[P_JERK] != 0.0;
    for (Py_ssize_t j = 0; j < n; j++) st.out[j] = step[j] / dt;
    double factor = brake_feedback(kind, J, e, ff, has_ff, mask, work, &st, escaping);
    int inside = hard_box(q, mask, work, &st, n, has_jerk);
    smoothness_bounds(work, &st, n, has_jerk);
    for (Py_ssize_t j = 0; j < n; j++) held[j] = 0.0;
    /* 4. SNS on the hard box */
    double scale = 1.0;
    int status = 0;
    if (!inside) {  /* (the velocity SNS starts from, for a user's rows: smooth_rows_c) */
        memcpy(method_velocity(work, J.m, n), st.out, (size_t)n * sizeof(double));
        status = sns_c(kind, J, e, ff, has_ff, mask, work, st.hlo, st.hhi, st.out, factor,
                       st.save, escaping, &scale);
    }
    work[INFO + I_SCALE] = scale;
    smooth_line(work, &st, n, has_jerk, step);
    /* 6. exactly onto a position limit; the motion state for the next step */
    exact_position(q, work, step);
    motion_state(step, dt, &st, n);
    return status;
}
