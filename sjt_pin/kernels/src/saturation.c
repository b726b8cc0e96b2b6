/* Position and speed limits of a kernel step: the task's scale, the rank test, Flacco's
 * saturation in the null space (SNS) and the exact position clamp. */

#include "kernels.h"

/* SNS's vectors in work's clamped part (n each unless noted): the held flags, the candidate
 * dq = b + s a (a: the method on the free joints, b: what the held ones leave them to make up,
 * hv: the held joints' velocities, rad/s), the free joints, the best candidate so far, and
 * scratch (ff2: m, G: m x m, norm: n). */
typedef struct {
    double *held, *a, *b, *hv, *free_;
    double *best_a, *best_b, *best_hv, *best_held;
    double *ff2, *G, *norm;
} Sns;

/* The largest s in [0, 1] with lower <= b + s a <= upper on the free joints, and the joint
 * that limits it (*k; -1 when s = 1 fits); -1 when no s fits (constraints.task_scale). */
static double task_scale_c(const double *a, const double *b, const double *lo,
                           const double *hi, const double *free_, Py_ssize_t n, Py_ssize_t *k)
{
    double s_max = INFINITY, s_min = -INFINITY;
    Py_ssize_t arg = -1;
    for (Py_ssize_t j = 0; j < n; j++) {
        if (free_[j] == 0.0) continue;
        double top, bottom;
        if (a[j] > 0.0) {
            top = (hi[j] - b[j]) / a[j];
            bottom = (lo[j] - b[j]) / a[j];
        } else if (a[j] < 0.0) {
            top = (lo[j] - b[j]) / a[j];
            bottom = (hi[j] - b[j]) / a[j];
        } else {
            top = b[j] < lo[j] - BOUND_TOL || b[j] > hi[j] + BOUND_TOL ? -INFINITY : INFINITY;
            bottom = -INFINITY;
        }
        if (top < s_max) {
            s_max = top;
            arg = j;
        }
        s_min = dmax(s_min, bottom);
    }
    if (s_max >= 1.0 && s_min <= 1.0) {
        *k = -1;
        return 1.0;
    }
    *k = arg;
    if (s_max < 0.0 || s_min > dmin(s_max, 1.0) + 1e-12) return -1.0;
    return dmax(dmin(s_max, 1.0), 0.0);
}

/* out = the velocity a (rad/s) scaled down as a whole into [lo, hi] on the joints of mask (0
 * on the others; the nearest point of the box when no scale fits): sns_c's first candidate,
 * continuous in a (constraints.scaled_into). zero: n doubles of scratch. Returns the scale. */
double scaled_into_c(const double *a, const double *lo, const double *hi, const double *mask,
                     Py_ssize_t n, double *zero, double *out)
{
    Py_ssize_t k;
    for (Py_ssize_t j = 0; j < n; j++) zero[j] = 0.0;
    double s = dmax(task_scale_c(a, zero, lo, hi, mask, n, &k), 0.0);
    for (Py_ssize_t j = 0; j < n; j++)
        out[j] = mask[j] != 0.0 ? dmin(dmax(s * a[j], lo[j]), hi[j]) : 0.0;
    return s;
}

/* whether the free joints' weighted task columns (the first error_rows rows), each scaled to
 * unit norm, span R^rows: their Gram matrix G (rows x rows scratch) is positive
 * definite with lambda_min above RANK_TOL^2 of its trace */
static int spans_c(Mat J, const double *sw, Py_ssize_t rows, const double *free_, double *G,
                   double *norm)
{
    Py_ssize_t n = J.n, count = 0;
    for (Py_ssize_t j = 0; j < n; j++) {
        double acc = free_[j] != 0.0 ? weighted_column_norm2(J, sw, rows, j) : 0.0;
        norm[j] = acc > 0.0 ? 1.0 / acc : 0.0;
        if (acc > 0.0) count++;
    }
    if (count < rows) return 0;
    for (Py_ssize_t a = 0; a < rows; a++)
        for (Py_ssize_t b = 0; b <= a; b++) {
            double acc = 0.0;
            for (Py_ssize_t j = 0; j < n; j++)
                acc += norm[j] * sw[a] * AT(J, a, j) * sw[b] * AT(J, b, j);
            G[a * rows + b] = G[b * rows + a] = acc;
        }
    /* lambda_min(G) > RANK_TOL^2 tr(G) (>= RANK_TOL^2 lambda_max): G - that I is positive
     * definite, one Cholesky factorisation */
    double trace = 0.0;
    for (Py_ssize_t i = 0; i < rows; i++) trace += G[i * rows + i];
    return cholesky_factor(G, rows, -RANK_TOL * RANK_TOL * trace);
}

/* a joint inside its range moves exactly onto a limit, never a rounding error past it */
void exact_position(const double *q, const double *work, double *step)
{
    Py_ssize_t count = (Py_ssize_t)work[P_BOX_COUNT];
    for (Py_ssize_t c = 0; c < count; c++) {
        BoxEntry b = box_entry(q, work, c);
        if (b.lower <= b.x && b.x <= b.upper)
            step[b.v] = dmin(dmax(step[b.v], b.lower - b.x), b.upper - b.x);
    }
}

/* core() with the gain of the feedback K e times `factor` (1: the step's own, recomputed on the
 * joints of mask for "auto"; else the fixed gain factor K, times the step's "auto" gain
 * info[I_GAIN]): the stage's re-solves after the feedback was slowed (Solver._constrain's
 * solve(free, held, scale)). `save` holds m numbers while the gains are changed. */
void core_scaled(int kind, Mat J, const double *e, const double *ff, int has_ff,
                 const double *mask, double *work, double *step, double factor,
                 double *save)
{
    if (factor == 1.0) {
        core(kind, J, e, ff, has_ff, mask, work, step);
        return;
    }
    Py_ssize_t m = J.m;
    double *k = work + (Py_ssize_t)work[P_ROWS] + m;
    double mode = work[P_GAIN_MODE];
    memcpy(save, k, (size_t)m * sizeof(double));
    for (Py_ssize_t i = 0; i < m; i++) {
        k[i] = k[i] * factor;
        if (mode != GAIN_FIXED) k[i] *= work[INFO + I_GAIN];
    }
    work[P_GAIN_MODE] = GAIN_FIXED;
    core(kind, J, e, ff, has_ff, mask, work, step);
    work[P_GAIN_MODE] = mode;
    memcpy(k, save, (size_t)m * sizeof(double));
}

static Sns sns_parts(double *work, Py_ssize_t m, Py_ssize_t n)
{
    Sns s;
    s.held = work + (Py_ssize_t)work[P_CLAMPED];
    s.a = s.held + 3 * n;
    s.b = s.a + n;
    s.hv = s.b + n;
    s.free_ = s.hv + n;
    s.best_a = s.free_ + n;
    s.best_b = s.best_a + n;
    s.best_hv = s.best_b + n;
    s.best_held = s.best_hv + n;
    s.ff2 = s.best_held + n;
    s.G = s.ff2 + m;
    s.norm = s.G + m * m;
    return s;
}

/* the candidate (a, b, hv, held) becomes the best so far */
static inline void sns_keep(const Sns *s, Py_ssize_t n)
{
    memcpy(s->best_a, s->a, (size_t)n * sizeof(double));
    memcpy(s->best_b, s->b, (size_t)n * sizeof(double));
    memcpy(s->best_hv, s->hv, (size_t)n * sizeof(double));
    memcpy(s->best_held, s->held, (size_t)n * sizeof(double));
}

/* The method solved again on the free joints (Flacco, De Luca and Khatib's SNS step, rad/s):
 * a = M_free(v) / dt, b = M_free(v - J hv) / dt - a, with the gain factor `factor`
 * (core_scaled) and the escape's velocity added to a when escaping. */
static void sns_resolve(int kind, Mat J, const double *e, const double *ff, int has_ff,
                        double *work, const Sns *s, double factor, double *save, int escaping)
{
    Py_ssize_t m = J.m, n = J.n;
    double dt = work[P_DT];
    Py_ssize_t extra = (Py_ssize_t)work[P_EXTRA];
    core_scaled(kind, J, e, ff, has_ff, s->free_, work, s->a, factor, save);
    int moving = 0;  /* held joints at rest leave the others nothing to make up for */
    for (Py_ssize_t j = 0; j < n; j++) moving |= s->hv[j] != 0.0;
    if (moving) {
        for (Py_ssize_t i = 0; i < m; i++) {
            double acc = has_ff ? ff[i] : 0.0;
            for (Py_ssize_t j = 0; j < n; j++) acc -= AT(J, i, j) * s->hv[j];
            s->ff2[i] = acc;
        }
        core_scaled(kind, J, e, s->ff2, 1, s->free_, work, s->b, factor, save);
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        s->a[j] /= dt;
        s->b[j] = moving ? s->b[j] / dt - s->a[j] : 0.0;
        if (escaping) s->a[j] += work[extra + j];
    }
}

/* Joint k is held at the bound its motion heads for (rad/s). Returns whether joints are left
 * free. */
static int sns_hold(const Sns *s, Py_ssize_t k, const double *lo, const double *hi, Py_ssize_t n)
{
    double *a = s->a, *b = s->b;
    double direction = a[k] != 0.0 ? a[k] : (b[k] > hi[k] ? b[k] - hi[k] : b[k]);
    s->held[k] = 1.0;
    s->free_[k] = 0.0;
    s->hv[k] = direction > 0.0 ? hi[k] : lo[k];
    int left = 0;
    for (Py_ssize_t j = 0; j < n; j++) left |= s->free_[j] != 0.0;
    return left;
}

/* Saturation in the Null Space (sjt_pin/constraints.py, saturate) on the box [lo, hi] (rad/s):
 * the joint that limits the task most is held at its bound and the method solved again on the
 * others (gain factor `factor`, see core_scaled); when the free joints no longer span the task,
 * the best candidate so far wins (the velocity `dq` scaled down as a whole is the first). `dq`
 * (rad/s) is overwritten with the result; the held joints are left in work's clamped part.
 * Returns CLAMPED when joints are held and SCALED when the task was scaled; *scale_out is the
 * task scale. */
int sns_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
          const double *mask, double *work, const double *lo, const double *hi,
          double *dq, double factor, double *save, int escaping, double *scale_out)
{
    Py_ssize_t m = J.m, n = J.n;
    Sns s = sns_parts(work, m, n);
    const double *sw = work + (Py_ssize_t)work[P_ROWS];
    Py_ssize_t rows = (Py_ssize_t)work[P_ERROR_ROWS];
    for (Py_ssize_t j = 0; j < n; j++) {
        s.a[j] = dq[j];
        s.b[j] = 0.0;
        s.hv[j] = 0.0;
        s.held[j] = 0.0;
        s.free_[j] = mask[j] != 0.0 ? mask[j] : 0.0;
    }
    Py_ssize_t k;
    double best = task_scale_c(s.a, s.b, lo, hi, s.free_, n, &k);
    sns_keep(&s, n);
    int any_held = 0;
    for (Py_ssize_t round = 0; round < n; round++) {
        double scale = task_scale_c(s.a, s.b, lo, hi, s.free_, n, &k);
        if (any_held && !spans_c(J, sw, rows, s.free_, s.G, s.norm)) break;
        if (scale > best) {
            best = scale;
            sns_keep(&s, n);
        }
        if (scale >= 1.0 || k < 0) break;
        any_held = 1;
        if (!sns_hold(&s, k, lo, hi, n)) break;
        /* fewer free joints than task rows cannot span them (spans_c): the next round would
         * stop before using a re-solve */
        Py_ssize_t left = 0;
        for (Py_ssize_t j = 0; j < n; j++) left += s.free_[j] != 0.0;
        if (left < rows) break;
        sns_resolve(kind, J, e, ff, has_ff, work, &s, factor, save, escaping);
    }
    double scale = dmax(best, 0.0);
    int status = 0;
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = s.best_held[j] != 0.0 ? s.best_hv[j] : s.best_b[j] + scale * s.best_a[j];
        if (mask[j] == 0.0) v = 0.0;
        dq[j] = dmin(dmax(v, lo[j]), hi[j]);
        s.held[j] = s.best_held[j];
        if (s.held[j] != 0.0) status |= CLAMPED;
    }
    *scale_out = best >= 0.0 ? scale : 0.0;
    if (scale < 1.0) status |= SCALED;
    return status;
}

/* The position (onto the range, or back into it at the recovery speed) and speed bounds of
 * this step, then Saturation in the Null Space on them (sns_c). Writes step; returns CLAMPED
 * when joints are held and SCALED when the task was scaled, 0 when nothing bounded it. */
int saturate_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
               const double *q, const double *mask, double *work, double *step,
               int escaping)
{
    Py_ssize_t n = J.n;
    double dt = work[P_DT];
    double *held = work + (Py_ssize_t)work[P_CLAMPED];
    double *lo = held + n, *hi = lo + n, *a = hi + n;
    for (Py_ssize_t j = 0; j < n; j++) {
        double vmax = speed_limit(work, j);
        lo[j] = -vmax;
        hi[j] = vmax;
        held[j] = 0.0;
    }
    Py_ssize_t count = (Py_ssize_t)work[P_BOX_COUNT];
    for (Py_ssize_t c = 0; c < count; c++) {
        BoxEntry b = box_entry(q, work, c);
        Py_ssize_t v = b.v;
        if (b.x > b.upper) {
            lo[v] = hi[v] = -dmin(b.back, (b.x - b.upper) / dt);
        } else if (b.x < b.lower) {
            lo[v] = hi[v] = dmin(b.back, (b.lower - b.x) / dt);
        } else {
            lo[v] = dmax(lo[v], (b.lower - b.x) / dt);
            hi[v] = dmin(hi[v], (b.upper - b.x) / dt);
        }
    }
    int inside = 1;
    for (Py_ssize_t j = 0; j < n; j++) {
        if (mask[j] == 0.0) {
            lo[j] = dmin(lo[j], 0.0);
            hi[j] = dmax(hi[j], 0.0);
        }
        a[j] = step[j] / dt;
        if (a[j] < lo[j] - BOUND_TOL || a[j] > hi[j] + BOUND_TOL) inside = 0;
    }
    work[INFO + I_SCALE] = 1.0;
    if (inside) {
        exact_position(q, work, step);
        return 0;
    }
    /* the method's velocity, for a user's rows (rows_step_c: scaled_into_c) */
    memcpy(method_velocity(work, J.m, n), a, (size_t)n * sizeof(double));
    /* a is sns_c's first candidate, and its result */
    double scale;
    int status = sns_c(kind, J, e, ff, has_ff, mask, work, lo, hi, a, 1.0, NULL, escaping,
                       &scale);
    for (Py_ssize_t j = 0; j < n; j++) step[j] = a[j] * dt;
    exact_position(q, work, step);
    work[INFO + I_SCALE] = scale;
    return status;
}
