/* The constraint stage's correction: the smallest change of a step onto general rows
 * A dq <= b within the bounds (NNLS on the dual), and a step checked against them. */

#include "kernels.h"

/* how far the smoothness box widens, around its centre, in the rounds that look for the
 * smallest breach of the acceleration and jerk limits that lets the rows hold (2^r times in
 * round r), and how closely the factor is then bisected (its ratio to the least that holds,
 * in at most SMOOTH_BISECTIONS halvings) */
#define SMOOTH_WIDEN_ROUNDS 6
#define SMOOTH_BISECTIONS 16
#define SMOOTH_PRECISION 1.01

/* rest_target_c's ridge of Jw Jw^T, relative to its mean diagonal (constraints.REST_RIDGE) */
#define REST_RIDGE 1e-12

/* -- the constraint stage's correction (sjt_pin/constraints.py: project, nonnegative_qp) -------- */

/* The state of nonnegative_qp_c: Q (k x k) with its ridge, r, the iterate y, the flags of the
 * passive set and of the inert rows (those no motion changes: Q_tt = 0), and its scratch. */
typedef struct {
    const double *Q, *r;
    Py_ssize_t k;
    double ridge, *y, *w, *s, *rhs, *sub, *V, *passive, *inert;
    Py_ssize_t *idx;
} Nnls;

/* y = 0, nothing passive; the rows no motion changes are inert (they never enter: their
 * gradient is zero and they would stall every round); returns the tolerance of the test for
 * optimality, tol (1 + max |r|) */
static double nnls_start(Nnls *p, double tol)
{
    double top = 0.0, rmax = 0.0;
    for (Py_ssize_t i = 0; i < p->k; i++) {
        p->y[i] = p->passive[i] = 0.0;
        top = dmax(top, p->Q[i * p->k + i]);
        rmax = dmax(rmax, fabs(p->r[i]));
    }
    p->ridge = DUAL_RIDGE * top;
    for (Py_ssize_t i = 0; i < p->k; i++)
        p->inert[i] = p->Q[i * p->k + i] <= 1e-14 * dmax(top, 1e-300) ? 1.0 : 0.0;
    return tol * (1.0 + rmax);
}

/* The row that enters the passive set: the largest entry of the negative gradient
 * -(Q y + r) among the rows neither passive nor inert, above `scale`; -1 when none (y is
 * optimal). */
static Py_ssize_t nnls_entering(const Nnls *p, double scale)
{
    Py_ssize_t t = -1, k = p->k;
    double best = -INFINITY;
    for (Py_ssize_t i = 0; i < k; i++) {
        if (p->passive[i] != 0.0 || p->inert[i] != 0.0) continue;
        double acc = -p->r[i] - p->ridge * p->y[i];
        for (Py_ssize_t j = 0; j < k; j++) acc -= p->Q[i * k + j] * p->y[j];
        if (acc > best) {
            best = acc;
            t = i;
        }
    }
    return best > scale ? t : -1;
}

/* s: the passive set's unconstrained minimiser (0 elsewhere), its system by Cholesky (the
 * ridge makes it positive definite) and the pseudo-inverse only if rounding made a pivot
 * vanish; writes the passive indices to idx and their count to *count. Returns whether every
 * passive entry of s is positive. */
static int nnls_passive_solve(const Nnls *p, Py_ssize_t *count)
{
    Py_ssize_t k = p->k, n = 0;
    for (Py_ssize_t i = 0; i < k; i++)
        if (p->passive[i] != 0.0) p->idx[n++] = i;
    for (Py_ssize_t a = 0; a < n; a++) {
        p->rhs[a] = -p->r[p->idx[a]];
        for (Py_ssize_t c = 0; c < n; c++) p->sub[a * n + c] = p->Q[p->idx[a] * k + p->idx[c]];
        p->sub[a * n + a] += p->ridge;
    }
    double *sol = p->w;
    memcpy(p->V, p->sub, (size_t)(n * n) * sizeof(double));
    if (cholesky_factor(p->V, n, 0.0))
        cholesky_substitute(p->V, n, p->rhs, sol);
    else
        pseudo_solve(p->sub, p->V, n, p->rhs, sol, 0.0);
    for (Py_ssize_t i = 0; i < k; i++) p->s[i] = 0.0;
    int positive = 1;
    for (Py_ssize_t a = 0; a < n; a++) {
        p->s[p->idx[a]] = sol[a];
        if (!(sol[a] > 0.0)) positive = 0;
    }
    *count = n;
    return positive;
}

/* The step from y toward s stops where the first passive entry at or below 0 in s reaches 0
 * (one already at 0 with s = 0 too stops it at once); those at 0 leave the passive set.
 * Returns whether any row is still passive. */
static int nnls_step_back(const Nnls *p, Py_ssize_t count)
{
    double alpha = INFINITY;
    for (Py_ssize_t a = 0; a < count; a++) {
        Py_ssize_t i = p->idx[a];
        if (p->s[i] > 0.0) continue;
        double gap = p->y[i] - p->s[i];
        alpha = dmin(alpha, gap > 0.0 ? p->y[i] / gap : 0.0);
    }
    int any = 0;
    for (Py_ssize_t i = 0; i < p->k; i++) {
        p->y[i] += alpha * (p->s[i] - p->y[i]);
        if (p->passive[i] != 0.0 && !(p->y[i] > 1e-15)) p->passive[i] = 0.0;
        if (p->passive[i] == 0.0) p->y[i] = 0.0;
        any |= p->passive[i] != 0.0;
    }
    return any;
}

/* argmin 1/2 y^T Q y + r^T y over y >= 0 for the symmetric PSD Q (k x k, row-major) plus
 * DUAL_RIDGE max(diag Q) I: the active-set method of Lawson and Hanson's NNLS on the normal
 * equations of the passive set, step for step as constraints.nonnegative_qp (the reference;
 * the passive set's system by Cholesky where numpy's lstsq solves it). scratch: 3 k + 2 k k
 * doubles, then k + k passive/inert flags and k indices. Returns the passive-set solves. */
static int nonnegative_qp_c(const double *Q, const double *r, Py_ssize_t k, double tol,
                            double *y, double *scratch)
{
    Nnls p = {Q, r, k, 0.0, y, scratch, NULL, NULL, NULL, NULL, NULL, NULL, NULL};
    p.s = p.w + k;
    p.rhs = p.s + k;
    p.sub = p.rhs + k;
    p.V = p.sub + k * k;
    p.passive = p.V + k * k;
    p.inert = p.passive + k;
    p.idx = (Py_ssize_t *)(p.inert + k);
    double scale = nnls_start(&p, tol);
    int solves = 0;
    for (Py_ssize_t outer = 0; outer < 3 * k + 10; outer++) {
        Py_ssize_t t = nnls_entering(&p, scale);
        if (t < 0) break;
        p.passive[t] = 1.0;
        for (Py_ssize_t inner = 0; inner < 3 * k + 10; inner++) {
            Py_ssize_t count;
            int positive = nnls_passive_solve(&p, &count);
            solves++;
            if (positive) {
                memcpy(y, p.s, (size_t)k * sizeof(double));
                break;
            }
            if (!nnls_step_back(&p, count)) break;
        }
    }
    return solves;
}

/* doubles of scratch nonnegative_qp_c needs for k rows (its flags and indices included) */
static Py_ssize_t nonnegative_qp_scratch(Py_ssize_t k) { return 6 * k + 2 * k * k + 1; }

/* The whitened dual of project_once_c on the moving joints cols (nc of n): L the Cholesky
 * factor of H = Jw_c^T Jw_c + rho I, the rows G x <= h (A's moving columns, then -e_c for
 * each finite lower bound and e_c for each finite upper one), C = G L^-T (rows x nc), the
 * residual h - G x0 at x0 = dq_c, and the dual's Q = C C^T and solution y. */
typedef struct {
    Py_ssize_t n, nc, k, lo_count, hi_count, rows;
    Py_ssize_t *cols;
    double *L, *C, *h, *y, *Q, *x0, *z, *scratch;
} Dual;

/* the moving joints and the finite bounds among them; out = dq. Returns the doubles the
 * dual's buffers need. */
static size_t dual_sizes(Dual *d, const double *dq, const double *lower, const double *upper,
                         const double *moving, Py_ssize_t k, double *out)
{
    d->nc = d->lo_count = d->hi_count = 0;
    d->k = k;
    for (Py_ssize_t j = 0; j < d->n; j++) {
        out[j] = dq[j];
        if (moving[j] == 0.0) continue;
        d->nc++;
        d->lo_count += isfinite(lower[j]) ? 1 : 0;
        d->hi_count += isfinite(upper[j]) ? 1 : 0;
    }
    Py_ssize_t nc = d->nc, rows = d->rows = k + d->lo_count + d->hi_count;
    return (size_t)(d->n + rows * nc + 2 * rows + rows * rows + 2 * nc
                    + nonnegative_qp_scratch(rows));
}

/* the dual's buffers in mem (dual_sizes doubles) */
static void dual_buffers(Dual *d, double *mem, const double *moving)
{
    Py_ssize_t nc = d->nc, rows = d->rows;
    d->cols = (Py_ssize_t *)mem;
    d->C = mem + d->n;
    d->h = d->C + rows * nc;
    d->y = d->h + rows;
    d->Q = d->y + rows;
    d->x0 = d->Q + rows * rows;
    d->z = d->x0 + nc;
    d->scratch = d->z + nc;
    Py_ssize_t c = 0;
    for (Py_ssize_t j = 0; j < d->n; j++)
        if (moving[j] != 0.0) d->cols[c++] = j;
}

/* L: H = Jw_c^T Jw_c + rho I factored on the moving joints (rho the mean of Jw_c^T Jw_c's
 * diagonal), the same for every dual of one projection (project_c): nc * nc doubles in L;
 * returns 0 only if the factorisation failed (not reached: H is positive definite) */
static int metric_factor(Mat Jw, const double *moving, double *L)
{
    Py_ssize_t n = Jw.n, nc = 0;
    Py_ssize_t cols[n > 0 ? n : 1];
    for (Py_ssize_t j = 0; j < n; j++)
        if (moving[j] != 0.0) cols[nc++] = j;
    double trace = 0.0;
    for (Py_ssize_t a = 0; a < nc; a++) {
        for (Py_ssize_t c = 0; c <= a; c++) {
            double acc = 0.0;
            for (Py_ssize_t i = 0; i < Jw.m; i++) acc += AT(Jw, i, cols[a]) * AT(Jw, i, cols[c]);
            L[a * nc + c] = L[c * nc + a] = acc;
        }
        trace += L[a * nc + a];
    }
    double rho = dmax(trace / (double)(nc > 0 ? nc : 1), 1e-12);
    return nc == 0 || cholesky_factor(L, nc, rho);
}

/* Row i of G into g (nc) and its h - G x0 into h[i]; *next walks the columns with a finite
 * bound of the kind of row i */
static void dual_row(Dual *d, Py_ssize_t i, Mat A, const double *b, const double *lower,
                     const double *upper, const double *moving, const double *dq,
                     Py_ssize_t *next, double *g)
{
    Py_ssize_t nc = d->nc, k = d->k;
    double hi_;
    if (i < k) {
        hi_ = b[i];
        for (Py_ssize_t j = 0; j < d->n; j++)
            if (moving[j] == 0.0) hi_ -= AT(A, i, j) * dq[j];
        for (Py_ssize_t a = 0; a < nc; a++) g[a] = AT(A, i, d->cols[a]);
    } else {
        for (Py_ssize_t a = 0; a < nc; a++) g[a] = 0.0;
        int upper_row = i >= k + d->lo_count;
        if (i == k || i == k + d->lo_count) *next = 0;
        const double *bound = upper_row ? upper : lower;
        while (!isfinite(bound[d->cols[*next]])) (*next)++;
        g[*next] = upper_row ? 1.0 : -1.0;
        hi_ = upper_row ? upper[d->cols[*next]] : -lower[d->cols[*next]];
        (*next)++;
    }
    for (Py_ssize_t a = 0; a < nc; a++) hi_ -= g[a] * d->x0[a];
    d->h[i] = hi_;
}

/* C = G L^-T row by row (forward substitution), r = h - G x0, and Q = C C^T */
static void dual_problem(Dual *d, Mat A, const double *b, const double *lower,
                         const double *upper, const double *moving, const double *dq)
{
    Py_ssize_t nc = d->nc, rows = d->rows, next = 0;
    for (Py_ssize_t i = 0; i < rows; i++) {
        double *g = d->C + i * nc;
        dual_row(d, i, A, b, lower, upper, moving, dq, &next, g);
        for (Py_ssize_t a = 0; a < nc; a++) {
            double acc = g[a];
            for (Py_ssize_t c = 0; c < a; c++) acc -= d->L[a * nc + c] * g[c];
            g[a] = acc / d->L[a * nc + a];
        }
    }
    for (Py_ssize_t i = 0; i < rows; i++)
        for (Py_ssize_t j = 0; j <= i; j++) {
            double acc = 0.0;
            for (Py_ssize_t a = 0; a < nc; a++) acc += d->C[i * nc + a] * d->C[j * nc + a];
            d->Q[i * rows + j] = d->Q[j * rows + i] = acc;
        }
}

/* The primal from the dual's y: z = -C^T y, x - x0 = L^-T z (back substitution), each moving
 * joint then within its bounds (the bounds are hard: rows that no velocity within them meets,
 * the dual unbounded but for its ridge, leave the answer on them, not beyond) */
static void dual_primal(const Dual *d, const double *lower, const double *upper, double *out)
{
    Py_ssize_t nc = d->nc, rows = d->rows;
    for (Py_ssize_t a = 0; a < nc; a++) {
        double acc = 0.0;
        for (Py_ssize_t i = 0; i < rows; i++) acc -= d->C[i * nc + a] * d->y[i];
        d->z[a] = acc;
    }
    for (Py_ssize_t a = nc - 1; a >= 0; a--) {
        double acc = d->z[a];
        for (Py_ssize_t c = a + 1; c < nc; c++) acc -= d->L[c * nc + a] * d->z[c];
        d->z[a] = acc / d->L[a * nc + a];
    }
    for (Py_ssize_t a = 0; a < nc; a++) {
        Py_ssize_t j = d->cols[a];
        out[j] = dmin(dmax(d->x0[a] + d->z[a], lower[j]), upper[j]);
    }
}

/* project_once_c on the rows and the finite bounds of [lower, upper] given (the others
 * -inf/inf): the dual's answer, each moving joint within those bounds. Returns the
 * passive-set solves, -1 when out of memory. */
static int project_dual(const double *dq, const double *L, Py_ssize_t n, Mat A, const double *b,
                        const double *lower, const double *upper, const double *moving,
                        double *out)
{
    Dual d;
    d.n = n;
    size_t size = dual_sizes(&d, dq, lower, upper, moving, A.m, out);
    double *mem = (double *)malloc(size * sizeof(double));
    if (!mem) return -1;
    dual_buffers(&d, mem, moving);
    d.L = (double *)L;  /* (read only) */
    for (Py_ssize_t a = 0; a < d.nc; a++) d.x0[a] = dq[d.cols[a]];
    dual_problem(&d, A, b, lower, upper, moving, dq);
    int solves = nonnegative_qp_c(d.Q, d.h, d.rows, 1e-13, d.y, d.scratch);
    dual_primal(&d, lower, upper, out);
    free(mem);
    return solves;
}

/* The bounds the answer x breaks (beyond 1e-12 (1 + |bound|)) join those in the dual (lo_in,
 * hi_in: the bound, or -inf/inf while it is not in); returns how many joined */
static int broken_bounds_join(const double *x, const double *lower, const double *upper,
                              const double *moving, Py_ssize_t n, double *lo_in, double *hi_in)
{
    int joined = 0;
    for (Py_ssize_t j = 0; j < n; j++) {
        if (moving[j] == 0.0) continue;
        if (lo_in[j] == -INFINITY && x[j] < lower[j] - 1e-12 * (1.0 + fabs(lower[j]))) {
            lo_in[j] = lower[j];
            joined++;
        }
        if (hi_in[j] == INFINITY && x[j] > upper[j] + 1e-12 * (1.0 + fabs(upper[j]))) {
            hi_in[j] = upper[j];
            joined++;
        }
    }
    return joined;
}

/* out = argmin (x - dq)^T H (x - dq), H = Jw_c^T Jw_c + rho I on the moving joints c (rho the
 * mean of H's diagonal), subject to A x <= b and lower <= x <= upper, the others at dq: as
 * constraints.project (its reference), on the dual of the Cholesky-whitened problem; when no
 * x meets them all, within the bounds. A bound enters the dual only once an answer breaks it:
 * the optimum of a convex problem with fewer constraints that meets the others is its optimum
 * (the speed and position bounds seldom bind where the rows do, and each bound in the dual is
 * one row more of it). Returns the passive-set solves, -1 when out of memory. */
static int project_once_c(const double *dq, const double *L, Py_ssize_t n, Mat A,
                          const double *b, const double *lower, const double *upper,
                          const double *moving, double *out)
{
    double *in = (double *)malloc((size_t)(2 * n + 1) * sizeof(double));
    if (!in) return -1;
    double *lo_in = in, *hi_in = in + n;
    for (Py_ssize_t j = 0; j < n; j++) {
        lo_in[j] = -INFINITY;
        hi_in[j] = INFINITY;
    }
    int solves = 0;
    for (Py_ssize_t round = 0; round <= 2 * n; round++) {
        int now = project_dual(dq, L, n, A, b, lo_in, hi_in, moving, out);
        if (now < 0) {
            solves = now;
            break;
        }
        solves += now;
        if (!broken_bounds_join(out, lower, upper, moving, n, lo_in, hi_in)) break;
    }
    for (Py_ssize_t j = 0; j < n && solves >= 0; j++)
        if (moving[j] != 0.0) out[j] = dmin(dmax(out[j], lower[j]), upper[j]);
    free(in);
    return solves;
}

/* The step the projection starts from when it had to correct dq (constraints.rest_target):
 * the least-norm velocity of the task motion Jw x the first projection x kept, plus dq's
 * self-motion (dq minus the least-norm velocity of its own task motion Jw dq, on the moving
 * joints) scaled by the share phi = |Jw x| / |Jw dq| of the task motion kept. A method's step
 * (SJT's per-joint scaling, a saturated step) carries self-motion along with its push on the
 * task; where the rows stop that push (a target inside an obstacle) its self-motion would go
 * on alone, and the push itself, projected again, would come out as self-motion that keeps the
 * contacts: the arm would drift in its null space. Writes into target (n) and returns 1, or 0
 * where it keeps dq (no task motion asked or kept whole, a singular Jw, out of memory). */
static int rest_target_c(const double *dq, Mat Jw, const double *moving, const double *x,
                         double *target)
{
    Py_ssize_t n = Jw.n, m = Jw.m;
    if (m == 0) return 0;
    double *S = (double *)malloc((size_t)(m * m + 4 * m) * sizeof(double));
    if (!S) return 0;
    double *t0 = S + m * m, *t1 = t0 + m, *w0 = t1 + m, *w1 = w0 + m;
    double asked = 0.0, kept = 0.0, trace = 0.0;
    for (Py_ssize_t i = 0; i < m; i++) {
        double a0 = 0.0, a1 = 0.0;
        for (Py_ssize_t j = 0; j < n; j++)
            if (moving[j] != 0.0) {
                a0 += AT(Jw, i, j) * dq[j];
                a1 += AT(Jw, i, j) * x[j];
            }
        t0[i] = a0;
        t1[i] = a1;
        asked += a0 * a0;
        kept += a1 * a1;
        for (Py_ssize_t r = 0; r <= i; r++) {
            double acc = 0.0;
            for (Py_ssize_t j = 0; j < n; j++)
                if (moving[j] != 0.0) acc += AT(Jw, i, j) * AT(Jw, r, j);
            S[i * m + r] = S[r * m + i] = acc;
        }
        trace += S[i * m + i];
    }
    double phi = asked > 0.0 ? sqrt(kept / asked) : 1.0;
    if (!(phi < 1.0) || !cholesky_factor(S, m, REST_RIDGE * dmax(trace / (double)m, 1e-300))) {
        free(S);
        return 0;
    }
    cholesky_substitute(S, m, t0, w0);
    cholesky_substitute(S, m, t1, w1);
    for (Py_ssize_t j = 0; j < n; j++) {
        target[j] = dq[j];
        if (moving[j] == 0.0) continue;
        double asked_j = 0.0, kept_j = 0.0;
        for (Py_ssize_t i = 0; i < m; i++) {
            asked_j += AT(Jw, i, j) * w0[i];
            kept_j += AT(Jw, i, j) * w1[i];
        }
        target[j] = kept_j + phi * (dq[j] - asked_j);
    }
    free(S);
    return 1;
}

/* project_once_c, from rest_target_c's start where the first projection corrected dq: the
 * stage's correction (constraints.project) */
static int project_c(const double *dq, Mat Jw, Mat A, const double *b, const double *lower,
                     const double *upper, const double *moving, double *out)
{
    Py_ssize_t n = Jw.n;
    double *L = (double *)malloc((size_t)(n * n + n + 1) * sizeof(double)), *target = L + n * n;
    if (!L) return -1;
    if (!metric_factor(Jw, moving, L)) {  /* not reached: H + rho I is positive definite */
        memcpy(out, dq, (size_t)n * sizeof(double));
        free(L);
        return 0;
    }
    int solves = project_once_c(dq, L, n, A, b, lower, upper, moving, out);
    int changed = 0;
    for (Py_ssize_t j = 0; j < n && !changed && solves >= 0; j++) changed = out[j] != dq[j];
    if (changed && rest_target_c(dq, Jw, moving, out, target)) {
        int again = project_once_c(target, L, n, A, b, lower, upper, moving, out);
        solves = again < 0 ? again : solves + again;
    }
    free(L);
    return solves;
}

/* nonnegative_qp(Q, r, y) -> int: y = argmin 1/2 y^T Q y + r^T y over y >= 0 */
PyObject *py_nonnegative_qp(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 3, "nonnegative_qp")) return NULL;
    Arg Qa = {0}, ra = {0}, ya = {0};
    PyObject *result = NULL;
    double *mem = NULL;
    if (acquire(args[0], &Qa, 0, 2, "Q") || acquire(args[1], &ra, 0, 1, "r")
        || acquire(args[2], &ya, 1, 1, "y"))
        goto done;
    Py_ssize_t k = length(&ra);
    Mat Qm = mat(&Qa);
    double *rv = vec(&ra, "r"), *yv = out_vec(&ya, "y");
    if (!rv || !yv) goto done;
    if (Qm.m != k || Qm.n != k || length(&ya) != k) {
        PyErr_Format(PyExc_ValueError, "Q (%zd, %zd), r (%zd,) and y (%zd,) do not fit", Qm.m,
                     Qm.n, k, length(&ya));
        goto done;
    }
    mem = (double *)malloc((size_t)(k * k + nonnegative_qp_scratch(k)) * sizeof(double));
    if (!mem) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < k; i++)
        for (Py_ssize_t j = 0; j < k; j++) mem[i * k + j] = AT(Qm, i, j);
    int solves = nonnegative_qp_c(mem, rv, k, 1e-13, yv, mem + k * k);
    result = PyLong_FromLong(solves);
done:
    free(mem);
    release(&Qa); release(&ra); release(&ya);
    return result;
}

/* A, b and (when bounded) lower, upper: a rows kernel's arguments 2 to 5, acquired in that
 * order; nonzero with the error set when one is not a float64 array of its rank */
static int acquire_rows(PyObject *const *args, int bounded, Arg *A, Arg *b, Arg *lo, Arg *hi)
{
    return acquire(args[2], A, 0, 2, "A") || acquire(args[3], b, 0, 1, "b")
           || (bounded && (acquire(args[4], lo, 0, 1, "lower")
                           || acquire(args[5], hi, 0, 1, "upper")));
}

/* project_rows(dq, Jw, A, b, lower, upper, moving, out) -> int */
PyObject *py_project_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 8, "project_rows")) return NULL;
    Arg dq = {0}, Jw = {0}, A = {0}, b = {0}, lo = {0}, hi = {0}, mv = {0}, out = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &dq, 0, 1, "dq") || acquire(args[1], &Jw, 0, 2, "Jw")
        || acquire_rows(args, 1, &A, &b, &lo, &hi) || acquire(args[6], &mv, 0, 1, "moving")
        || acquire(args[7], &out, 1, 1, "out"))
        goto done;
    Mat Jm = mat(&Jw), Am = mat(&A);
    Py_ssize_t n = length(&dq);
    if (Jm.n != n || Am.n != n || length(&b) != Am.m || length(&lo) != n || length(&hi) != n
        || length(&mv) != n || length(&out) != n) {
        PyErr_Format(PyExc_ValueError, "dq (%zd,), Jw (%zd, %zd), A (%zd, %zd), b (%zd,), lower, "
                     "upper, moving and out (n,) do not fit", n, Jm.m, Jm.n, Am.m, Am.n,
                     length(&b));
        goto done;
    }
    double *dv = vec(&dq, "dq"), *bv = vec(&b, "b"), *lv = vec(&lo, "lower");
    double *hv = vec(&hi, "upper"), *mvv = vec(&mv, "moving"), *ov = out_vec(&out, "out");
    if (!dv || !bv || !lv || !hv || !mvv || !ov) goto done;
    int solves;
    Py_BEGIN_ALLOW_THREADS
    solves = project_c(dv, Jm, Am, bv, lv, hv, mvv, ov);
    Py_END_ALLOW_THREADS
    if (solves < 0) {
        PyErr_NoMemory();
        goto done;
    }
    result = PyLong_FromLong(solves);
done:
    release(&dq); release(&Jw); release(&A); release(&b); release(&lo); release(&hi);
    release(&mv); release(&out);
    return result;
}

/* Whether the step (rad, over dt) meets every row A q_dot <= b (within BOUND_TOL (1 + |b|)) */
static int rows_hold(Mat A, const double *b, const double *step, double dt)
{
    for (Py_ssize_t i = 0; i < A.m; i++) {
        double acc = -b[i];
        for (Py_ssize_t j = 0; j < A.n; j++) acc += AT(A, i, j) * step[j] / dt;
        if (acc > BOUND_TOL * (1.0 + fabs(b[i]))) return 0;
    }
    return 1;
}

/* Whether the step (rad, over dt) lies within [lower, upper] (rad/s, within BOUND_TOL) */
static int bounds_hold(const double *lower, const double *upper, const double *step, double dt,
                       Py_ssize_t n)
{
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = step[j] / dt;
        if (v < lower[j] - BOUND_TOL || v > upper[j] + BOUND_TOL) return 0;
    }
    return 1;
}

/* The metric's rows Jw = sw J mask (m x n, row-major), the step's velocity dq = step / dt and
 * the moving joints (1 where the mask is not 0) */
static void weighted_rows(Mat J, const double *sw, const double *mask, const double *step,
                          double dt, double *Jw, double *dq, double *moving)
{
    Py_ssize_t m = J.m, n = J.n;
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < n; j++) Jw[i * n + j] = sw[i] * AT(J, i, j) * mask[j];
    for (Py_ssize_t j = 0; j < n; j++) {
        dq[j] = step[j] / dt;
        moving[j] = mask[j] != 0.0 ? 1.0 : 0.0;
    }
}

/* A kernel step (step, written by step_c) against a user's general rows A q_dot <= b and
 * bounds [lower, upper] (rad/s; -inf/inf where none): 0 when it meets them all (step
 * untouched), -1 when it breaks one of the bounds (the caller's whole constraint stage must
 * saturate it), else 1 with the method's velocity scaled as a whole into the kernel's own box
 * of this step (method_velocity, scaled_into_c: SNS's first candidate, not its result, which
 * jumps with q where two sets of held joints scale the task alike) projected onto the rows within
 * those bounds and that box (project_c in the metric of the weighted task rows, the moving
 * joints of the mask; every joint inside its range exactly onto a limit it reaches); -2 when
 * out of memory (constraints.ConstraintStage.enforce, constraints.scaled_into). */
static int rows_step_c(Mat J, const double *q, Mat A, const double *b, const double *lower,
                       const double *upper, double *work, double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    double dt = work[P_DT];
    const double *mask = work + (Py_ssize_t)work[P_MASK];
    const double *sw = work + (Py_ssize_t)work[P_ROWS];
    const double *box_lo = work + (Py_ssize_t)work[P_CLAMPED] + n, *box_hi = box_lo + n;
    if (!bounds_hold(lower, upper, step, dt, n)) return -1;
    if (rows_hold(A, b, step, dt)) return 0;
    double *mem = (double *)malloc((size_t)(m * n + 5 * n + 1) * sizeof(double));
    if (!mem) return -2;
    double *Jw = mem, *dq = Jw + m * n, *lo = dq + n, *hi = lo + n, *moving = hi + n;
    double *out = moving + n;
    weighted_rows(J, sw, mask, step, dt, Jw, dq, moving);
    /* the box cut the kernel's step (saturate_c): the method's velocity scaled into it instead
     * of SNS's result (out as scratch) */
    double *held = work + (Py_ssize_t)work[P_CLAMPED];
    int cut = !(work[INFO + I_SCALE] >= 1.0);
    for (Py_ssize_t j = 0; j < n && !cut; j++) cut = held[j] != 0.0;
    if (cut) {  /* what the step reports follows: that scale, no joint held */
        work[INFO + I_SCALE] = scaled_into_c(method_velocity(work, m, n), box_lo, box_hi, mask,
                                             n, out, dq);
        for (Py_ssize_t j = 0; j < n; j++) held[j] = 0.0;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        lo[j] = dmax(box_lo[j], lower[j]);
        hi[j] = dmin(box_hi[j], upper[j]);
    }
    Mat Jm = {Jw, m, n, n, 1};
    int solves = project_c(dq, Jm, A, b, lo, hi, moving, out);
    if (solves < 0) {
        free(mem);
        return -2;
    }
    for (Py_ssize_t j = 0; j < n; j++) step[j] = out[j] * dt;
    exact_position(q, work, step);
    free(mem);
    return 1;
}

/* Whether a limit's rows A, b and bounds lower, upper (any may be unset) hold no NaN, and A no
 * inf (inf in b or a bound means no bound): a NaN bounds nothing, so the joints would move
 * freely. Sets ValueError otherwise (the caller names the limit). */
static int rows_finite(Mat A, const Arg *b, const Arg *lo, const Arg *hi)
{
    for (Py_ssize_t i = 0; i < A.m; i++)
        for (Py_ssize_t j = 0; j < A.n; j++)
            if (!isfinite(AT(A, i, j))) goto bad;
    const Arg *vectors[3] = {b, lo, hi};
    for (int k = 0; k < 3; k++) {
        const Arg *a = vectors[k];
        if (!a->view.buf) continue;
        Py_ssize_t len = length(a), stride = a->view.ndim ? a->view.strides[0] / 8 : 1;
        const double *x = (const double *)a->view.buf;
        for (Py_ssize_t i = 0; i < len; i++)
            if (isnan(x[i * stride])) goto bad;
    }
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "a limit's rows or bounds hold NaN (or A holds inf): a "
                    "row or bound that bounds nothing would let the joints move freely");
    return -1;
}

/* rows_step(J, q, A, b, lower, upper, work, step) -> int (rows_step_c) */
PyObject *py_rows_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 8, "rows_step")) return NULL;
    Arg J = {0}, q = {0}, A = {0}, b = {0}, lo = {0}, hi = {0}, work = {0}, step = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &q, 0, 1, "q")
        || acquire_rows(args, 1, &A, &b, &lo, &hi) || acquire(args[6], &work, 1, 1, "work")
        || acquire(args[7], &step, 1, 1, "step"))
        goto done;
    Mat Jm = mat(&J), Am = mat(&A);
    Py_ssize_t n = Jm.n;
    if (Am.n != n || length(&b) != Am.m || length(&lo) != n || length(&hi) != n
        || length(&step) != n) {
        PyErr_Format(PyExc_ValueError, "J (%zd, %zd), A (%zd, %zd), b (%zd,), lower, upper and "
                     "step (n,) do not fit", Jm.m, n, Am.m, Am.n, length(&b));
        goto done;
    }
    if (check_work(&work, Jm.m, n, length(&q)) || rows_finite(Am, &b, &lo, &hi)) goto done;
    if (((const double *)work.view.buf)[P_SMOOTH] != 0.0) {
        PyErr_SetString(PyExc_ValueError, "rows_step: a work vector with the acceleration/jerk "
                        "stage (Layout(..., smooth=True)) keeps no step box");
        goto done;
    }
    double *qv = vec(&q, "q"), *bv = vec(&b, "b"), *lv = vec(&lo, "lower");
    double *hv = vec(&hi, "upper"), *wv = out_vec(&work, "work"), *sv = out_vec(&step, "step");
    if (!qv || !bv || !lv || !hv || !wv || !sv) goto done;
    int status;
    Py_BEGIN_ALLOW_THREADS
    status = rows_step_c(Jm, qv, Am, bv, lv, hv, wv, sv);
    Py_END_ALLOW_THREADS
    if (status == -2) {
        PyErr_NoMemory();
        goto done;
    }
    result = PyLong_FromLong(status);
done:
    release(&J); release(&q); release(&A); release(&b); release(&lo); release(&hi);
    release(&work); release(&step);
    return result;
}

/* smooth_rows_c's velocities (n each): the step's dq, the box of a round [lo, hi], the moving
 * joints, the projection's result, the hard box (the stage's within the user's bounds), the
 * acceleration and jerk limits' box around the previous state, the acceleration limits' box
 * around the previous velocity, and the box the widening rounds start from (the first, then
 * the second) */
typedef struct {
    double *dq, *lo, *hi, *moving, *res, *hard_lo, *hard_hi, *soft_lo, *soft_hi, *acc_lo,
        *acc_hi;
    const double *base_lo, *base_hi;
    int jerk;  /* whether jerk limits narrow the smoothness box */
} SmoothBoxes;

/* The hard box (the stage's, within the user's bounds when given), the smoothness box and the
 * acceleration box around the previous state; 0 when a user's bound leaves nothing of the
 * hard box on some joint. */
static int smooth_boxes(SmoothBoxes *x, const double *lower, const double *upper,
                        const double *previous, const double *work, Py_ssize_t n)
{
    const double *S = work + (Py_ssize_t)work[P_SMOOTH];
    const double *hlo = S + SM_HARD_LO * n, *hhi = S + SM_HARD_HI * n, *acc = S + SM_ACC * n;
    double dt = work[P_DT];
    x->base_lo = x->soft_lo;
    x->base_hi = x->soft_hi;
    x->jerk = work[P_JERK] != 0.0;
    for (Py_ssize_t j = 0; j < n; j++) {
        x->hard_lo[j] = lower ? dmax(hlo[j], lower[j]) : hlo[j];
        x->hard_hi[j] = upper ? dmin(hhi[j], upper[j]) : hhi[j];
        if (x->hard_lo[j] > x->hard_hi[j]) return 0;
        double by[2];  /* (which limit set each bound: not needed here) */
        smoothness_limits(previous[j], previous[n + j], acc[j], S[SM_JERK * n + j],
                          S[SM_JERK_SPEED * n + j], dt, x->jerk, x->soft_lo + j, x->soft_hi + j,
                          by, by + 1);
        x->acc_lo[j] = previous[j] - acc[j] * dt;
        x->acc_hi[j] = previous[j] + acc[j] * dt;
    }
    return 1;
}

/* The base box widened `widen` times around its centre within the hard box (INFINITY: the hard
 * box alone); returns 2 when the hard box lies beyond the base box on some joint (it wins
 * there: the joint takes the hard box's bound nearest the base box), else 1. */
static int widened_box(SmoothBoxes *x, double widen, Py_ssize_t n)
{
    int status = 1;
    for (Py_ssize_t j = 0; j < n; j++) {
        double l = x->hard_lo[j], u = x->hard_hi[j];
        if (isfinite(widen)) {
            double c = 0.5 * (x->base_lo[j] + x->base_hi[j]);
            double r = 0.5 * (x->base_hi[j] - x->base_lo[j]);
            double sl = dmax(l, c - widen * r), su = dmin(u, c + widen * r);
            if (sl <= su) {
                l = sl;
                u = su;
            } else {  /* the box lies wholly below the hard box (then l, l) or above it */
                status = 2;
                l = u = c + widen * r < l ? l : u;
            }
        }
        x->lo[j] = l;
        x->hi[j] = u;
    }
    return status;
}

/* Whether the velocity x meets every row (to the dual's ridge: 1e-9 (1 + |b|)) */
static int rows_met(Mat A, const double *b, const double *x)
{
    for (Py_ssize_t i = 0; i < A.m; i++) {
        double acc = -b[i];
        for (Py_ssize_t j = 0; j < A.n; j++) acc += AT(A, i, j) * x[j];
        if (acc > 1e-9 * (1.0 + fabs(b[i]))) return 0;
    }
    return 1;
}

/* The factor by which the base box, widened around its centre, takes in the hard box
 * (INFINITY where the box has no width or the hard box no bound) */
static double covering_factor(const SmoothBoxes *x, Py_ssize_t n)
{
    double w = 1.0;
    for (Py_ssize_t j = 0; j < n; j++) {
        double c = 0.5 * (x->base_lo[j] + x->base_hi[j]);
        double r = 0.5 * (x->base_hi[j] - x->base_lo[j]);
        double reach = dmax(c - x->hard_lo[j], x->hard_hi[j] - c);
        if (reach > 0.0) w = dmax(w, r > 0.0 ? reach / r : INFINITY);
    }
    return w;
}

/* The step projected (project_c, metric Jw) onto the rows within the base box widened w times
 * and the hard box: 0 when the rows then hold, 1 when not, -2 when out of memory. */
static int projected_within(SmoothBoxes *x, Mat Jw, Mat A, const double *b, double w,
                            int *status)
{
    if (widened_box(x, w, Jw.n) == 2) *status = 2;
    if (project_c(x->dq, Jw, A, b, x->lo, x->hi, x->moving, x->res) < 0) return -2;
    return rows_met(A, b, x->res) ? 0 : 1;
}

/* The step projected onto the rows within the smoothness box; where they do not hold there,
 * within the acceleration box (the jerk limits yield: most rows an arm cannot meet within its
 * jerk limits it can meet within its acceleration limits), else within that box widened until
 * the rows hold (2, 4, ... 32 times, then the hard box alone) and then only as far as they
 * need (the factor bisected between the last two rounds): the limits yield as little as the
 * rows ask, not as far as the round's box lets the task pull. 1, or 2 when the smoothness box
 * had to give way; -2 when out of memory. */
static int smooth_projection(SmoothBoxes *x, Mat Jw, Mat A, const double *b)
{
    int status = 1, missed = projected_within(x, Jw, A, b, 1.0, &status);
    if (missed <= 0) return missed < 0 ? -2 : status;
    status = 2;
    if (x->jerk) {
        x->base_lo = x->acc_lo;
        x->base_hi = x->acc_hi;
        missed = projected_within(x, Jw, A, b, 1.0, &status);
        if (missed <= 0) return missed < 0 ? -2 : status;
    }
    int round = 1;
    double w = 2.0;
    for (;; round++, w *= 2.0) {
        if (round == SMOOTH_WIDEN_ROUNDS) w = INFINITY;
        missed = projected_within(x, Jw, A, b, w, &status);
        if (missed < 0) return -2;
        if (!missed || round == SMOOTH_WIDEN_ROUNDS) break;
    }
    /* the rows fail within lo times the box and hold within hi times (the hard box: the factor
     * that takes it all in) */
    double lo = round == SMOOTH_WIDEN_ROUNDS ? ldexp(1.0, SMOOTH_WIDEN_ROUNDS - 1) : 0.5 * w;
    double hi = isfinite(w) ? w : covering_factor(x, Jw.n);
    if (!(hi > lo) || !isfinite(hi)) return status;
    missed = 0;  /* (x->res: the projection within w times the box, or the hard box) */
    for (int k = 0; k < SMOOTH_BISECTIONS && hi > SMOOTH_PRECISION * lo; k++) {
        double mid = sqrt(lo * hi);
        missed = projected_within(x, Jw, A, b, mid, &status);
        if (missed < 0) return -2;
        if (missed) lo = mid; else hi = mid;
    }
    if (missed && projected_within(x, Jw, A, b, hi, &status) < 0) return -2;
    return status;
}

/* The projected velocity becomes the step (every joint inside its range exactly onto a limit
 * it reaches), SM_OUT and the motion state (SM_DQ, SM_DDQ); joints outside the smoothness box
 * are marked in SM_TORN. */
static void smooth_commit(const SmoothBoxes *x, const double *q, const double *previous,
                          Py_ssize_t n, double *work, double *step)
{
    double dt = work[P_DT];
    double *S = work + (Py_ssize_t)work[P_SMOOTH];
    double *pdq = S + SM_DQ * n, *pddq = S + SM_DDQ * n;
    double *out = S + SM_OUT * n, *torn = S + SM_TORN * n;
    for (Py_ssize_t j = 0; j < n; j++) step[j] = x->res[j] * dt;
    exact_position(q, work, step);
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = step[j] / dt;
        if (v < x->soft_lo[j] - BOUND_TOL || v > x->soft_hi[j] + BOUND_TOL) torn[j] = 1.0;
        out[j] = v;
        pddq[j] = (v - previous[j]) / dt;
        pdq[j] = v;
    }
}

/* The velocity smooth_rows_c projects: the stage's wanted velocity before its move within the
 * smoothness box (SM_DESIRED), or, where its hard box cut the method's (braked) velocity, that
 * velocity scaled as a whole into the hard box (scaled_into_c: SNS's first candidate, continuous
 * in the step, where SNS's choice of held joints jumps with q; then the step reports that scale
 * and no joint held), as rows_step_c does: a blocked arm's correction then comes to rest. */
static void smooth_start(SmoothBoxes *x, double *work, Py_ssize_t m, Py_ssize_t n)
{
    const double *S = work + (Py_ssize_t)work[P_SMOOTH];
    double *held = work + (Py_ssize_t)work[P_CLAMPED];
    int cut = !(work[INFO + I_SCALE] >= 1.0);
    for (Py_ssize_t j = 0; j < n && !cut; j++) cut = held[j] != 0.0;
    if (!cut) {
        memcpy(x->dq, S + SM_DESIRED * n, (size_t)n * sizeof(double));
        return;
    }
    work[INFO + I_SCALE] = scaled_into_c(method_velocity(work, m, n), x->hard_lo, x->hard_hi,
                                         work + (Py_ssize_t)work[P_MASK], n, x->res, x->dq);
    for (Py_ssize_t j = 0; j < n; j++) held[j] = 0.0;
}

/* A step of the compiled acceleration/jerk stage (step and the stage's part of work, written by
 * smooth_stage_c) against a user's general rows A q_dot <= b and bounds [lower, upper] (rad/s;
 * -inf/inf where none; both NULL: none at all); `previous` (2 nv) is the motion state the step
 * started from (the velocity, then the acceleration, commanded the step before). 0 when the
 * step meets them all (step and work untouched); -1 when a user's bound leaves nothing of the
 * stage's hard box on some joint (the caller's whole constraint stage must weigh them); else
 * the stage's wanted velocity (smooth_start: not the step, which moved toward it as far as the
 * smoothness box allows, so that a blocked arm's correction has a fixed point at rest) is
 * projected (project_c in the metric of the weighted task rows, the moving joints of the mask)
 * onto the rows within the user's bounds, the stage's hard box (positions with their braking,
 * speeds) and its smoothness box: 1 when that holds; 2 when no velocity in it meets the rows,
 * and the hard limits and the rows win (the stage's rule): the smoothness box is widened around
 * its centre only as far as the rows need (smooth_projection), and the joints that leave it
 * are marked in SM_TORN. After a projection every joint
 * inside its range lands exactly on a limit it reaches, SM_OUT holds the new velocity and the
 * motion state (SM_DQ, SM_DDQ) the one it commands. -2 when out of memory. */
static int smooth_rows_c(Mat J, const double *q, Mat A, const double *b, const double *lower,
                         const double *upper, const double *previous, double *work,
                         double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    double dt = work[P_DT];
    if ((!lower || bounds_hold(lower, upper, step, dt, n)) && rows_hold(A, b, step, dt)) return 0;
    double *mem = (double *)malloc((size_t)(m * n + 12 * n + 1) * sizeof(double));
    if (!mem) return -2;
    SmoothBoxes x = {0};
    x.dq = mem + m * n;
    x.lo = x.dq + n;
    x.hi = x.lo + n;
    x.moving = x.hi + n;
    x.res = x.moving + n;
    x.hard_lo = x.res + n;
    x.hard_hi = x.hard_lo + n;
    x.soft_lo = x.hard_hi + n;
    x.soft_hi = x.soft_lo + n;
    x.acc_lo = x.soft_hi + n;
    x.acc_hi = x.acc_lo + n;
    weighted_rows(J, work + (Py_ssize_t)work[P_ROWS], work + (Py_ssize_t)work[P_MASK], step, dt,
                  mem, x.dq, x.moving);
    if (!smooth_boxes(&x, lower, upper, previous, work, n)) {
        free(mem);
        return -1;
    }
    smooth_start(&x, work, m, n);
    Mat Jm = {mem, m, n, n, 1};
    int status = smooth_projection(&x, Jm, A, b);
    if (status >= 0) smooth_commit(&x, q, previous, n, work, step);
    free(mem);
    return status;
}

/* smooth_rows_step(J, q, A, b, lower, upper, previous, work, step) -> int (smooth_rows_c;
 * lower and upper both None: no bounds, two buffers fewer to acquire) */
PyObject *py_smooth_rows_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 9, "smooth_rows_step")) return NULL;
    Arg J = {0}, q = {0}, A = {0}, b = {0}, lo = {0}, hi = {0}, pv = {0}, work = {0};
    Arg step = {0};
    PyObject *result = NULL;
    int bounded = args[4] != Py_None || args[5] != Py_None;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &q, 0, 1, "q")
        || acquire_rows(args, bounded, &A, &b, &lo, &hi)
        || acquire(args[6], &pv, 0, 1, "previous") || acquire(args[7], &work, 1, 1, "work")
        || acquire(args[8], &step, 1, 1, "step"))
        goto done;
    Mat Jm = mat(&J), Am = mat(&A);
    Py_ssize_t n = Jm.n;
    if (Am.n != n || length(&b) != Am.m || (bounded && (length(&lo) != n || length(&hi) != n))
        || length(&pv) != 2 * n || length(&step) != n) {
        PyErr_Format(PyExc_ValueError, "J (%zd, %zd), A (%zd, %zd), b (%zd,), lower, upper, "
                     "step (n,) and previous (2 n,) do not fit", Jm.m, n, Am.m, Am.n,
                     length(&b));
        goto done;
    }
    if (check_work(&work, Jm.m, n, length(&q)) || rows_finite(Am, &b, &lo, &hi)) goto done;
    double *wv = out_vec(&work, "work");
    if (!wv) goto done;
    if (!(wv[P_SMOOTH] > 0.0)) {
        PyErr_SetString(PyExc_ValueError, "work has no acceleration/jerk stage "
                        "(Layout(..., smooth=True))");
        goto done;
    }
    double *qv = vec(&q, "q"), *bv = vec(&b, "b");
    double *lv = bounded ? vec(&lo, "lower") : NULL, *hv = bounded ? vec(&hi, "upper") : NULL;
    double *pvv = vec(&pv, "previous"), *sv = out_vec(&step, "step");
    if (!qv || !bv || (bounded && (!lv || !hv)) || !pvv || !sv) goto done;
    int status;
    Py_BEGIN_ALLOW_THREADS
    status = smooth_rows_c(Jm, qv, Am, bv, lv, hv, pvv, wv, sv);
    Py_END_ALLOW_THREADS
    if (status == -2) {
        PyErr_NoMemory();
        goto done;
    }
    result = PyLong_FromLong(status);
done:
    release(&J); release(&q); release(&A); release(&b); release(&lo); release(&hi);
    release(&pv); release(&work); release(&step);
    return result;
}
