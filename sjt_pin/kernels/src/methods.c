/* The CLIK mappings of one step: the transpose family (JT eq. 10, SJT eq. 21 and its damped
 * feedback) and the least-squares family (JP eq. 8, DLS), with feed-forward and posture. */

#include "kernels.h"

/* (W J_j)^T v = sum_i w_i J_ij v_i: column j of the weighted rows against v */
static inline double weighted_column_dot(Mat J, const double *sw, const double *v, Py_ssize_t j)
{
    double acc = 0.0;
    for (Py_ssize_t i = 0; i < J.m; i++) acc += sw[i] * AT(J, i, j) * v[i];
    return acc;
}

/* -- the step kernels ------------------------------------------------------------------------- */

/* three p x p scratch matrices after the scratch vectors, p = min(m, n) */
static double *matrices(double *work, Py_ssize_t m, Py_ssize_t n)
{
    return work + (Py_ssize_t)work[P_SCRATCH] + 4 * m + 6 * n;
}

/* Rows that end with n rows of the identity (a posture task, weighted by sw): the n x n normal
 * matrix is diagonal plus rank m_t, Dg + U U^T with U (n x m_t), and the Woodbury identity
 * (Dg + U U^T)^-1 = Dg^-1 - Dg^-1 U (I + U^T Dg^-1 U)^-1 U^T Dg^-1 solves it with an m_t x m_t
 * Cholesky: linear in n. x = (Dg + U U^T)^-1 rhs; entries with Dg = 0 are left out (x = 0).
 * U, Dg live in `space` (n m_t + m_t^2 + n + 2 m_t doubles). */
static void woodbury(const double *U, const double *Dg, Py_ssize_t n, Py_ssize_t mt,
                     const double *rhs, double *x, double *space)
{
    double *S = space, *t = space + mt * mt, *t2 = t + mt;
    for (Py_ssize_t a = 0; a < mt; a++) {
        t[a] = 0.0;
        for (Py_ssize_t b = 0; b < mt; b++) S[a * mt + b] = a == b ? 1.0 : 0.0;
    }
    /* one pass over the joints (U's rows in order): x = Dg^-1 rhs, t = U^T x and the lower
     * triangle of S = I + U^T Dg^-1 U */
    for (Py_ssize_t j = 0; j < n; j++) {
        if (!(Dg[j] > 0.0)) {
            x[j] = 0.0;
            continue;
        }
        const double *u = U + j * mt;
        double xj = x[j] = rhs[j] / Dg[j], inverse = 1.0 / Dg[j];
        for (Py_ssize_t a = 0; a < mt; a++) {
            t[a] += u[a] * xj;
            double ua = u[a] * inverse;
            for (Py_ssize_t b = 0; b <= a; b++) S[a * mt + b] += ua * u[b];
        }
    }
    for (Py_ssize_t a = 0; a < mt; a++)
        for (Py_ssize_t b = 0; b < a; b++) S[b * mt + a] = S[a * mt + b];
    cholesky_solve_c(S, mt, 0.0, t, t2);
    for (Py_ssize_t j = 0; j < n; j++) {
        if (!(Dg[j] > 0.0)) continue;
        double acc = 0.0;
        for (Py_ssize_t a = 0; a < mt; a++) acc += U[j * mt + a] * t2[a];
        x[j] -= acc / Dg[j];
    }
}

/* whether the rows end with n identity rows and the Woodbury scratch fits in the matrices'
 * space (3 p^2 doubles, p = n here) */
static Py_ssize_t identity_block(const double *work, Py_ssize_t m, Py_ssize_t n)
{
    Py_ssize_t ident = (Py_ssize_t)work[P_IDENTITY_ROWS];
    if (ident != n || m <= n) return -1;
    Py_ssize_t mt = m - n;
    if (n * mt + mt * mt + 2 * mt + n > 3 * n * n) return -1;
    return mt;
}

/* (W^2 J_j)^T v = sum_i w_i^2 J_ij v_i: column j of J^T W^2 against v */
static inline double squared_weight_column_dot(Mat J, const double *sw, const double *v,
                                               Py_ssize_t j)
{
    double acc = 0.0;
    for (Py_ssize_t i = 0; i < J.m; i++) acc += sw[i] * sw[i] * AT(J, i, j) * v[i];
    return acc;
}

/* step += dt D J_w^T (J_w D J_w^T + (mu^2 + extra) I)^-1 (sw v) (m x m solve when m <= n), or
 * the same as dt sqrt(D) (G + (mu^2 + extra) I)^-1 sqrt(D) J_w^T (sw v) (n x n) */
void damped_solve(Mat J, const double *v, const double *sw, const double *alpha,
                  double *work, double dt, double *step, double extra)
{
    Py_ssize_t m = J.m, n = J.n;
    double *A = matrices(work, m, n);
    double mu2 = work[P_MU] * work[P_MU] + extra;
    Py_ssize_t start = (Py_ssize_t)work[P_SCRATCH] + m + 3 * n;
    Py_ssize_t mt = identity_block(work, m, n);
    if (mt >= 0) {  /* task rows, then posture rows: diagonal plus rank m_t */
        double *rhs = work + start, *x = work + start + n;
        double *U = A, *Dg = A + n * mt, *space = Dg + n;
        for (Py_ssize_t j = 0; j < n; j++) {
            double root = sqrt(alpha[j]), acc = 0.0;
            for (Py_ssize_t a = 0; a < mt; a++) {
                U[j * mt + a] = root * sw[a] * AT(J, a, j);
                acc += sw[a] * sw[a] * AT(J, a, j) * v[a];
            }
            double wp = sw[mt + j] * sw[mt + j];
            Dg[j] = alpha[j] * wp + mu2;
            rhs[j] = root * (acc + wp * v[mt + j]);
        }
        woodbury(U, Dg, n, mt, rhs, x, space);
        for (Py_ssize_t j = 0; j < n; j++) step[j] += dt * sqrt(alpha[j]) * x[j];
        return;
    }
    gram(J, sw, alpha, m <= n, A);
    if (m <= n) {
        double *rhs = work + start, *y = work + start + m;
        for (Py_ssize_t i = 0; i < m; i++) rhs[i] = sw[i] * v[i];
        cholesky_solve_c(A, m, mu2, rhs, y);
        for (Py_ssize_t j = 0; j < n; j++)
            step[j] += dt * alpha[j] * weighted_column_dot(J, sw, y, j);
    } else {
        double *rhs = work + start, *x = work + start + n;
        for (Py_ssize_t j = 0; j < n; j++)
            rhs[j] = sqrt(alpha[j]) * squared_weight_column_dot(J, sw, v, j);
        cholesky_solve_c(A, n, mu2, rhs, x);
        for (Py_ssize_t j = 0; j < n; j++) step[j] += dt * sqrt(alpha[j]) * x[j];
    }
}

/* The weighted error of the transpose mappings: kew = K W e (per row), and on the error rows
 * (those before the posture's) |e|^2, |W e|^2 into r and |K W e|^2 returned. */
static double weighted_error(const double *e, const double *sw, const double *k, Py_ssize_t m,
                             Py_ssize_t error_rows, double *kew, Core *r)
{
    double kew_sq = 0.0;
    for (Py_ssize_t i = 0; i < m; i++) {
        double ew = sw[i] * e[i];
        kew[i] = k[i] * ew;
        if (i < error_rows) {
            r->e_sq += e[i] * e[i];
            r->ew_sq += ew * ew;
            kew_sq += kew[i] * kew[i];
        }
    }
    return kew_sq;
}

/* The column scales on the joints of mask: alpha_j = 1 / max(|W J_j|^2, length^2) (SJT eq. 21's
 * D; 0 for a column below col_tol), s = alpha for the scaled mappings else the mask; step_j =
 * (W J_j)^T K W e, unscaled. Returns tr(J S J^T) in *trace, the stall ratio's numerator
 * sum s_j (task part)^2 in *stall, and max sqrt(|W J_j|^2) s_j (the Levenberg-Marquardt
 * term's curvature) in *curvature. */
static void column_scales(Mat J, const double *sw, const double *kew, const double *mask,
                          const double *work, double *alpha, double *s, double *step,
                          double *trace, double *stall, double *curvature)
{
    Py_ssize_t m = J.m, n = J.n, error_rows = (Py_ssize_t)work[P_ERROR_ROWS];
    double tol = work[P_COL_TOL], length2 = work[P_LENGTH2];
    int scaled = work[P_SCALED] != 0.0;
    /* rows that end with n identity rows (a posture): column j has one entry there, row
     * mt + j, so only the mt task rows are summed (the zeros add nothing) */
    Py_ssize_t mt = identity_block(work, m, n), dense = mt >= 0 ? mt : m;
    for (Py_ssize_t j = 0; j < n; j++) {
        double norm = 0.0, acc = 0.0, acc_task = 0.0;
        if (mask[j] != 0.0) {
            for (Py_ssize_t i = 0; i < dense; i++) {
                double wij = sw[i] * AT(J, i, j);
                norm += wij * wij;
                acc += wij * kew[i];
                if (i < error_rows) acc_task += wij * kew[i];
            }
            if (mt >= 0) {
                double wij = sw[mt + j];
                norm += wij * wij;
                acc += wij * kew[mt + j];
                if (mt + j < error_rows) acc_task += wij * kew[mt + j];
            }
        }
        alpha[j] = norm > tol ? sjt_alpha(norm, length2) : 0.0;
        s[j] = scaled ? alpha[j] : mask[j];
        *trace += s[j] * norm;
        *stall += s[j] * acc_task * acc_task;
        if (norm > tol) *curvature = dmax(*curvature, sqrt(norm) * s[j]);
        step[j] = acc;
    }
}

/* The "auto" gain's lambda_hat >= lambda_max(W J S J^T W) of the transpose loop (loop_bound_c on
 * the Gram matrix; with posture rows the task block's bound plus the posture's diagonal), plus
 * the Levenberg-Marquardt term lm |W e| curvature (1/s times dt gives the loop's eigenvalue). */
static double transpose_bound(Mat J, const double *sw, const double *s, double *work,
                              double ew_sq, double curvature)
{
    Py_ssize_t m = J.m, n = J.n;
    double bound, *A = matrices(work, m, n);
    Py_ssize_t mt = (Py_ssize_t)work[P_IDENTITY_ROWS] == n && m > n ? m - n : -1;
    if (mt >= 0) {
        /* lambda_max of the stacked loop matrix <= the task block's + the posture block's
         * (diagonal: s_j w_j), for PSD block matrices */
        Mat task = {J.p, mt, n, J.s0, J.s1};
        Py_ssize_t p = mt < n ? mt : n;
        double posture = 0.0;
        for (Py_ssize_t j = 0; j < n; j++)
            posture = dmax(posture, s[j] * sw[mt + j] * sw[mt + j]);
        gram(task, sw, s, mt <= n, A);
        bound = loop_bound_c(A, p, BOUND_PRODUCTS, A + p * p, A + 2 * p * p) + posture;
    } else {
        Py_ssize_t p = m < n ? m : n;
        gram(J, sw, s, m <= n, A);
        bound = loop_bound_c(A, p, BOUND_PRODUCTS, A + p * p, A + 2 * p * p);
    }
    return bound + work[P_LM] * sqrt(ew_sq) * curvature;
}

/* The transpose step (rad) from the unscaled step_j = (W J_j)^T K W e: damped (the feedback
 * v = gain K e + ff through damped_solve, damping lm sqrt(|W e|^2 max alpha)), else
 * dt gain s_j step_j plus the feed-forward mapped by the transpose (S J^T W^2 ff) or damped. */
static void transpose_apply(Mat J, const double *e, const double *ff, int has_ff,
                            const double *alpha, const double *s, double *work, double gain,
                            double ew_sq, double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    double dt = work[P_DT];
    Py_ssize_t rows = (Py_ssize_t)work[P_ROWS], scratch = (Py_ssize_t)work[P_SCRATCH];
    const double *sw = work + rows, *k = work + rows + m;
    double ff_mode = work[P_FF_MODE];
    if (work[P_FB_MODE] == FB_DAMPED) {
        double *v = work + scratch + 3 * m + 6 * n;
        for (Py_ssize_t i = 0; i < m; i++) {
            v[i] = gain * k[i] * e[i];
            if (has_ff) v[i] += ff[i];
        }
        for (Py_ssize_t j = 0; j < n; j++) step[j] = 0.0;
        double alpha_max = 0.0;
        for (Py_ssize_t j = 0; j < n; j++) alpha_max = dmax(alpha_max, alpha[j]);
        damped_solve(J, v, sw, alpha, work, dt, step, work[P_LM] * sqrt(ew_sq * alpha_max));
        return;
    }
    for (Py_ssize_t j = 0; j < n; j++) step[j] *= dt * gain * s[j];
    if (has_ff && ff_mode == FF_TRANSPOSE) {
        for (Py_ssize_t j = 0; j < n; j++)
            step[j] += dt * s[j] * squared_weight_column_dot(J, sw, ff, j);
    } else if (has_ff && ff_mode == FF_DAMPED) {
        damped_solve(J, ff, sw, alpha, work, dt, step, 0.0);
    }
}

/* the transpose-type mapping (JT eq. 10, SJT eq. 21, and the damped forms) on the joints of
 * mask; see transpose_step's docstring in sjt_pin/kernels/__init__.py */
static Core transpose_core(Mat J, const double *e, const double *ff, int has_ff,
                           const double *mask, double *work, double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    double dt = work[P_DT];
    Py_ssize_t rows = (Py_ssize_t)work[P_ROWS];
    const double *sw = work + rows, *k = work + rows + m;
    Py_ssize_t scratch = (Py_ssize_t)work[P_SCRATCH];
    double *kew = work + scratch, *alpha = work + scratch + m, *s = work + scratch + m + n;
    Core r = {0};
    double kew_sq = weighted_error(e, sw, k, m, (Py_ssize_t)work[P_ERROR_ROWS], kew, &r);
    double trace = 0.0, stall = 0.0, curvature = 0.0;
    column_scales(J, sw, kew, mask, work, alpha, s, step, &trace, &stall, &curvature);
    stall = kew_sq > 0.0 && trace > 0.0 ? stall / (kew_sq * trace) : 0.0;
    double bound = 1.0, gain;
    if (work[P_GAIN_MODE] == GAIN_FIXED) {
        gain = 1.0;
    } else if (work[P_FB_MODE] == FB_DAMPED) {
        gain = work[P_GAIN_ARG] / dt;
    } else {
        bound = transpose_bound(J, sw, s, work, r.ew_sq, curvature);
        gain = bound > 0.0 ? work[P_GAIN_ARG] / (dt * bound) : 0.0;
    }
    if (has_ff)
        for (Py_ssize_t i = 0; i < m; i++) r.ff_sq += ff[i] * ff[i];
    transpose_apply(J, e, ff, has_ff, alpha, s, work, gain, r.ew_sq, step);
    r.gain = gain;
    r.bound = bound;
    r.stall = stall;
    r.trace = trace;
    return r;
}

/* sol = A^+ rhs for the PSD A (p x p, overwritten), singular values of the underlying J below
 * rcond sigma_max treated as zero, the others damped by shift >= 0: (A + shift I)^-1 rhs on
 * the eigenvalues of A above the cutoff. By Cholesky when that is exact (lambda_min(A) >= 1 /
 * tr(A^-1) above the cutoff), else by Jacobi eigenvalues */
static void damped_pseudo_solve(double *A, double *V, Py_ssize_t p, const double *rhs,
                                double *sol, double rcond, double shift)
{
    double top = 0.0;
    for (Py_ssize_t i = 0; i < p; i++) top = dmax(top, A[i * p + i]);
    double cutoff = dmax(rcond * rcond, EIGEN_FLOOR) * top;
    memcpy(V, A, (size_t)(p * p) * sizeof(double));
    int ok = cholesky_factor(V, p, 0.0);
    if (ok) {
        double inverse_trace = 0.0;
        for (Py_ssize_t c = 0; c < p; c++)
            for (Py_ssize_t i = 0; i < p; i++) {
                double acc = i == c ? 1.0 : 0.0;
                for (Py_ssize_t t = c; t < i; t++) acc -= V[i * p + t] * sol[t];
                sol[i] = i >= c ? acc / V[i * p + i] : 0.0;
                inverse_trace += sol[i] * sol[i];
            }
        ok = inverse_trace * cutoff < 1.0;
    }
    if (ok && shift > 0.0) {  /* A is regular: factor A + shift I instead */
        memcpy(V, A, (size_t)(p * p) * sizeof(double));
        ok = cholesky_factor(V, p, shift);
    }
    if (ok) {
        cholesky_substitute(V, p, rhs, sol);
        return;
    }
    symmetric_eigen_c(A, V, p);
    for (Py_ssize_t i = 0; i < p; i++) sol[i] = 0.0;
    for (Py_ssize_t c = 0; c < p; c++) {
        double lam = A[c * p + c];
        if (lam <= cutoff) continue;
        double proj = 0.0;
        for (Py_ssize_t i = 0; i < p; i++) proj += V[i * p + c] * rhs[i];
        proj /= lam + shift;
        for (Py_ssize_t i = 0; i < p; i++) sol[i] += proj * V[i * p + c];
    }
}

/* sol = A^+ rhs (damped_pseudo_solve without damping) */
void pseudo_solve(double *A, double *V, Py_ssize_t p, const double *rhs, double *sol,
                  double rcond)
{
    damped_pseudo_solve(A, V, p, rhs, sol, rcond, 0.0);
}

/* The least-squares right-hand side v = gain K W e (+ W ff) (task units/s, per row), and
 * |e|^2, |W e|^2 on the error rows and |ff|^2 into out. */
static void least_squares_rhs(const double *e, const double *ff, int has_ff, const double *sw,
                              const double *k, Py_ssize_t m, Py_ssize_t error_rows, double gain,
                              double *v, Core *out)
{
    for (Py_ssize_t i = 0; i < m; i++) {
        double ew = sw[i] * e[i];
        if (i < error_rows) {
            out->e_sq += e[i] * e[i];
            out->ew_sq += ew * ew;
        }
        v[i] = gain * k[i] * ew;
        if (has_ff) {
            v[i] += sw[i] * ff[i];
            out->ff_sq += ff[i] * ff[i];
        }
    }
}

/* The least-squares step (rad) with posture rows (the last n rows an identity block below m_t
 * task rows): the normal equations are diagonal plus rank m_t, solved by Woodbury's identity
 * with the damping mu^2 + lm. */
static void least_squares_posture(Mat J, const double *mask, const double *v, double *work,
                                  Py_ssize_t mt, double lm, double *r, double *sol,
                                  double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    const double *sw = work + (Py_ssize_t)work[P_ROWS];
    double dt = work[P_DT], damping = work[P_MU];
    double *A = matrices(work, m, n);
    double *U = A, *Dg = A + n * mt, *space = Dg + n;
    for (Py_ssize_t j = 0; j < n; j++) {
        double acc = 0.0;
        for (Py_ssize_t a = 0; a < mt; a++) {
            U[j * mt + a] = mask[j] * sw[a] * AT(J, a, j);
            acc += sw[a] * AT(J, a, j) * v[a];
        }
        Dg[j] = mask[j] * sw[mt + j] * sw[mt + j] + damping * damping + lm;
        r[j] = mask[j] * (acc + sw[mt + j] * v[mt + j]);
    }
    woodbury(U, Dg, n, mt, r, sol, space);
    for (Py_ssize_t j = 0; j < n; j++) step[j] = dt * mask[j] * sol[j];
}

/* the least-squares mapping (JP eq. 8, DLS) on the joints of mask: the normal equations of the
 * weighted rows (the row or the column space, the smaller), damped by mu^2 + P_LM |e_w| (m^2):
 * DLS's lambda^2 plus the Levenberg-Marquardt term that grows with the error (P_LM = w L in m;
 * 0 for the textbook JP and DLS), by Cholesky, else (mu = 0) by damped_pseudo_solve */
static Core least_squares_core(Mat J, const double *e, const double *ff, int has_ff,
                               const double *mask, double *work, double *step)
{
    Py_ssize_t m = J.m, n = J.n, p = m < n ? m : n;
    int use_rows = m <= n;
    double dt = work[P_DT];
    double gain = work[P_GAIN_MODE] != GAIN_FIXED ? work[P_GAIN_ARG] / dt : 1.0;
    Py_ssize_t rows = (Py_ssize_t)work[P_ROWS];
    const double *sw = work + rows, *k = work + rows + m;
    Py_ssize_t scratch = (Py_ssize_t)work[P_SCRATCH];
    double *v = work + scratch, *r = work + scratch + m, *sol = work + scratch + m + n;
    double *A = matrices(work, m, n), *V = A + p * p;
    Core out = {0};
    out.gain = gain;
    out.bound = 1.0;
    out.stall = 1.0;
    least_squares_rhs(e, ff, has_ff, sw, k, m, (Py_ssize_t)work[P_ERROR_ROWS], gain, v, &out);
    double damping = work[P_MU], lm = work[P_LM] * sqrt(out.ew_sq);
    Py_ssize_t mt = identity_block(work, m, n);
    if (mt >= 0) {  /* task rows, then posture rows: diagonal plus rank m_t */
        least_squares_posture(J, mask, v, work, mt, lm, r, sol, step);
        return out;
    }
    gram(J, sw, mask, use_rows, A);
    if (!use_rows)
        for (Py_ssize_t j = 0; j < n; j++) r[j] = mask[j] * weighted_column_dot(J, sw, v, j);
    const double *rhs = use_rows ? v : r;
    if (damping > 0.0)
        cholesky_solve_c(A, p, damping * damping + lm, rhs, sol);
    else
        damped_pseudo_solve(A, V, p, rhs, sol, work[P_RCOND], lm);
    for (Py_ssize_t j = 0; j < n; j++)
        step[j] = use_rows ? dt * mask[j] * weighted_column_dot(J, sw, sol, j)
                           : dt * mask[j] * sol[j];
    return out;
}

Core core(int kind, Mat J, const double *e, const double *ff, int has_ff,
          const double *mask, double *work, double *step)
{
    if (kind == TRANSPOSE) return transpose_core(J, e, ff, has_ff, mask, work, step);
    return least_squares_core(J, e, ff, has_ff, mask, work, step);
}
