/* The compiled inner loops of sjt-pin: one step of each family of CLIK mappings (the paper's
 * eq. 8, 10, 21 and the damped forms), their joint limits, the set-point search, and the
 * tasks' small transforms. Plain C on the CPython API, built by `pip install`: nothing is
 * compiled at run time. Arrays come in through the buffer protocol (float64; 2-D arrays with
 * any strides, 1-D inputs copied when not contiguous); the Python reference formulas are in
 * sjt_pin/mappings.py and tests/test_kernels.py checks these functions against them.
 *
 * Every function keeps the name, arguments and results of the Python-visible kernel it
 * implements (see sjt_pin/kernels/__init__.py); the slot numbers of a solver's `work` vector
 * are those of sjt_pin/kernels/layout.py, exported below and checked by a test. */

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* -- the work vector's slots: named here once, exported by name to sjt_pin/kernels/layout.py - */
#define PARAMETERS(X) X(P_DT) X(P_GAIN_MODE) X(P_GAIN_ARG) X(P_FF_MODE) X(P_MU) X(P_COL_TOL) \
    X(P_SCALED) X(P_RCOND) X(P_LENGTH2) X(P_FB_MODE) X(P_LM) X(P_ERROR_ROWS) X(P_STALL_RATIO) \
    X(P_STALL_ERROR) X(P_ROWS) X(P_MASK) X(P_BOX) X(P_BOX_COUNT) X(P_SPEED) X(P_SCRATCH) \
    X(P_EXTRA) X(P_CLAMPED) X(P_ESCAPING) X(P_HAS_FF) X(P_IDENTITY_ROWS) X(P_STALL_RUN) \
    X(P_STALL_WAIT) X(P_SMOOTH) X(P_JERK)
#define RESULTS(X) X(I_E_SQ) X(I_FF_SQ) X(I_GAIN) X(I_LOOP) X(I_STALL) X(I_TRACE) X(I_EW_SQ) \
    X(I_SCALE) X(I_REGULAR)
#define SEARCH_STATE(X) X(S_F) X(S_NU) X(S_ITER) X(S_BEST) X(S_STALE) X(S_TOL_SQ) \
    X(S_MAX_STEP) X(S_ERROR_ROWS) X(S_E_SQ) \
    X(S_STALE_LIMIT) X(S_PROGRESS) \
    X(S_HELD_BEST) X(S_HELD_STALE) X(S_HELD_LIMIT) X(S_HELD_PROGRESS)
/* the acceleration/jerk stage's part of work (at P_SMOOTH; n numbers each, then m): the
 * motion state, the limits, the step's boxes and what they did (see smooth_stage_c) */
#define SMOOTH_PARTS(X) X(SM_DQ) X(SM_DDQ) X(SM_ACC) X(SM_JERK) X(SM_JERK_SPEED) \
    X(SM_BRAKE_ACC) X(SM_BRAKE_JERK) X(SM_HARD_LO) X(SM_HARD_HI) X(SM_SOFT_LO) X(SM_SOFT_HI) \
    X(SM_HARD_LO_BY) X(SM_HARD_HI_BY) X(SM_SOFT_LO_BY) X(SM_SOFT_HI_BY) X(SM_DESIRED) \
    X(SM_OUT) X(SM_TORN) X(SM_FF) X(SM_GAINS)
/* which limit set a bound of the acceleration/jerk stage's boxes (its *_BY parts) */
#define LIMIT_CODES(X) X(L_POSITION) X(L_VELOCITY) X(L_ACCELERATION) X(L_JERK)
#define SLOT_ENUM(name) name,
#define SLOT_NAME(name) #name,
enum { PARAMETERS(SLOT_ENUM) P_COUNT };
enum { RESULTS(SLOT_ENUM) I_COUNT };
enum { SEARCH_STATE(SLOT_ENUM) S_COUNT };
enum { SMOOTH_PARTS(SLOT_ENUM) SM_COUNT };
enum { LIMIT_CODES(SLOT_ENUM) L_COUNT };
static const char *const PARAMETER_NAMES[] = { PARAMETERS(SLOT_NAME) };
static const char *const RESULT_NAMES[] = { RESULTS(SLOT_NAME) };
static const char *const SEARCH_STATE_NAMES[] = { SEARCH_STATE(SLOT_NAME) };
static const char *const SMOOTH_PART_NAMES[] = { SMOOTH_PARTS(SLOT_NAME) };
static const char *const LIMIT_CODE_NAMES[] = { LIMIT_CODES(SLOT_NAME) };
/* the results follow the parameters */
#define INFO P_COUNT
#define GAIN_FIXED 0
#define GAIN_AUTO 1
#define FF_TRANSPOSE 1
#define FF_DAMPED 2
#define FB_TRANSPOSE 0
#define FB_DAMPED 1
#define NON_FINITE 1
#define STALLED 2
#define CLAMPED 4
#define SCALED 8
#define BOUND_PRODUCTS 2
#define EIGEN_FLOOR (1e3 * 2.220446049250313e-16)
#define TRANSPOSE 0
#define LEAST_SQUARES 1
#define CONTINUE 0
#define CONVERGED 1
#define SEARCH_STALLED 2
#define NU_DOWN 3.0
#define NU_UP 4.0
#define NU_MIN 1e-6
#define NU_MAX 1e8

/* a read-only matrix with element strides */
typedef struct { const double *p; Py_ssize_t m, n, s0, s1; } Mat;
#define AT(M, i, j) ((M).p[(i) * (M).s0 + (j) * (M).s1])

static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

/* -- small dense linear algebra ------------------------------------------------------------- */

/* The p x p loop matrix of J_w S J_w^T (m x m when use_rows, m <= n), or of
 * S^1/2 J_w^T J_w S^1/2 (n x n): both have the same non-zero eigenvalues. */
static void gram(Mat J, const double *sw, const double *s, int use_rows, double *out)
{
    Py_ssize_t m = J.m, n = J.n;
    if (use_rows) {
        for (Py_ssize_t a = 0; a < m; a++)
            for (Py_ssize_t b = 0; b <= a; b++) {
                double acc = 0.0;
                for (Py_ssize_t j = 0; j < n; j++) acc += s[j] * AT(J, a, j) * AT(J, b, j);
                out[a * m + b] = out[b * m + a] = acc * sw[a] * sw[b];
            }
    } else {
        for (Py_ssize_t i = 0; i < n; i++)
            for (Py_ssize_t j = 0; j <= i; j++) {
                double acc = 0.0;
                if (s[i] > 0.0 && s[j] > 0.0) {
                    for (Py_ssize_t a = 0; a < m; a++)
                        acc += sw[a] * sw[a] * AT(J, a, i) * AT(J, a, j);
                    acc *= sqrt(s[i] * s[j]);
                }
                out[i * n + j] = out[j * n + i] = acc;
            }
    }
}

/* An upper bound of lambda_max of the symmetric PSD A (p x p): (tr A^(2^(s+1)))^(1/2^(s+1)),
 * s = products matrix products; B, C are scratch of A's size. 0 for A = 0. */
static double loop_bound_c(const double *A, Py_ssize_t p, int products, double *B, double *C)
{
    double trace = 0.0;
    for (Py_ssize_t i = 0; i < p; i++) trace += A[i * p + i];
    if (trace <= 0.0) return 0.0;
    double log_scale = log(trace);
    for (Py_ssize_t i = 0; i < p * p; i++) B[i] = A[i] / trace;
    for (int t = 0; t < products; t++) {
        double frob = 0.0;
        for (Py_ssize_t i = 0; i < p * p; i++) frob += B[i] * B[i];
        for (Py_ssize_t i = 0; i < p; i++)
            for (Py_ssize_t j = 0; j <= i; j++) {
                double acc = 0.0;
                for (Py_ssize_t k = 0; k < p; k++) acc += B[i * p + k] * B[k * p + j];
                C[i * p + j] = C[j * p + i] = acc / frob;
            }
        memcpy(B, C, (size_t)(p * p) * sizeof(double));
        log_scale = 2.0 * log_scale + log(frob);
    }
    double frob = 0.0;
    for (Py_ssize_t i = 0; i < p * p; i++) frob += B[i] * B[i];
    double exponent = pow(2.0, products + 1);
    return exp((2.0 * log_scale + log(frob)) / exponent);
}

/* The lower triangle of A (p x p) becomes the Cholesky factor of A + shift I; 0 if that
 * matrix is not positive definite. */
static int cholesky_factor(double *A, Py_ssize_t p, double shift)
{
    for (Py_ssize_t j = 0; j < p; j++) {
        double d = A[j * p + j] + shift;
        for (Py_ssize_t k = 0; k < j; k++) d -= A[j * p + k] * A[j * p + k];
        if (!(d > 0.0)) return 0;
        d = sqrt(d);
        A[j * p + j] = d;
        for (Py_ssize_t i = j + 1; i < p; i++) {
            double acc = A[i * p + j];
            for (Py_ssize_t k = 0; k < j; k++) acc -= A[i * p + k] * A[j * p + k];
            A[i * p + j] = acc / d;
        }
    }
    return 1;
}

/* out = (L L^T)^-1 rhs for the lower-triangular factor L (p x p) */
static void cholesky_substitute(const double *L, Py_ssize_t p, const double *rhs, double *out)
{
    for (Py_ssize_t i = 0; i < p; i++) {
        double acc = rhs[i];
        for (Py_ssize_t k = 0; k < i; k++) acc -= L[i * p + k] * out[k];
        out[i] = acc / L[i * p + i];
    }
    for (Py_ssize_t i = p - 1; i >= 0; i--) {
        double acc = out[i];
        for (Py_ssize_t k = i + 1; k < p; k++) acc -= L[k * p + i] * out[k];
        out[i] = acc / L[i * p + i];
    }
}

static int cholesky_solve_c(double *A, Py_ssize_t p, double shift, const double *rhs, double *out)
{
    if (!cholesky_factor(A, p, shift)) return 0;
    cholesky_substitute(A, p, rhs, out);
    return 1;
}

/* Eigen-decomposition of the symmetric A (p x p) by cyclic Jacobi rotations, in place: A's
 * diagonal holds the eigenvalues and V's columns the eigenvectors. */
static void symmetric_eigen_c(double *A, double *V, Py_ssize_t p)
{
    for (Py_ssize_t i = 0; i < p; i++)
        for (Py_ssize_t j = 0; j < p; j++) V[i * p + j] = i == j ? 1.0 : 0.0;
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = 0.0, diag = 0.0;
        for (Py_ssize_t i = 0; i < p; i++) {
            diag += A[i * p + i] * A[i * p + i];
            for (Py_ssize_t j = 0; j < i; j++) off += A[i * p + j] * A[i * p + j];
        }
        if (off <= 1e-32 * diag || off == 0.0) break;
        for (Py_ssize_t a = 0; a < p - 1; a++)
            for (Py_ssize_t b = a + 1; b < p; b++) {
                double apq = A[a * p + b];
                if (apq == 0.0) continue;
                double theta = (A[b * p + b] - A[a * p + a]) / (2.0 * apq);
                double t = 1.0 / (fabs(theta) + sqrt(theta * theta + 1.0));
                if (theta < 0.0) t = -t;
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (Py_ssize_t k = 0; k < p; k++) {
                    if (k != a && k != b) {
                        double akp = A[k * p + a], akq = A[k * p + b];
                        A[k * p + a] = A[a * p + k] = c * akp - s * akq;
                        A[k * p + b] = A[b * p + k] = s * akp + c * akq;
                    }
                }
                A[a * p + a] -= t * apq;
                A[b * p + b] += t * apq;
                A[a * p + b] = A[b * p + a] = 0.0;
                for (Py_ssize_t k = 0; k < p; k++) {
                    double vkp = V[k * p + a], vkq = V[k * p + b];
                    V[k * p + a] = c * vkp - s * vkq;
                    V[k * p + b] = s * vkp + c * vkq;
                }
            }
    }
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
    for (Py_ssize_t j = 0; j < n; j++) x[j] = Dg[j] > 0.0 ? rhs[j] / Dg[j] : 0.0;
    for (Py_ssize_t a = 0; a < mt; a++) {
        double acc = 0.0;
        for (Py_ssize_t j = 0; j < n; j++) acc += U[j * mt + a] * x[j];
        t[a] = acc;
        for (Py_ssize_t b = 0; b <= a; b++) {
            double g = a == b ? 1.0 : 0.0;
            for (Py_ssize_t j = 0; j < n; j++)
                if (Dg[j] > 0.0) g += U[j * mt + a] * U[j * mt + b] / Dg[j];
            S[a * mt + b] = S[b * mt + a] = g;
        }
    }
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

/* |W J_j|^2 over the first `rows` rows: the squared norm of weighted column j (task units^2) */
static inline double weighted_column_norm2(Mat J, const double *sw, Py_ssize_t rows,
                                           Py_ssize_t j)
{
    double acc = 0.0;
    for (Py_ssize_t i = 0; i < rows; i++) acc += (sw[i] * AT(J, i, j)) * (sw[i] * AT(J, i, j));
    return acc;
}

/* SJT's scale of a column of squared norm `norm` (above the column tolerance), eq. (18) with the
 * floor l^2 = length2 under the norm: alpha = 1 / max(|W J_j|^2, l^2) */
static inline double sjt_alpha(double norm, double length2) { return 1.0 / dmax(norm, length2); }

/* (W J_j)^T v = sum_i w_i J_ij v_i: column j of the weighted rows against v */
static inline double weighted_column_dot(Mat J, const double *sw, const double *v, Py_ssize_t j)
{
    double acc = 0.0;
    for (Py_ssize_t i = 0; i < J.m; i++) acc += sw[i] * AT(J, i, j) * v[i];
    return acc;
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
static void damped_solve(Mat J, const double *v, const double *sw, const double *alpha,
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

/* results of a mapping: |e|^2, |ff|^2, |e_w|^2, gain, lambda_hat, stall ratio, trace */
typedef struct { double e_sq, ff_sq, ew_sq, gain, bound, stall, trace; } Core;

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
    for (Py_ssize_t j = 0; j < n; j++) {
        double norm = 0.0, acc = 0.0, acc_task = 0.0;
        if (mask[j] != 0.0) {
            for (Py_ssize_t i = 0; i < m; i++) {
                double wij = sw[i] * AT(J, i, j);
                norm += wij * wij;
                acc += wij * kew[i];
                if (i < error_rows) acc_task += wij * kew[i];
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
static void pseudo_solve(double *A, double *V, Py_ssize_t p, const double *rhs, double *sol,
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

static Core core(int kind, Mat J, const double *e, const double *ff, int has_ff,
                 const double *mask, double *work, double *step)
{
    if (kind == TRANSPOSE) return transpose_core(J, e, ff, has_ff, mask, work, step);
    return least_squares_core(J, e, ff, has_ff, mask, work, step);
}

/* a bound counts as reached within this many rad/s (m/s) of it (sjt_pin/constraints.py) */
#define BOUND_TOL 1e-12
/* the free joints span the task space while the smallest singular value of their normalised
 * task columns is above this fraction of the largest (Flacco's rank test) */
#define RANK_TOL 1e-6
/* the braking speed's root search (sjt_pin/limits/position.py, BRAKING_TOL, BRAKING_STEPS) */
#define BRAKING_TOL 9.094947017729282e-13
#define BRAKING_STEPS 60

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

/* Entry c of the position box in work (the joints with position limits): its velocity index
 * v, its coordinate x = q[index] (rad or m), its range [lower, upper] and its recovery speed
 * back (rad/s or m/s) toward the range from outside it. */
typedef struct { Py_ssize_t v; double x, lower, upper, back; } BoxEntry;

static inline BoxEntry box_entry(const double *q, const double *work, Py_ssize_t c)
{
    Py_ssize_t box = (Py_ssize_t)work[P_BOX], count = (Py_ssize_t)work[P_BOX_COUNT];
    BoxEntry b = {(Py_ssize_t)work[box + count + c], q[(Py_ssize_t)work[box + c]],
                  work[box + 2 * count + c], work[box + 3 * count + c],
                  work[box + 4 * count + c]};
    return b;
}

/* The speed limit of velocity coordinate j (rad/s or m/s; INFINITY for none): work keeps its
 * inverse, 0 for none. */
static inline double speed_limit(const double *work, Py_ssize_t j)
{
    double inv = work[(Py_ssize_t)work[P_SPEED] + j];
    return inv > 0.0 ? 1.0 / inv : INFINITY;
}

/* a joint inside its range moves exactly onto a limit, never a rounding error past it */
static void exact_position(const double *q, const double *work, double *step)
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
static void core_scaled(int kind, Mat J, const double *e, const double *ff, int has_ff,
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

/* SNS's vectors in work's clamped part (n each unless noted): the held flags, the candidate
 * dq = b + s a (a: the method on the free joints, b: what the held ones leave them to make up,
 * hv: the held joints' velocities, rad/s), the free joints, the best candidate so far, and
 * scratch (ff2: m, G: m x m, norm: n). */
typedef struct {
    double *held, *a, *b, *hv, *free_;
    double *best_a, *best_b, *best_hv, *best_held;
    double *ff2, *G, *norm;
} Sns;

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
static int sns_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
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
static int saturate_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
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
    /* a is sns_c's first candidate, and its result */
    double scale;
    int status = sns_c(kind, J, e, ff, has_ff, mask, work, lo, hi, a, 1.0, NULL, escaping,
                       &scale);
    for (Py_ssize_t j = 0; j < n; j++) step[j] = a[j] * dt;
    exact_position(q, work, step);
    work[INFO + I_SCALE] = scale;
    return status;
}

/* -- the acceleration and jerk stage, compiled (sjt_pin/constraints.py and sjt_pin/limits are
 * its reference: Solver._constrain, _brake_feedback, ConstraintStage.box/enforce, smooth,
 * PositionLimit.bounds, braking_speed, stopping_distance, AccelerationLimit, JerkLimit) --- */

/* The speed (rad/s or m/s) at which a ramp at `rate` (rad/s^2, or rad/s^3 for a change of
 * acceleration) still comes to rest within `room` (rad, or rad/s) when it starts after one step
 * of dt (s): the positive root of v dt + v^2 / (2 rate) = room, as rate (-dt + sqrt(dt^2 +
 * 2 room / rate)) (sjt_pin/limits/position.py, braking_speed without jerk). */
static inline double ramp_speed(double rate, double room, double dt)
{
    return rate * (-dt + sqrt(dt * dt + 2.0 * room / rate));
}

/* The jerk limit Jk's bounds [*lo, *hi] on this step's velocity (rad/s) from the state (v, a)
 * the step starts from: an acceleration within Jk dt of a, and the speed limit vj approached
 * with an acceleration that can still ramp down to 0 before it (sjt_pin/limits/jerk.py) */
static inline void jerk_bounds(double v, double a, double Jk, double vj, double dt, double *lo,
                               double *hi)
{
    double change = Jk * dt;
    *lo = v + dt * (a - change);
    *hi = v + dt * (a + change);
    double bound = v + dt * ramp_speed(Jk, dmax(vj - v, 0.0), dt);
    if (isfinite(bound)) *hi = dmin(*hi, bound);
    bound = v - dt * ramp_speed(Jk, dmax(vj + v, 0.0), dt);
    if (isfinite(bound)) *lo = dmax(*lo, bound);
}

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

/* Step 3, the smoothness box (rad/s, AccelerationLimit and JerkLimit): the previous velocity
 * pdq changed by at most A dt, and with jerk limits the previous acceleration pddq changed by at
 * most Jk dt, the velocity approaching the jerk's speed vj no faster than a ramp of the
 * acceleration can end there (ramp_speed); limits that contradict each other give the middle.
 * Codes L_ACCELERATION, L_JERK. */
static void smoothness_bounds(const double *work, const Stage *st, Py_ssize_t n, int has_jerk)
{
    double dt = work[P_DT];
    for (Py_ssize_t j = 0; j < n; j++) {
        double pdq = st->pdq[j], change = st->A[j] * dt, Jk = st->Jk[j];
        st->slo[j] = -INFINITY;
        st->shi[j] = INFINITY;
        st->slb[j] = st->shb[j] = -1.0;
        tighten(st->slo + j, st->shi + j, st->slb + j, st->shb + j, pdq - change, pdq + change,
                L_ACCELERATION);
        if (has_jerk && isfinite(Jk)) {
            double lo, hi;
            jerk_bounds(pdq, st->pddq[j], Jk, st->vj[j], dt, &lo, &hi);
            tighten(st->slo + j, st->shi + j, st->slb + j, st->shb + j, lo, hi, L_JERK);
        }
        if (st->slo[j] > st->shi[j])  /* limits that contradict each other: the middle */
            st->slo[j] = st->shi[j] = 0.5 * (st->slo[j] + st->shi[j]);
    }
}

/* Step 5 (ConstraintStage.smooth): the velocity moves from the smoothness box's centre (within
 * the hard box where both meet) toward out along a line, as far tau in [0, 1] as the smoothness
 * box allows, its bounds first narrowed so that with jerk limits out is reached without
 * overshooting it (ramp_speed of the gap); the hard box wins where it clips the result (marked
 * in torn). Writes desired (out before), dqff (the line's base), out and step (rad). */
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
        st->torn[j] = v < st->hlo[j] || v > st->hhi[j] ? 1.0 : 0.0;
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
static int smooth_stage_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
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
    if (!inside)
        status = sns_c(kind, J, e, ff, has_ff, mask, work, st.hlo, st.hhi, st.out, factor,
                       st.save, escaping, &scale);
    work[INFO + I_SCALE] = scale;
    smooth_line(work, &st, n, has_jerk, step);
    /* 6. exactly onto a position limit; the motion state for the next step */
    exact_position(q, work, step);
    motion_state(step, dt, &st, n);
    return status;
}

/* The mapping's results into work's info part (StepInfo), and |step| / dt (rad/s) as the
 * regular velocity. */
static void record_core(const Core *r, const double *step, Py_ssize_t n, double *work)
{
    double *info = work + INFO, regular = 0.0;
    info[I_E_SQ] = r->e_sq;
    info[I_FF_SQ] = r->ff_sq;
    info[I_EW_SQ] = r->ew_sq;
    info[I_GAIN] = r->gain;
    info[I_LOOP] = r->bound;
    info[I_STALL] = r->stall;
    info[I_TRACE] = r->trace;
    if (!isfinite(r->e_sq + r->ff_sq)) return;
    for (Py_ssize_t j = 0; j < n; j++) regular += step[j] * step[j];
    info[I_REGULAR] = sqrt(regular) / work[P_DT];
}

/* A stall (loop gain along the command below P_STALL_RATIO of tr, |e| above the floor) is
 * Python's (STALLED) on the first stalled step of a run and when the run reaches P_STALL_WAIT
 * (the escape's window; Python then restarts the count at 0): a lasting stall, such as a
 * target out of reach, stays on the fast path in between. Counts the run in work. */
static int stall_status(const Core *r, double *work)
{
    if (!(r->stall < work[P_STALL_RATIO] && r->ew_sq > work[P_STALL_ERROR])) {
        work[P_STALL_RUN] = -1.0;
        return 0;
    }
    if (work[P_STALL_RUN] < 0.0) {
        work[P_STALL_RUN] = 1.0;
        return STALLED;
    }
    return (work[P_STALL_RUN] += 1.0) >= work[P_STALL_WAIT] ? STALLED : 0;
}

/* One step's pipeline: the method (core), the stall check, the escape's velocity, then the
 * limits: the acceleration/jerk stage (smooth_stage_c) or the position and speed bounds
 * (saturate_c). Returns the status bits. */
static int step_c(int kind, Mat J, const double *e, const double *ff, const double *q,
                  double *work, double *step)
{
    Py_ssize_t n = J.n;
    double dt = work[P_DT];
    const double *mask = work + (Py_ssize_t)work[P_MASK];
    int has_ff = work[P_HAS_FF] != 0.0;
    Core r = core(kind, J, e, ff, has_ff, mask, work, step);
    record_core(&r, step, n, work);
    if (!isfinite(r.e_sq + r.ff_sq)) return NON_FINITE;
    int status = stall_status(&r, work);
    int escaping = work[P_ESCAPING] != 0.0;
    Py_ssize_t extra = (Py_ssize_t)work[P_EXTRA];
    if (escaping)
        for (Py_ssize_t j = 0; j < n; j++) step[j] += dt * work[extra + j];
    if (work[P_SMOOTH] > 0.0)  /* acceleration (and jerk) limits: their stage, compiled */
        status |= smooth_stage_c(kind, J, e, ff, has_ff, q, mask, work, step, escaping);
    else
        status |= saturate_c(kind, J, e, ff, has_ff, q, mask, work, step, escaping);
    return status;
}

/* -- the set-point search ---------------------------------------------------------------------- */

/* Wrap or fix the free joints that q + step takes out of their range; 1 if one was fixed */
static int search_clamp(const double *q, double *step, const double *limits, Py_ssize_t c,
                        double *free_, double *fixed)
{
    int changed = 0;
    for (Py_ssize_t k = 0; k < c; k++) {
        Py_ssize_t qi = (Py_ssize_t)limits[k], vi = (Py_ssize_t)limits[c + k];
        if (free_[vi] == 0.0) continue;
        double lo = limits[2 * c + k], hi = limits[3 * c + k];
        double next = q[qi] + step[vi];
        if (lo <= next && next <= hi) continue;
        if (hi - lo >= 2.0 * M_PI) {
            double turn = next > hi ? -2.0 * M_PI : 2.0 * M_PI;
            if (lo <= next + turn && next + turn <= hi) {
                step[vi] += turn;
                continue;
            }
        }
        free_[vi] = 0.0;
        fixed[vi] = dmin(dmax(next, lo), hi) - q[qi];
        changed = 1;
    }
    return changed;
}

/* the damped step from (J, e) at q, scaled to the trust region, within the limits */
static void limited_step(Mat J, const double *e, const double *q, const double *limits,
                         Py_ssize_t c, double *work, double *state, double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    Py_ssize_t rows = (Py_ssize_t)work[P_ROWS], mask_at = (Py_ssize_t)work[P_MASK];
    const double *sw = work + rows, *mask = work + mask_at;
    Py_ssize_t scratch = (Py_ssize_t)work[P_SCRATCH];
    double *alpha = work + scratch + m, *free_ = work + scratch + m + n;
    double *fixed = work + scratch + m + 2 * n, *v = work + scratch + 3 * m + 6 * n;
    double ew_sq = 0.0;
    for (Py_ssize_t i = 0; i < m; i++) ew_sq += (sw[i] * e[i]) * (sw[i] * e[i]);
    double damping = state[S_NU] * ew_sq;
    double tol = work[P_COL_TOL], length2 = work[P_LENGTH2];
    int scaled = work[P_SCALED] != 0.0;
    for (Py_ssize_t j = 0; j < n; j++) {
        free_[j] = mask[j];
        fixed[j] = 0.0;
    }
    for (Py_ssize_t round = 0; round < c + 1; round++) {
        for (Py_ssize_t i = 0; i < m; i++) {
            double acc = e[i];
            for (Py_ssize_t j = 0; j < n; j++)
                if (free_[j] == 0.0 && mask[j] != 0.0) acc -= AT(J, i, j) * fixed[j];
            v[i] = acc;
        }
        for (Py_ssize_t j = 0; j < n; j++) {
            double norm = free_[j] != 0.0 ? weighted_column_norm2(J, sw, m, j) : 0.0;
            if (norm <= tol)
                alpha[j] = 0.0;
            else if (scaled)
                alpha[j] = sjt_alpha(norm, length2);
            else
                alpha[j] = 1.0;
            step[j] = 0.0;
        }
        damped_solve(J, v, sw, alpha, work, 1.0, step, damping);
        double biggest = 0.0;
        for (Py_ssize_t j = 0; j < n; j++) {
            if (free_[j] == 0.0 && mask[j] != 0.0) step[j] = fixed[j];
            biggest = dmax(biggest, fabs(step[j]));
        }
        if (biggest > state[S_MAX_STEP]) {
            double scale = state[S_MAX_STEP] / biggest;
            for (Py_ssize_t j = 0; j < n; j++) step[j] *= scale;
        }
        if (!search_clamp(q, step, limits, c, free_, fixed)) break;
    }
}

/* whether a joint of q sits on one of its position limits (to 1e-9) */
static int search_held(const double *q, const double *limits, Py_ssize_t c)
{
    for (Py_ssize_t k = 0; k < c; k++) {
        double x = q[(Py_ssize_t)limits[k]];
        if (x <= limits[2 * c + k] + 1e-9 || x >= limits[3 * c + k] - 1e-9) return 1;
    }
    return 0;
}

static int search_iteration_c(Mat J, const double *e, const double *q, Py_ssize_t nq,
                              double *J_cur, double *e_cur, double *q_cur, const double *limits,
                              Py_ssize_t c, double *work, double *state, double *step)
{
    Py_ssize_t m = J.m, n = J.n;
    const double *sw = work + (Py_ssize_t)work[P_ROWS];
    Py_ssize_t error_rows = (Py_ssize_t)state[S_ERROR_ROWS];
    double f = 0.0, e_sq = 0.0;
    for (Py_ssize_t i = 0; i < m; i++) {
        f += 0.5 * (sw[i] * e[i]) * (sw[i] * e[i]);
        if (i < error_rows) e_sq += e[i] * e[i];
    }
    int first = state[S_ITER] == 0.0;
    state[S_ITER] += 1.0;
    if (first || f < state[S_F]) {
        for (Py_ssize_t i = 0; i < m; i++) {
            e_cur[i] = e[i];
            for (Py_ssize_t j = 0; j < n; j++) J_cur[i * n + j] = AT(J, i, j);
        }
        memcpy(q_cur, q, (size_t)nq * sizeof(double));
        state[S_F] = f;
        state[S_E_SQ] = e_sq;
        if (!first) state[S_NU] = dmax(state[S_NU] / NU_DOWN, NU_MIN);
        if (e_sq <= state[S_TOL_SQ]) return CONVERGED;
    } else {
        state[S_NU] *= NU_UP;
    }
    if (f < state[S_PROGRESS] * state[S_BEST] || first) {
        state[S_BEST] = dmin(f, state[S_F]);
        state[S_STALE] = 0.0;
    } else {
        state[S_STALE] += 1.0;
    }
    if (state[S_STALE] >= state[S_STALE_LIMIT] || state[S_NU] > NU_MAX || !isfinite(f))
        return SEARCH_STALLED;
    /* with a joint held at its limit the start is heading for a minimum on the boundary of the
     * box: it stalls sooner (a stricter progress over fewer iterations) */
    if (f < state[S_HELD_PROGRESS] * state[S_HELD_BEST] || first) {
        state[S_HELD_BEST] = dmin(f, state[S_F]);
        state[S_HELD_STALE] = 0.0;
    } else {
        state[S_HELD_STALE] += 1.0;
    }
    if (state[S_HELD_STALE] >= state[S_HELD_LIMIT] && search_held(q_cur, limits, c))
        return SEARCH_STALLED;
    Mat cur = {J_cur, m, n, n, 1};
    limited_step(cur, e_cur, q_cur, limits, c, work, state, step);
    return CONTINUE;
}

/* -- the set-point search on one pose task: every iteration of a start in one call ------------- */

/* w = log3(R) (rad), R row-major 3 x 3: (theta / sin theta) vee(R - R^T) / 2 below 120 degrees,
 * the axis from the symmetric part R + R^T above (where sin theta no longer carries it) */
static void search_log3(const double *R, double *w)
{
    double a0 = 0.5 * (R[7] - R[5]), a1 = 0.5 * (R[2] - R[6]), a2 = 0.5 * (R[3] - R[1]);
    double s = sqrt(a0 * a0 + a1 * a1 + a2 * a2), c = 0.5 * (R[0] + R[4] + R[8] - 1.0);
    double theta = atan2(s, c);
    if (c > -0.5) {
        double k = s > 0.0 ? theta / s : 1.0;
        w[0] = k * a0, w[1] = k * a1, w[2] = k * a2;
        return;
    }
    int k = 0;  /* (R + R^T) / 2 - c I = (1 - c) u u^T: its largest diagonal entry's column */
    for (int i = 1; i < 3; i++)
        if (R[4 * i] > R[4 * k]) k = i;
    double u[3];
    for (int i = 0; i < 3; i++) u[i] = 0.5 * (R[3 * i + k] + R[3 * k + i]) - (i == k ? c : 0.0);
    double scale = theta / sqrt(u[k] * (1.0 - c));
    if (u[0] * a0 + u[1] * a1 + u[2] * a2 < 0.0) scale = -scale;
    for (int i = 0; i < 3; i++) w[i] = scale * u[i];
}

/* The pose error [e_p; e_w] = log6(oMf^-1 oMd) of a frame at (R, p) to the target Md (4 x 4),
 * in world axes at the frame (the rows of the LOCAL_WORLD_ALIGNED Jacobian): with
 * w = log3(R_d R^T) and d = p_d - p, e_w = w and e_p = a d - w x d / 2 + b (w.d) w, where
 * a = (t / 2) / tan(t / 2), b = (1 - a) / t^2, t = |w| (the SE(3) logarithm's V^-1). */
static void search_pose_error(Mat R, const double *p, Py_ssize_t p_stride, Mat Md, double *e)
{
    double Rerr[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            Rerr[3 * i + j] = AT(Md, i, 0) * AT(R, j, 0) + AT(Md, i, 1) * AT(R, j, 1)
                              + AT(Md, i, 2) * AT(R, j, 2);
    double w[3], d[3];
    search_log3(Rerr, w);
    for (int i = 0; i < 3; i++) d[i] = AT(Md, i, 3) - p[i * p_stride];
    double t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2], t = sqrt(t2), a, b;
    if (t < 1e-3) {
        a = 1.0 - t2 / 12.0 - t2 * t2 / 720.0;
        b = 1.0 / 12.0 + t2 / 720.0;
    } else {
        a = 0.5 * t / tan(0.5 * t);
        b = (1.0 - a) / t2;
    }
    double wd = b * (w[0] * d[0] + w[1] * d[1] + w[2] * d[2]);
    e[0] = a * d[0] - 0.5 * (w[1] * d[2] - w[2] * d[1]) + wd * w[0];
    e[1] = a * d[1] - 0.5 * (w[2] * d[0] - w[0] * d[2]) + wd * w[1];
    e[2] = a * d[2] - 0.5 * (w[0] * d[1] - w[1] * d[0]) + wd * w[2];
    e[3] = w[0], e[4] = w[1], e[5] = w[2];
}

/* q = q_cur (+) step, Pinocchio's integrate on the joints of the table (3 x k: q index,
 * v index, kind): kind 0 adds (revolute, prismatic), kind 1 turns a (cos, sin) pair by the
 * angle and renormalises it to first order (a continuous joint) */
static void search_integrate(const double *q_cur, const double *step, const double *joints,
                             Py_ssize_t k, Py_ssize_t nq, double *q)
{
    memcpy(q, q_cur, (size_t)nq * sizeof(double));
    for (Py_ssize_t r = 0; r < k; r++) {
        Py_ssize_t qi = (Py_ssize_t)joints[r], vi = (Py_ssize_t)joints[k + r];
        if (joints[2 * k + r] == 0.0) {
            q[qi] = q_cur[qi] + step[vi];
            continue;
        }
        double ca = q_cur[qi], sa = q_cur[qi + 1], co = cos(step[vi]), si = sin(step[vi]);
        double c = co * ca - si * sa, s = si * ca + co * sa, scale = 0.5 * (3.0 - c * c - s * s);
        q[qi] = scale * c, q[qi + 1] = scale * s;
    }
}

/* -- the tasks' transforms ---------------------------------------------------------------------- */

static void frame_velocity_c(Mat oMf, Mat oMd, const double *velocity, double *out)
{
    double d0 = AT(oMf, 0, 3) - AT(oMd, 0, 3), d1 = AT(oMf, 1, 3) - AT(oMd, 1, 3);
    double d2 = AT(oMf, 2, 3) - AT(oMd, 2, 3);
    double w0 = velocity[3], w1 = velocity[4], w2 = velocity[5];
    double v0 = velocity[0] + w1 * d2 - w2 * d1, v1 = velocity[1] + w2 * d0 - w0 * d2;
    double v2 = velocity[2] + w0 * d1 - w1 * d0;
    for (int a = 0; a < 3; a++) {
        out[a] = AT(oMf, 0, a) * v0 + AT(oMf, 1, a) * v1 + AT(oMf, 2, a) * v2;
        out[3 + a] = AT(oMf, 0, a) * w0 + AT(oMf, 1, a) * w1 + AT(oMf, 2, a) * w2;
    }
}

static double rotation_defect_c(Mat M)
{
    double defect = 0.0;
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
            double acc = a == b ? -1.0 : 0.0;
            for (int c = 0; c < 3; c++) acc += AT(M, c, a) * AT(M, c, b);
            defect = dmax(defect, fabs(acc));
            if (acc != acc) defect = NAN;
        }
    double det = AT(M, 0, 0) * (AT(M, 1, 1) * AT(M, 2, 2) - AT(M, 1, 2) * AT(M, 2, 1))
                 - AT(M, 0, 1) * (AT(M, 1, 0) * AT(M, 2, 2) - AT(M, 1, 2) * AT(M, 2, 0))
                 + AT(M, 0, 2) * (AT(M, 1, 0) * AT(M, 2, 1) - AT(M, 1, 1) * AT(M, 2, 0));
    if (defect != defect || det != det
        || !(isfinite(AT(M, 0, 3)) && isfinite(AT(M, 1, 3)) && isfinite(AT(M, 2, 3))))
        return NAN;
    if (!(det > 0.0) || AT(M, 3, 0) != 0.0 || AT(M, 3, 1) != 0.0 || AT(M, 3, 2) != 0.0
        || AT(M, 3, 3) != 1.0)
        return INFINITY;
    return defect;
}

static void position_rows_c(Mat J6, Mat oMf, const double *p_d, const double *velocity,
                            Py_ssize_t velocity_size, double *out, Py_ssize_t size)
{
    Py_ssize_t n = J6.n;
    Py_ssize_t d = size / (n + 3);
    for (Py_ssize_t r = 0; r < d; r++) {
        Py_ssize_t a = (Py_ssize_t)out[r];
        for (Py_ssize_t j = 0; j < n; j++) out[d + r * n + j] = AT(J6, a, j);
        out[d + d * n + r] = p_d[a] - AT(oMf, a, 3);
        if (velocity_size >= 3) out[2 * d + d * n + r] = velocity[a];
    }
}

/* -- the Python side: buffers ------------------------------------------------------------------- */

typedef struct {
    Py_buffer view;
    int held;
    double *copy; /* a contiguous copy of a strided 1-D input */
} Arg;

static int format_ok(const Py_buffer *b)
{
    const char *f = b->format ? b->format : "B";
    if (*f == '<' || *f == '=' || *f == '@') f++;
    if (b->itemsize != 8 || f[1] != '\0') return 0;
    return *f == 'd';
}

static void release(Arg *a)
{
    if (a->held) PyBuffer_Release(&a->view);
    a->held = 0;
    free(a->copy);
    a->copy = NULL;
}

/* a float64 buffer of `ndim` dimensions (-1: any) */
static int acquire(PyObject *obj, Arg *a, int writable, int ndim, const char *name)
{
    a->held = 0;
    a->copy = NULL;
    int flags = PyBUF_STRIDES | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &a->view, flags) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a %sfloat64 array, got %.100s", name,
                     writable ? "writable " : "", Py_TYPE(obj)->tp_name);
        return -1;
    }
    a->held = 1;
    if (!format_ok(&a->view)) {
        PyErr_Format(PyExc_TypeError, "%s must hold float64 numbers", name);
        release(a);
        return -1;
    }
    if (ndim >= 0 && a->view.ndim != ndim) {
        PyErr_Format(PyExc_ValueError, "%s must be %d-dimensional, got %d dimensions", name, ndim,
                     a->view.ndim);
        release(a);
        return -1;
    }
    return 0;
}

static Py_ssize_t length(const Arg *a) { return a->view.ndim == 0 ? 1 : a->view.shape[0]; }

/* a contiguous pointer to a 1-D buffer (a copy of a strided read-only one) */
static double *vec(Arg *a, const char *name)
{
    if (a->view.ndim == 0) return (double *)a->view.buf;
    Py_ssize_t stride = a->view.strides[0], n = a->view.shape[0];
    if (stride == 8 || n <= 1) return (double *)a->view.buf;
    a->copy = (double *)malloc((size_t)(n > 0 ? n : 1) * sizeof(double));
    if (!a->copy) {
        PyErr_NoMemory();
        return NULL;
    }
    for (Py_ssize_t i = 0; i < n; i++)
        a->copy[i] = *(const double *)((const char *)a->view.buf + i * stride);
    (void)name;
    return a->copy;
}

/* a writable 1-D output must be contiguous (results are written in place) */
static double *out_vec(Arg *a, const char *name)
{
    if (a->view.ndim != 1 || (a->view.strides[0] != 8 && a->view.shape[0] > 1)) {
        PyErr_Format(PyExc_ValueError, "%s must be a contiguous 1-D array", name);
        return NULL;
    }
    return (double *)a->view.buf;
}

static Mat mat(const Arg *a)
{
    Mat M = {(const double *)a->view.buf, a->view.shape[0], a->view.shape[1],
             a->view.strides[0] / 8, a->view.strides[1] / 8};
    return M;
}

static double *out_mat(Arg *a, const char *name)
{
    if (a->view.ndim != 2 || a->view.strides[1] != 8 || a->view.strides[0] != 8 * a->view.shape[1]) {
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous 2-D array", name);
        return NULL;
    }
    return (double *)a->view.buf;
}

static int nargs_ok(Py_ssize_t got, Py_ssize_t want, const char *name)
{
    if (got == want) return 1;
    PyErr_Format(PyExc_TypeError, "%s() takes %zd arguments (%zd given)", name, want, got);
    return 0;
}

/* whether work[offset .. offset + count) lies after the header and within size */
static int region_ok(double offset, Py_ssize_t count, Py_ssize_t size)
{
    return offset >= INFO + I_COUNT && offset + (double)count <= (double)size;
}

/* work laid out by layout.Layout for rows (m, n) and a q of nq coordinates: every part within
 * the vector, the limit box's indices within q and the velocity (a work vector written by hand
 * is refused here, never read out of bounds) */
static int check_work(const Arg *work, Py_ssize_t m, Py_ssize_t n, Py_ssize_t nq)
{
    Py_ssize_t size = length(work);
    if (size < INFO + I_COUNT) goto bad;
    const double *w = (const double *)work->view.buf;
    double scratch = w[P_SCRATCH], count = w[P_BOX_COUNT];
    Py_ssize_t p = m < n ? m : n;
    if (!(scratch >= 0 && scratch + 4 * m + 6 * n + 3 * p * p <= size)) goto bad;
    double smooth = w[P_SMOOTH];  /* the acceleration/jerk stage's part: before the scratch */
    if (!(smooth == 0.0 || (smooth >= INFO + I_COUNT
                            && smooth + (SM_COUNT - 1) * n + m <= scratch))) goto bad;
    if (!(count >= 0 && count <= n) || !region_ok(w[P_ROWS], 2 * m, size)
        || !region_ok(w[P_MASK], n, size) || !region_ok(w[P_BOX], 5 * (Py_ssize_t)count, size)
        || !region_ok(w[P_SPEED], n, size) || !region_ok(w[P_EXTRA], n, size)
        || !region_ok(w[P_CLAMPED], 12 * n + m + m * m, size)) goto bad;
    Py_ssize_t box = (Py_ssize_t)w[P_BOX], c = (Py_ssize_t)count;
    for (Py_ssize_t k = 0; k < c; k++)
        if (!(w[box + k] >= 0 && w[box + k] < nq && w[box + c + k] >= 0 && w[box + c + k] < n))
            goto bad;
    return 0;
bad:
    PyErr_Format(PyExc_ValueError, "work does not fit rows of shape (%zd, %zd) and a q of %zd "
                 "coordinates: make it with sjt_pin.kernels.Layout(m, n, c).allocate()", m, n,
                 nq);
    return -1;
}

/* whether a table of c columns holds q indices (row 0; a (cos, sin) pair takes two when row 2
 * says so) below nq and velocity indices (row 1) below n: the search's limits and joints */
static int table_ok(const double *table, Py_ssize_t c, Py_ssize_t nq, Py_ssize_t n, int pairs,
                    const char *name)
{
    for (Py_ssize_t k = 0; k < c; k++) {
        double width = pairs && table[2 * c + k] != 0.0 ? 2.0 : 1.0;
        if (!(table[k] >= 0 && table[k] + width <= nq && table[c + k] >= 0 && table[c + k] < n)) {
            PyErr_Format(PyExc_ValueError, "%s: column %zd indexes past q (%zd,) or the "
                         "velocity (%zd,)", name, k, nq, n);
            return -1;
        }
    }
    return 0;
}

/* transpose_step / least_squares_step (J, e, ff, q, work, step) -> status */
static PyObject *step_wrapper(int kind, PyObject *const *args, Py_ssize_t nargs, const char *fn)
{
    if (!nargs_ok(nargs, 6, fn)) return NULL;
    Arg J = {0}, e = {0}, ff = {0}, q = {0}, work = {0}, step = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &e, 0, 1, "e")
        || acquire(args[2], &ff, 0, 1, "ff") || acquire(args[3], &q, 0, 1, "q")
        || acquire(args[4], &work, 1, 1, "work") || acquire(args[5], &step, 1, 1, "step"))
        goto done;
    Mat Jm = mat(&J);
    if (length(&e) != Jm.m || length(&step) != Jm.n
        || (((double *)work.view.buf)[P_HAS_FF] != 0.0 && length(&ff) != Jm.m)) {
        PyErr_Format(PyExc_ValueError, "J (%zd, %zd), e (%zd,), ff (%zd,) and step (%zd,) do not "
                     "fit", Jm.m, Jm.n, length(&e), length(&ff), length(&step));
        goto done;
    }
    if (check_work(&work, Jm.m, Jm.n, length(&q))) goto done;
    double *ev = vec(&e, "e"), *ffv = vec(&ff, "ff"), *qv = vec(&q, "q");
    double *wv = out_vec(&work, "work"), *sv = out_vec(&step, "step");
    if (!ev || !ffv || !qv || !wv || !sv) goto done;
    int status;
    Py_BEGIN_ALLOW_THREADS
    status = step_c(kind, Jm, ev, ffv, qv, wv, sv);
    Py_END_ALLOW_THREADS
    result = PyLong_FromLong(status);
done:
    release(&J); release(&e); release(&ff); release(&q); release(&work); release(&step);
    return result;
}

static PyObject *py_transpose_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return step_wrapper(TRANSPOSE, args, nargs, "transpose_step");
}

static PyObject *py_least_squares_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return step_wrapper(LEAST_SQUARES, args, nargs, "least_squares_step");
}

static double *square(Arg *a, Py_ssize_t *p, const char *name)
{
    double *buf = out_mat(a, name);
    if (!buf) return NULL;
    if (a->view.shape[0] != a->view.shape[1]) {
        PyErr_Format(PyExc_ValueError, "%s must be square", name);
        return NULL;
    }
    *p = a->view.shape[0];
    return buf;
}

/* cholesky_solve(A, shift, rhs, out) -> bool */
static PyObject *py_cholesky_solve(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 4, "cholesky_solve")) return NULL;
    double shift = PyFloat_AsDouble(args[1]);
    if (shift == -1.0 && PyErr_Occurred()) return NULL;
    Arg A = {0}, rhs = {0}, out = {0};
    PyObject *result = NULL;
    Py_ssize_t p;
    if (acquire(args[0], &A, 1, 2, "A") || acquire(args[2], &rhs, 0, 1, "rhs")
        || acquire(args[3], &out, 1, 1, "out"))
        goto done;
    double *Av = square(&A, &p, "A"), *rv = vec(&rhs, "rhs"), *ov = out_vec(&out, "out");
    if (!Av || !rv || !ov) goto done;
    if (length(&rhs) != p || length(&out) != p) {
        PyErr_SetString(PyExc_ValueError, "rhs and out must have A's size");
        goto done;
    }
    result = PyBool_FromLong(cholesky_solve_c(Av, p, shift, rv, ov));
done:
    release(&A); release(&rhs); release(&out);
    return result;
}

/* loop_bound(A, products, B, C) -> float */
static PyObject *py_loop_bound(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 4, "loop_bound")) return NULL;
    long products = PyLong_AsLong(args[1]);
    if (products == -1 && PyErr_Occurred()) return NULL;
    Arg A = {0}, B = {0}, C = {0};
    PyObject *result = NULL;
    Py_ssize_t p, pb, pc;
    if (acquire(args[0], &A, 0, 2, "A") || acquire(args[2], &B, 1, 2, "B")
        || acquire(args[3], &C, 1, 2, "C"))
        goto done;
    Mat Am = mat(&A);
    double *Bv = square(&B, &pb, "B"), *Cv = square(&C, &pc, "C");
    if (!Bv || !Cv) goto done;
    p = Am.m;
    if (Am.n != p || pb != p || pc != p) {
        PyErr_SetString(PyExc_ValueError, "A, B and C must be square, of one size");
        goto done;
    }
    double *dense = (double *)malloc((size_t)(p * p > 0 ? p * p : 1) * sizeof(double));
    if (!dense) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < p; i++)
        for (Py_ssize_t j = 0; j < p; j++) dense[i * p + j] = AT(Am, i, j);
    double bound = loop_bound_c(dense, p, (int)products, Bv, Cv);
    free(dense);
    result = PyFloat_FromDouble(bound);
done:
    release(&A); release(&B); release(&C);
    return result;
}

/* symmetric_eigen(A, V) -> None */
static PyObject *py_symmetric_eigen(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 2, "symmetric_eigen")) return NULL;
    Arg A = {0}, V = {0};
    PyObject *result = NULL;
    Py_ssize_t p, pv;
    if (acquire(args[0], &A, 1, 2, "A") || acquire(args[1], &V, 1, 2, "V")) goto done;
    double *Av = square(&A, &p, "A"), *Vv = square(&V, &pv, "V");
    if (!Av || !Vv) goto done;
    if (pv != p) {
        PyErr_SetString(PyExc_ValueError, "A and V must have one size");
        goto done;
    }
    symmetric_eigen_c(Av, Vv, p);
    result = Py_NewRef(Py_None);
done:
    release(&A); release(&V);
    return result;
}

static int is_4x4(const Arg *a, const char *name)
{
    if (a->view.shape[0] == 4 && a->view.shape[1] == 4) return 1;
    PyErr_Format(PyExc_ValueError, "%s must be a 4x4 matrix", name);
    return 0;
}

/* frame_velocity(oMf, oMd, velocity, out) -> None */
static PyObject *py_frame_velocity(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 4, "frame_velocity")) return NULL;
    Arg f = {0}, d = {0}, v = {0}, out = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &f, 0, 2, "oMf") || acquire(args[1], &d, 0, 2, "oMd")
        || acquire(args[2], &v, 0, 1, "velocity") || acquire(args[3], &out, 1, 1, "out"))
        goto done;
    if (!is_4x4(&f, "oMf") || !is_4x4(&d, "oMd")) goto done;
    if (length(&v) != 6 || length(&out) != 6) {
        PyErr_SetString(PyExc_ValueError, "velocity and out must have shape (6,)");
        goto done;
    }
    double *vv = vec(&v, "velocity"), *ov = out_vec(&out, "out");
    if (!vv || !ov) goto done;
    frame_velocity_c(mat(&f), mat(&d), vv, ov);
    result = Py_NewRef(Py_None);
done:
    release(&f); release(&d); release(&v); release(&out);
    return result;
}

/* rotation_defect(M) -> float */
static PyObject *py_rotation_defect(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 1, "rotation_defect")) return NULL;
    Arg M = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &M, 0, 2, "M")) goto done;
    if (!is_4x4(&M, "M")) goto done;
    result = PyFloat_FromDouble(rotation_defect_c(mat(&M)));
done:
    release(&M);
    return result;
}

/* position_rows(J6, oMf, p_d, velocity, out) -> None */
static PyObject *py_position_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 5, "position_rows")) return NULL;
    Arg J = {0}, f = {0}, p = {0}, v = {0}, out = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J6") || acquire(args[1], &f, 0, 2, "oMf")
        || acquire(args[2], &p, 0, 1, "p_d") || acquire(args[3], &v, 0, 1, "velocity")
        || acquire(args[4], &out, 1, 1, "out"))
        goto done;
    Mat Jm = mat(&J);
    if (Jm.m != 6 || !is_4x4(&f, "oMf")) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "J6 must have 6 rows");
        goto done;
    }
    Py_ssize_t size = length(&out), vs = length(&v);
    Py_ssize_t d = size / (Jm.n + 3);
    if (length(&p) != 3 || d < 1 || d > 3 || d * (Jm.n + 3) != size || (vs != 0 && vs < 3)) {
        PyErr_SetString(PyExc_ValueError, "position_rows: p_d must have shape (3,), velocity "
                        "(0,), (3,) or (6,), and out d (n + 3) entries for 1 to 3 axes");
        goto done;
    }
    double *pv = vec(&p, "p_d"), *vv = vs ? vec(&v, "velocity") : (double *)v.view.buf;
    double *ov = out_vec(&out, "out");
    if (!pv || (vs && !vv) || !ov) goto done;
    for (Py_ssize_t r = 0; r < d; r++)
        if (!(ov[r] >= 0 && ov[r] <= 2)) {
            PyErr_SetString(PyExc_ValueError, "position_rows: out must start with axes 0-2");
            goto done;
        }
    position_rows_c(Jm, mat(&f), pv, vv, vs, ov, size);
    result = Py_NewRef(Py_None);
done:
    release(&J); release(&f); release(&p); release(&v); release(&out);
    return result;
}

/* unit_defect(q, blocks) -> float: the largest |sum(q[first:first + size]^2) - 1| over the
 * blocks (first, size) of `blocks` (quaternions, (cos, sin) pairs); NaN if one is NaN */
static PyObject *py_unit_defect(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 2, "unit_defect")) return NULL;
    Arg q = {0}, b = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &q, 0, 1, "q") || acquire(args[1], &b, 0, 1, "blocks")) goto done;
    double *qv = vec(&q, "q"), *bv = vec(&b, "blocks");
    if (!qv || !bv) goto done;
    Py_ssize_t n = length(&q), k = length(&b) / 2;
    double worst = 0.0;
    for (Py_ssize_t i = 0; i < k; i++) {
        Py_ssize_t first = (Py_ssize_t)bv[2 * i], size = (Py_ssize_t)bv[2 * i + 1];
        if (first < 0 || size < 0 || first + size > n) {
            PyErr_Format(PyExc_ValueError, "block (%zd, %zd) is outside q (%zd,)", first, size, n);
            goto done;
        }
        double sum = 0.0;
        for (Py_ssize_t j = first; j < first + size; j++) sum += qv[j] * qv[j];
        double d = fabs(sum - 1.0);
        if (isnan(d)) { worst = d; break; }
        if (d > worst) worst = d;
    }
    result = PyFloat_FromDouble(worst);
done:
    release(&q); release(&b);
    return result;
}

/* search_iteration(J, e, q, J_cur, e_cur, q_cur, limits, work, state, step) -> int */
static PyObject *py_search_iteration(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "search_iteration")) return NULL;
    Arg J = {0}, e = {0}, q = {0}, Jc = {0}, ec = {0}, qc = {0}, lim = {0}, work = {0},
        state = {0}, step = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &e, 0, 1, "e")
        || acquire(args[2], &q, 0, 1, "q") || acquire(args[3], &Jc, 1, 2, "J_cur")
        || acquire(args[4], &ec, 1, 1, "e_cur") || acquire(args[5], &qc, 1, 1, "q_cur")
        || acquire(args[6], &lim, 0, 2, "limits") || acquire(args[7], &work, 1, 1, "work")
        || acquire(args[8], &state, 1, 1, "state") || acquire(args[9], &step, 1, 1, "step"))
        goto done;
    Mat Jm = mat(&J);
    double *Jcv = out_mat(&Jc, "J_cur"), *limv = out_mat(&lim, "limits");
    double *ev = vec(&e, "e"), *qv = vec(&q, "q"), *ecv = out_vec(&ec, "e_cur");
    double *qcv = out_vec(&qc, "q_cur"), *wv = out_vec(&work, "work");
    double *sv = out_vec(&state, "state"), *stv = out_vec(&step, "step");
    if (!Jcv || !limv || !ev || !qv || !ecv || !qcv || !wv || !sv || !stv) goto done;
    if (Jc.view.shape[0] != Jm.m || Jc.view.shape[1] != Jm.n || length(&e) != Jm.m
        || length(&ec) != Jm.m || length(&step) != Jm.n || length(&qc) != length(&q)
        || lim.view.shape[0] != 4 || length(&state) < S_COUNT) {
        PyErr_SetString(PyExc_ValueError, "search_iteration: the arrays do not fit J's shape");
        goto done;
    }
    if (check_work(&work, Jm.m, Jm.n, length(&q))
        || table_ok(limv, lim.view.shape[1], length(&q), Jm.n, 0, "limits")) goto done;
    int status = search_iteration_c(Jm, ev, qv, length(&q), Jcv, ecv, qcv, limv,
                                    lim.view.shape[1], wv, sv, stv);
    result = PyLong_FromLong(status);
done:
    release(&J); release(&e); release(&q); release(&Jc); release(&ec); release(&qc);
    release(&lim); release(&work); release(&state); release(&step);
    return result;
}

/* The Jacobian (6 x n) that jacobian(*arguments) returns, acquired in *Ja and viewed in *Jm
 * (Pinocchio's one-dimensional Jacobian of a robot with one joint as a column). Returns the
 * Python object to release with *Ja after use; NULL with the exception set on an error. */
static PyObject *search_jacobian(PyObject *jacobian, PyObject *arguments, Py_ssize_t n, Arg *Ja,
                                 Mat *Jm)
{
    PyObject *J = PyObject_Call(jacobian, arguments, NULL);
    if (!J) return NULL;
    if (acquire(J, Ja, 0, -1, "the Jacobian")) {
        Py_DECREF(J);
        return NULL;
    }
    Mat view = {(const double *)Ja->view.buf, 0, 0, 0, 0};
    if (Ja->view.ndim == 2) {
        view = mat(Ja);
    } else if (Ja->view.ndim == 1) {  /* Pinocchio's Jacobian of a robot with one joint */
        Mat column = {(const double *)Ja->view.buf, Ja->view.shape[0], 1,
                      Ja->view.strides[0] / 8, 1};
        view = column;
    }
    if (view.m != 6 || view.n != n) {
        PyErr_SetString(PyExc_ValueError, "search_pose: the Jacobian is not 6 x nv");
        release(Ja);
        Py_DECREF(J);
        return NULL;
    }
    *Jm = view;
    return J;
}

/* The acquired buffers of search_pose, in its argument order. */
typedef struct {
    Arg R, p, Md, tab, q, qc, Jc, e, ec, lim, work, state, step;
} SearchArgs;

/* Up to `count` iterations of the set-point search on a pose task: the pose error (rad, m) of
 * the frame whose rotation and translation views follow q, one search_iteration_c, and the
 * integration of its step, until it stops. Returns (status, iterations), NULL on an error. */
static PyObject *search_pose_loop(PyObject *jacobian, PyObject *arguments, SearchArgs *a,
                                  long count)
{
    double *tabv = (double *)a->tab.view.buf, *qv = (double *)a->q.view.buf;
    double *qcv = (double *)a->qc.view.buf, *Jcv = (double *)a->Jc.view.buf;
    double *ev = (double *)a->e.view.buf, *ecv = (double *)a->ec.view.buf;
    double *limv = (double *)a->lim.view.buf, *wv = (double *)a->work.view.buf;
    double *sv = (double *)a->state.view.buf, *stv = (double *)a->step.view.buf;
    Mat Rm = mat(&a->R), Mm = mat(&a->Md);
    Py_ssize_t n = length(&a->step), nq = length(&a->q), k = a->tab.view.shape[1];
    const double *pv = (const double *)a->p.view.buf;
    Py_ssize_t p_stride = a->p.view.strides[0] / 8;
    int status = CONTINUE;
    long done = 0;
    while (done < count) {
        Arg Ja = {0};
        Mat Jm;
        PyObject *J = search_jacobian(jacobian, arguments, n, &Ja, &Jm);
        if (!J) return NULL;
        search_pose_error(Rm, pv, p_stride, Mm, ev);
        status = search_iteration_c(Jm, ev, qv, nq, Jcv, ecv, qcv, limv,
                                    a->lim.view.shape[1], wv, sv, stv);
        release(&Ja);
        Py_DECREF(J);
        done++;
        if (status != CONTINUE) break;
        search_integrate(qcv, stv, tabv, k, nq, qv);
    }
    return Py_BuildValue("(il)", status, done);
}

/* search_pose's checks of the acquired arrays' shapes and tables; 0 when they fit */
static int search_pose_fits(SearchArgs *a)
{
    double *tabv = out_mat(&a->tab, "joints"), *qv = out_vec(&a->q, "q");
    double *qcv = out_vec(&a->qc, "q_cur"), *Jcv = out_mat(&a->Jc, "J_cur");
    double *ev = out_vec(&a->e, "e"), *ecv = out_vec(&a->ec, "e_cur");
    double *limv = out_mat(&a->lim, "limits"), *wv = out_vec(&a->work, "work");
    double *sv = out_vec(&a->state, "state"), *stv = out_vec(&a->step, "step");
    if (!tabv || !qv || !qcv || !Jcv || !ev || !ecv || !limv || !wv || !sv || !stv) return -1;
    Mat Rm = mat(&a->R), Mm = mat(&a->Md);
    Py_ssize_t n = length(&a->step), nq = length(&a->q), k = a->tab.view.shape[1];
    if (Rm.m != 3 || Rm.n != 3 || length(&a->p) != 3 || Mm.m != 4 || Mm.n != 4
        || a->tab.view.shape[0] != 3 || a->Jc.view.shape[0] != 6 || a->Jc.view.shape[1] != n
        || length(&a->e) != 6 || length(&a->ec) != 6 || length(&a->qc) != nq
        || a->lim.view.shape[0] != 4 || length(&a->state) < S_COUNT) {
        PyErr_SetString(PyExc_ValueError, "search_pose: the arrays do not fit a pose task");
        return -1;
    }
    if (check_work(&a->work, 6, n, nq)
        || table_ok(limv, a->lim.view.shape[1], nq, n, 0, "limits")
        || table_ok(tabv, k, nq, n, 1, "joints")) return -1;
    return 0;
}

/* search_pose(jacobian, arguments, rotation, translation, target, joints, q, q_cur, J_cur, e,
 *             e_cur, limits, work, state, step, count) -> (status, iterations) */
static PyObject *py_search_pose(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 16, "search_pose")) return NULL;
    PyObject *jacobian = args[0], *arguments = args[1];
    if (!PyCallable_Check(jacobian) || !PyTuple_Check(arguments)) {
        PyErr_SetString(PyExc_TypeError, "search_pose: jacobian must be callable and arguments "
                        "a tuple");
        return NULL;
    }
    SearchArgs a;
    memset(&a, 0, sizeof a);
    PyObject *result = NULL;
    long count = PyLong_AsLong(args[15]);
    if (count == -1 && PyErr_Occurred()) return NULL;
    if (acquire(args[2], &a.R, 0, 2, "rotation") || acquire(args[3], &a.p, 0, 1, "translation")
        || acquire(args[4], &a.Md, 0, 2, "target") || acquire(args[5], &a.tab, 0, 2, "joints")
        || acquire(args[6], &a.q, 1, 1, "q") || acquire(args[7], &a.qc, 1, 1, "q_cur")
        || acquire(args[8], &a.Jc, 1, 2, "J_cur") || acquire(args[9], &a.e, 1, 1, "e")
        || acquire(args[10], &a.ec, 1, 1, "e_cur") || acquire(args[11], &a.lim, 0, 2, "limits")
        || acquire(args[12], &a.work, 1, 1, "work")
        || acquire(args[13], &a.state, 1, 1, "state")
        || acquire(args[14], &a.step, 1, 1, "step"))
        goto done;
    if (search_pose_fits(&a) == 0) result = search_pose_loop(jacobian, arguments, &a, count);
done:
    release(&a.R); release(&a.p); release(&a.Md); release(&a.tab); release(&a.q);
    release(&a.qc); release(&a.Jc); release(&a.e); release(&a.ec); release(&a.lim);
    release(&a.work); release(&a.state); release(&a.step);
    return result;
}

/* -- the constraint stage's correction (sjt_pin/constraints.py: project, nonnegative_qp) -------- */

/* the dual's ridge relative to its largest diagonal entry (constraints.DUAL_RIDGE) */
#define DUAL_RIDGE 1e-13
/* rest_target_c's ridge of Jw Jw^T, relative to its mean diagonal (constraints.REST_RIDGE) */
#define REST_RIDGE 1e-12

/* argmin 1/2 y^T Q y + r^T y over y >= 0 for the symmetric PSD Q (k x k, row-major) plus
 * DUAL_RIDGE max(diag Q) I: the active-set method of Lawson and Hanson's NNLS on the normal
 * equations of the passive set, step for step as constraints.nonnegative_qp (the reference;
 * the passive set's system by Cholesky where numpy's lstsq solves it). scratch: 3 k + 2 k k
 * doubles, then k + k passive/inert flags and k indices. Returns the passive-set solves. */
static int nonnegative_qp_c(const double *Q, const double *r, Py_ssize_t k, double tol,
                            double *y, double *scratch)
{
    double *w = scratch, *s = w + k, *rhs = s + k, *sub = rhs + k, *V = sub + k * k;
    double *passive = V + k * k, *inert = passive + k;
    Py_ssize_t *idx = (Py_ssize_t *)(inert + k);
    double top = 0.0, rmax = 0.0;
    for (Py_ssize_t i = 0; i < k; i++) {
        y[i] = passive[i] = 0.0;
        top = dmax(top, Q[i * k + i]);
        rmax = dmax(rmax, fabs(r[i]));
    }
    double scale = tol * (1.0 + rmax), ridge = DUAL_RIDGE * top;
    for (Py_ssize_t i = 0; i < k; i++)
        inert[i] = Q[i * k + i] <= 1e-14 * dmax(top, 1e-300) ? 1.0 : 0.0;
    int solves = 0;
    for (Py_ssize_t outer = 0; outer < 3 * k + 10; outer++) {
        Py_ssize_t t = -1;
        double best = -INFINITY;
        for (Py_ssize_t i = 0; i < k; i++) {
            if (passive[i] != 0.0 || inert[i] != 0.0) continue;
            double acc = -r[i] - ridge * y[i];
            for (Py_ssize_t j = 0; j < k; j++) acc -= Q[i * k + j] * y[j];
            w[i] = acc;
            if (acc > best) {
                best = acc;
                t = i;
            }
        }
        if (t < 0 || best <= scale) break;
        passive[t] = 1.0;
        for (Py_ssize_t inner = 0; inner < 3 * k + 10; inner++) {
            Py_ssize_t p = 0;
            for (Py_ssize_t i = 0; i < k; i++)
                if (passive[i] != 0.0) idx[p++] = i;
            for (Py_ssize_t a = 0; a < p; a++) {
                rhs[a] = -r[idx[a]];
                for (Py_ssize_t c = 0; c < p; c++) sub[a * p + c] = Q[idx[a] * k + idx[c]];
                sub[a * p + a] += ridge;
            }
            double *sol = w;  /* w is recomputed before it is read again */
            /* the ridge makes the passive set's system positive definite: Cholesky, and the
             * pseudo-inverse only if rounding made a pivot vanish */
            memcpy(V, sub, (size_t)(p * p) * sizeof(double));
            if (cholesky_factor(V, p, 0.0))
                cholesky_substitute(V, p, rhs, sol);
            else
                pseudo_solve(sub, V, p, rhs, sol, 0.0);
            solves++;
            for (Py_ssize_t i = 0; i < k; i++) s[i] = 0.0;
            int positive = 1;
            for (Py_ssize_t a = 0; a < p; a++) {
                s[idx[a]] = sol[a];
                if (!(sol[a] > 0.0)) positive = 0;
            }
            if (positive) {
                memcpy(y, s, (size_t)k * sizeof(double));
                break;
            }
            /* the step toward s stops where the first of those at or below 0 reaches 0 (one
             * already at 0 with s = 0 too stops it at once) */
            double alpha = INFINITY;
            for (Py_ssize_t a = 0; a < p; a++) {
                Py_ssize_t i = idx[a];
                if (s[i] > 0.0) continue;
                double gap = y[i] - s[i];
                alpha = dmin(alpha, gap > 0.0 ? y[i] / gap : 0.0);
            }
            int any = 0;
            for (Py_ssize_t i = 0; i < k; i++) {
                y[i] += alpha * (s[i] - y[i]);
                if (passive[i] != 0.0 && !(y[i] > 1e-15)) passive[i] = 0.0;
                if (passive[i] == 0.0) y[i] = 0.0;
                any |= passive[i] != 0.0;
            }
            if (!any) break;
        }
    }
    return solves;
}

/* doubles of scratch nonnegative_qp_c needs for k rows (its flags and indices included) */
static Py_ssize_t nonnegative_qp_scratch(Py_ssize_t k) { return 6 * k + 2 * k * k + 1; }

/* out = argmin (x - dq)^T H (x - dq), H = Jw_c^T Jw_c + rho I on the moving joints c (rho the
 * mean of H's diagonal), subject to A x <= b and lower <= x <= upper, the others at dq: as
 * constraints.project (its reference), on the dual of the Cholesky-whitened problem; when no
 * x meets them all, within the bounds. Returns the passive-set solves, -1 when out of memory. */
static int project_once_c(const double *dq, Mat Jw, Mat A, const double *b,
                          const double *lower, const double *upper, const double *moving,
                          double *out)
{
    Py_ssize_t n = Jw.n, m = Jw.m, k = A.m, nc = 0, rows;
    Py_ssize_t lo_count = 0, hi_count = 0;
    for (Py_ssize_t j = 0; j < n; j++) {
        out[j] = dq[j];
        if (moving[j] != 0.0) {
            nc++;
            lo_count += isfinite(lower[j]) ? 1 : 0;
            hi_count += isfinite(upper[j]) ? 1 : 0;
        }
    }
    rows = k + lo_count + hi_count;
    size_t size = (size_t)(n + nc * nc + rows * nc + 2 * rows + rows * rows + 2 * nc
                           + nonnegative_qp_scratch(rows));
    double *mem = (double *)malloc(size * sizeof(double));
    if (!mem) return -1;
    Py_ssize_t *cols = (Py_ssize_t *)mem;
    double *L = mem + n, *C = L + nc * nc, *h = C + rows * nc, *y = h + rows, *Q = y + rows;
    double *x0 = Q + rows * rows, *z = x0 + nc, *scratch = z + nc;
    nc = 0;
    for (Py_ssize_t j = 0; j < n; j++)
        if (moving[j] != 0.0) cols[nc++] = j;
    double trace = 0.0;
    for (Py_ssize_t a = 0; a < nc; a++) {
        x0[a] = dq[cols[a]];
        for (Py_ssize_t c = 0; c <= a; c++) {
            double acc = 0.0;
            for (Py_ssize_t i = 0; i < m; i++) acc += AT(Jw, i, cols[a]) * AT(Jw, i, cols[c]);
            L[a * nc + c] = L[c * nc + a] = acc;
        }
        trace += L[a * nc + a];
    }
    double rho = dmax(trace / (double)(nc > 0 ? nc : 1), 1e-12);
    int solves = 0;
    if (nc > 0 && !cholesky_factor(L, nc, rho)) {
        free(mem);
        return 0;  /* not reached: H + rho I is positive definite */
    }
    /* G: A's moving columns, then -e_c for each finite lower bound, e_c for each upper;
     * C = G L^-T row by row (forward substitution), r = h - G x0 (into h) */
    Py_ssize_t row = 0;
    for (Py_ssize_t i = 0; i < rows; i++) {
        double *g = C + i * nc;
        double hi_;
        if (i < k) {
            hi_ = b[i];
            for (Py_ssize_t j = 0; j < n; j++)
                if (moving[j] == 0.0) hi_ -= AT(A, i, j) * dq[j];
            for (Py_ssize_t a = 0; a < nc; a++) g[a] = AT(A, i, cols[a]);
        } else {
            for (Py_ssize_t a = 0; a < nc; a++) g[a] = 0.0;
            int upper_row = i >= k + lo_count;
            /* the next column with a finite bound of this kind */
            if (i == k || i == k + lo_count) row = 0;
            while (!isfinite(upper_row ? upper[cols[row]] : lower[cols[row]])) row++;
            g[row] = upper_row ? 1.0 : -1.0;
            hi_ = upper_row ? upper[cols[row]] : -lower[cols[row]];
            row++;
        }
        for (Py_ssize_t a = 0; a < nc; a++) hi_ -= g[a] * x0[a];
        h[i] = hi_;
        for (Py_ssize_t a = 0; a < nc; a++) {
            double acc = g[a];
            for (Py_ssize_t c = 0; c < a; c++) acc -= L[a * nc + c] * g[c];
            g[a] = acc / L[a * nc + a];
        }
    }
    for (Py_ssize_t i = 0; i < rows; i++)
        for (Py_ssize_t j = 0; j <= i; j++) {
            double acc = 0.0;
            for (Py_ssize_t a = 0; a < nc; a++) acc += C[i * nc + a] * C[j * nc + a];
            Q[i * rows + j] = Q[j * rows + i] = acc;
        }
    solves = nonnegative_qp_c(Q, h, rows, 1e-13, y, scratch);
    /* z = -C^T y, then x - x0 = L^-T z (back substitution) */
    for (Py_ssize_t a = 0; a < nc; a++) {
        double acc = 0.0;
        for (Py_ssize_t i = 0; i < rows; i++) acc -= C[i * nc + a] * y[i];
        z[a] = acc;
    }
    for (Py_ssize_t a = nc - 1; a >= 0; a--) {
        double acc = z[a];
        for (Py_ssize_t c = a + 1; c < nc; c++) acc -= L[c * nc + a] * z[c];
        z[a] = acc / L[a * nc + a];
    }
    /* the bounds are hard: rows that no velocity within them meets (the dual unbounded but
     * for its ridge) leave the answer on them, not beyond */
    for (Py_ssize_t a = 0; a < nc; a++) {
        Py_ssize_t j = cols[a];
        out[j] = dmin(dmax(x0[a] + z[a], lower[j]), upper[j]);
    }
    free(mem);
    return solves;
}

/* The step the projection starts from when it had to correct dq (constraints.rest_target):
 * dq's self-motion (dq minus its least-norm part with the same task motion Jw dq, on the
 * moving joints) scaled by the share phi = |Jw x| / |Jw dq| of the task motion the first
 * projection x kept. A method's step (SJT's per-joint scaling, a saturated step) carries
 * self-motion along with its push on the task; where the rows stop that push (a target inside
 * an obstacle) its self-motion would go on alone and the arm drift in its null space. Writes
 * into target (n) and returns 1, or 0 where it keeps dq (no task motion asked or kept whole,
 * a singular Jw, out of memory). */
static int rest_target_c(const double *dq, Mat Jw, const double *moving, const double *x,
                         double *target)
{
    Py_ssize_t n = Jw.n, m = Jw.m;
    if (m == 0) return 0;
    double *S = (double *)malloc((size_t)(m * m + 3 * m) * sizeof(double));
    if (!S) return 0;
    double *t0 = S + m * m, *t1 = t0 + m, *w = t1 + m;
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
    cholesky_substitute(S, m, t0, w);
    for (Py_ssize_t j = 0; j < n; j++) {
        target[j] = dq[j];
        if (moving[j] == 0.0) continue;
        double task = 0.0;
        for (Py_ssize_t i = 0; i < m; i++) task += AT(Jw, i, j) * w[i];
        target[j] = task + phi * (dq[j] - task);
    }
    free(S);
    return 1;
}

/* project_once_c, from rest_target_c's start where the first projection corrected dq: the
 * stage's correction (constraints.project) */
static int project_c(const double *dq, Mat Jw, Mat A, const double *b, const double *lower,
                     const double *upper, const double *moving, double *out)
{
    int solves = project_once_c(dq, Jw, A, b, lower, upper, moving, out);
    if (solves < 0) return solves;
    Py_ssize_t n = Jw.n;
    int changed = 0;
    for (Py_ssize_t j = 0; j < n && !changed; j++) changed = out[j] != dq[j];
    if (!changed) return solves;
    double *target = (double *)malloc((size_t)(n > 0 ? n : 1) * sizeof(double));
    if (!target) return -1;
    if (rest_target_c(dq, Jw, moving, out, target)) {
        int again = project_once_c(target, Jw, A, b, lower, upper, moving, out);
        solves = again < 0 ? again : solves + again;
    }
    free(target);
    return solves;
}

/* nonnegative_qp(Q, r, y) -> int: y = argmin 1/2 y^T Q y + r^T y over y >= 0 */
static PyObject *py_nonnegative_qp(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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

/* project_rows(dq, Jw, A, b, lower, upper, moving, out) -> int */
static PyObject *py_project_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 8, "project_rows")) return NULL;
    Arg dq = {0}, Jw = {0}, A = {0}, b = {0}, lo = {0}, hi = {0}, mv = {0}, out = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &dq, 0, 1, "dq") || acquire(args[1], &Jw, 0, 2, "Jw")
        || acquire(args[2], &A, 0, 2, "A") || acquire(args[3], &b, 0, 1, "b")
        || acquire(args[4], &lo, 0, 1, "lower") || acquire(args[5], &hi, 0, 1, "upper")
        || acquire(args[6], &mv, 0, 1, "moving") || acquire(args[7], &out, 1, 1, "out"))
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

/* A kernel step (step, written by step_c) against a user's general rows A q_dot <= b and
 * bounds [lower, upper] (rad/s; -inf/inf where none): 0 when it meets them all (step
 * untouched), -1 when it breaks one of the bounds (the caller's whole constraint stage must
 * saturate it), else 1 with step projected onto the rows within those bounds and the kernel's
 * own box of this step (project_c in the metric of the weighted task rows, the moving joints
 * of the mask; every joint inside its range exactly onto a limit it reaches); -2 when out of
 * memory. */
static int rows_step_c(Mat J, const double *q, Mat A, const double *b, const double *lower,
                       const double *upper, double *work, double *step)
{
    Py_ssize_t m = J.m, n = J.n, k = A.m;
    double dt = work[P_DT];
    const double *mask = work + (Py_ssize_t)work[P_MASK];
    const double *sw = work + (Py_ssize_t)work[P_ROWS];
    const double *box_lo = work + (Py_ssize_t)work[P_CLAMPED] + n, *box_hi = box_lo + n;
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = step[j] / dt;
        if (v < lower[j] - BOUND_TOL || v > upper[j] + BOUND_TOL) return -1;
    }
    int broken = 0;
    for (Py_ssize_t i = 0; i < k && !broken; i++) {
        double acc = -b[i];
        for (Py_ssize_t j = 0; j < n; j++) acc += AT(A, i, j) * step[j] / dt;
        if (acc > BOUND_TOL * (1.0 + fabs(b[i]))) broken = 1;
    }
    if (!broken) return 0;
    double *mem = (double *)malloc((size_t)(m * n + 5 * n + 1) * sizeof(double));
    if (!mem) return -2;
    double *Jw = mem, *dq = Jw + m * n, *lo = dq + n, *hi = lo + n, *moving = hi + n;
    double *out = moving + n;
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < n; j++) Jw[i * n + j] = sw[i] * AT(J, i, j) * mask[j];
    for (Py_ssize_t j = 0; j < n; j++) {
        dq[j] = step[j] / dt;
        lo[j] = dmax(box_lo[j], lower[j]);
        hi[j] = dmin(box_hi[j], upper[j]);
        moving[j] = mask[j] != 0.0 ? 1.0 : 0.0;
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
static PyObject *py_rows_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 8, "rows_step")) return NULL;
    Arg J = {0}, q = {0}, A = {0}, b = {0}, lo = {0}, hi = {0}, work = {0}, step = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &q, 0, 1, "q")
        || acquire(args[2], &A, 0, 2, "A") || acquire(args[3], &b, 0, 1, "b")
        || acquire(args[4], &lo, 0, 1, "lower") || acquire(args[5], &hi, 0, 1, "upper")
        || acquire(args[6], &work, 1, 1, "work") || acquire(args[7], &step, 1, 1, "step"))
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

/* the acceleration and jerk limits' box of joint j around the state (v, a) a step starts from
 * (smooth_stage_c's step 3, without the approach to the wanted velocity) */
static void smoothness_box(const double *S, Py_ssize_t n, Py_ssize_t j, double v, double a,
                           double dt, int has_jerk, double *lo_out, double *hi_out)
{
    double A = S[SM_ACC * n + j], Jk = S[SM_JERK * n + j], vj = S[SM_JERK_SPEED * n + j];
    double lo = v - A * dt, hi = v + A * dt;
    if (has_jerk && isfinite(Jk)) {
        double jl, jh;
        jerk_bounds(v, a, Jk, vj, dt, &jl, &jh);
        lo = dmax(lo, jl);
        hi = dmin(hi, jh);
    }
    if (lo > hi) lo = hi = 0.5 * (lo + hi);  /* limits that contradict each other */
    *lo_out = lo;
    *hi_out = hi;
}

/* how far the smoothness box widens, around its centre, in the rounds that look for the
 * smallest breach of the acceleration and jerk limits that lets the rows hold */
#define SMOOTH_WIDEN_ROUNDS 6

/* A step of the compiled acceleration/jerk stage (step and the stage's part of work, written by
 * smooth_stage_c) against a user's general rows A q_dot <= b and bounds [lower, upper] (rad/s;
 * -inf/inf where none; both NULL: none at all); `previous` (2 nv) is the motion state the step started from (the
 * velocity, then the acceleration, commanded the step before). 0 when the step meets them all
 * (step and work untouched); -1 when a user's bound leaves nothing of the stage's hard box on
 * some joint (the caller's whole constraint stage must weigh them); else step is projected
 * (project_c in the metric of the weighted task rows, the moving joints of the mask) onto the
 * rows within the user's bounds, the stage's hard box (positions with their braking, speeds)
 * and the acceleration/jerk box around the previous state: 1 when that holds; 2 when no velocity
 * in it meets the rows, and the hard limits and the rows win (the stage's rule): the
 * smoothness box is widened around its centre, 2, 4, ... 32 times, until they hold (else it is
 * dropped), and the joints that leave it are marked in SM_TORN. After a projection every joint
 * inside its range lands exactly on a limit it reaches, SM_OUT holds the new velocity and the
 * motion state (SM_DQ, SM_DDQ) the one it commands. -2 when out of memory. */
static int smooth_rows_c(Mat J, const double *q, Mat A, const double *b, const double *lower,
                         const double *upper, const double *previous, double *work,
                         double *step)
{
    Py_ssize_t m = J.m, n = J.n, k = A.m;
    double dt = work[P_DT];
    const double *mask = work + (Py_ssize_t)work[P_MASK];
    const double *sw = work + (Py_ssize_t)work[P_ROWS];
    double *S = work + (Py_ssize_t)work[P_SMOOTH];
    double *pdq = S + SM_DQ * n, *pddq = S + SM_DDQ * n;
    const double *hlo = S + SM_HARD_LO * n, *hhi = S + SM_HARD_HI * n;
    double *out = S + SM_OUT * n, *torn = S + SM_TORN * n;
    int has_jerk = work[P_JERK] != 0.0;
    int broken = 0;
    for (Py_ssize_t j = 0; j < n && !broken && lower; j++) {
        double v = step[j] / dt;
        if (v < lower[j] - BOUND_TOL || v > upper[j] + BOUND_TOL) broken = 1;
    }
    for (Py_ssize_t i = 0; i < k && !broken; i++) {
        double acc = -b[i];
        for (Py_ssize_t j = 0; j < n; j++) acc += AT(A, i, j) * step[j] / dt;
        if (acc > BOUND_TOL * (1.0 + fabs(b[i]))) broken = 1;
    }
    if (!broken) return 0;
    double *mem = (double *)malloc((size_t)(m * n + 10 * n + 1) * sizeof(double));
    if (!mem) return -2;
    double *Jw = mem, *dq = Jw + m * n, *lo = dq + n, *hi = lo + n, *moving = hi + n;
    double *res = moving + n, *hard_lo = res + n, *hard_hi = hard_lo + n;
    double *soft_lo = hard_hi + n, *soft_hi = soft_lo + n;
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < n; j++) Jw[i * n + j] = sw[i] * AT(J, i, j) * mask[j];
    for (Py_ssize_t j = 0; j < n; j++) {
        dq[j] = step[j] / dt;
        moving[j] = mask[j] != 0.0 ? 1.0 : 0.0;
        hard_lo[j] = lower ? dmax(hlo[j], lower[j]) : hlo[j];
        hard_hi[j] = upper ? dmin(hhi[j], upper[j]) : hhi[j];
        if (hard_lo[j] > hard_hi[j]) {  /* the user's bound against the hard box */
            free(mem);
            return -1;
        }
        smoothness_box(S, n, j, previous[j], previous[n + j], dt, has_jerk, soft_lo + j,
                       soft_hi + j);
    }
    Mat Jm = {Jw, m, n, n, 1};
    int status = 1;
    for (int round = 0; round <= SMOOTH_WIDEN_ROUNDS; round++) {
        /* round r: the smoothness box widened 2^r times (the last round: none), within the
         * hard box */
        double widen = (double)(1 << (round < SMOOTH_WIDEN_ROUNDS ? round : 0));
        for (Py_ssize_t j = 0; j < n; j++) {
            double l = hard_lo[j], u = hard_hi[j];
            if (round < SMOOTH_WIDEN_ROUNDS) {
                double c = 0.5 * (soft_lo[j] + soft_hi[j]), r = 0.5 * (soft_hi[j] - soft_lo[j]);
                double sl = dmax(l, c - widen * r), su = dmin(u, c + widen * r);
                if (sl <= su) {  /* else the hard box lies beyond: it wins on this joint */
                    l = sl;
                    u = su;
                } else {
                    status = 2;
                }
            }
            lo[j] = l;
            hi[j] = u;
        }
        if (project_c(dq, Jm, A, b, lo, hi, moving, res) < 0) {
            free(mem);
            return -2;
        }
        int kept = 1;  /* the rows met within the box (to the dual's ridge) */
        for (Py_ssize_t i = 0; i < k && kept; i++) {
            double acc = -b[i];
            for (Py_ssize_t j = 0; j < n; j++) acc += AT(A, i, j) * res[j];
            if (acc > 1e-9 * (1.0 + fabs(b[i]))) kept = 0;
        }
        if (kept || round == SMOOTH_WIDEN_ROUNDS) break;
        status = 2;
    }
    for (Py_ssize_t j = 0; j < n; j++) step[j] = res[j] * dt;
    exact_position(q, work, step);
    for (Py_ssize_t j = 0; j < n; j++) {
        double v = step[j] / dt;
        if (v < soft_lo[j] - BOUND_TOL || v > soft_hi[j] + BOUND_TOL) torn[j] = 1.0;
        out[j] = v;
        pddq[j] = (v - previous[j]) / dt;
        pdq[j] = v;
    }
    free(mem);
    return status;
}

/* smooth_rows_step(J, q, A, b, lower, upper, previous, work, step) -> int (smooth_rows_c;
 * lower and upper both None: no bounds, two buffers fewer to acquire) */
static PyObject *py_smooth_rows_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 9, "smooth_rows_step")) return NULL;
    Arg J = {0}, q = {0}, A = {0}, b = {0}, lo = {0}, hi = {0}, pv = {0}, work = {0};
    Arg step = {0};
    PyObject *result = NULL;
    int bounded = args[4] != Py_None || args[5] != Py_None;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &q, 0, 1, "q")
        || acquire(args[2], &A, 0, 2, "A") || acquire(args[3], &b, 0, 1, "b")
        || (bounded && (acquire(args[4], &lo, 0, 1, "lower")
                        || acquire(args[5], &hi, 0, 1, "upper")))
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

/* -- collision dampers (sjt_pin/limits/collision.py) ------------------------------------------ */

/* damper_rows(J, support, pairs, gain_rate, A, b): one velocity-damper row per pair. J (6, N):
 * Pinocchio's WORLD joint Jacobians (data.J, rows linear then angular); support (njoints, N):
 * 1 where a column moves a joint's frame; pairs (k, 13): distance d, margin, the joints of
 * the two geometries (a, b), the unit normal n from a to b (coal's), the closest points p_a
 * and p_b (world). Row i: A_i = (u_a^T J) support[a] - (u_b^T J) support[b] with
 * u_x = [n; p_x x n], and b_i = gain_rate (d - margin); A (k, N) and b (k,) are written. */
static void damper_rows_c(Mat J, Mat support, Mat pairs, double rate, double *A, double *b)
{
    Py_ssize_t N = J.n;
    for (Py_ssize_t i = 0; i < pairs.m; i++) {
        double u[2][6];
        Py_ssize_t joint[2];
        double nx = AT(pairs, i, 4), ny = AT(pairs, i, 5), nz = AT(pairs, i, 6);
        for (int side = 0; side < 2; side++) {
            double px = AT(pairs, i, 7 + 3 * side), py = AT(pairs, i, 8 + 3 * side);
            double pz = AT(pairs, i, 9 + 3 * side);
            u[side][0] = nx;
            u[side][1] = ny;
            u[side][2] = nz;
            u[side][3] = py * nz - pz * ny;
            u[side][4] = pz * nx - px * nz;
            u[side][5] = px * ny - py * nx;
            joint[side] = (Py_ssize_t)AT(pairs, i, 2 + side);
        }
        for (Py_ssize_t c = 0; c < N; c++) {
            double va = 0.0, vb = 0.0;
            for (int r = 0; r < 6; r++) {
                va += u[0][r] * AT(J, r, c);
                vb += u[1][r] * AT(J, r, c);
            }
            A[i * N + c] = va * AT(support, joint[0], c) - vb * AT(support, joint[1], c);
        }
        b[i] = rate * (AT(pairs, i, 0) - AT(pairs, i, 1));
    }
}

static PyObject *py_damper_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 6, "damper_rows")) return NULL;
    double rate = PyFloat_AsDouble(args[3]);
    if (rate == -1.0 && PyErr_Occurred()) return NULL;
    Arg J = {0}, sup = {0}, pairs = {0}, A = {0}, b = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &sup, 0, 2, "support")
        || acquire(args[2], &pairs, 0, 2, "pairs") || acquire(args[4], &A, 1, 2, "A")
        || acquire(args[5], &b, 1, 1, "b"))
        goto done;
    Mat Jm = mat(&J), Sm = mat(&sup), Pm = mat(&pairs);
    double *Av = out_mat(&A, "A"), *bv = out_vec(&b, "b");
    if (!Av || !bv) goto done;
    if (Jm.m != 6 || Sm.n != Jm.n || Pm.n != 13 || A.view.shape[0] != Pm.m
        || A.view.shape[1] != Jm.n || length(&b) != Pm.m) {
        PyErr_Format(PyExc_ValueError, "J (6, N), support (njoints, N), pairs (k, 13), A (k, N) "
                     "and b (k,) do not fit: J (%zd, %zd), support (%zd, %zd), pairs (%zd, %zd)",
                     Jm.m, Jm.n, Sm.m, Sm.n, Pm.m, Pm.n);
        goto done;
    }
    for (Py_ssize_t i = 0; i < Pm.m; i++)
        for (int side = 0; side < 2; side++) {
            double j = AT(Pm, i, 2 + side);
            if (!(j >= 0.0 && j < (double)Sm.m)) {
                PyErr_Format(PyExc_ValueError, "pairs[%zd] names joint %zd; support has %zd",
                             i, (Py_ssize_t)j, Sm.m);
                goto done;
            }
        }
    damper_rows_c(Jm, Sm, Pm, rate, Av, bv);
    result = Py_None;
    Py_INCREF(result);
done:
    release(&J); release(&sup); release(&pairs); release(&A); release(&b);
    return result;
}

/* witness_rows(oMi, poses, rows, found, memory, state, tick, keep, apart, owners) -> int: the
 * collision limit's witness rows (limits/collision.py, "Witnesses"). rows (N, 13) holds the
 * step's exact rows of the pairs `found` (count,) in its first count rows (as damper_rows
 * reads them); poses (njoints, 16): the 4x4 world pose of each joint the rows name (row-major),
 * taken here from Pinocchio's data.oMi (joint 0: the identity) unless oMi is None. A pair
 * whose d - margin is not under keep remembers nothing. memory (npairs * W, 6): per pair up to W remembered closest points, each
 * in its joint's frame (p_a, p_b); state (npairs, 2): how many are remembered and the tick of
 * the call that last saw the pair within influence (a pair missed by the previous call,
 * tick - 1, forgets them). Each remembered pair of points that lies farther than `apart`
 * (either point, its frame) from this step's and whose separation s = n^T (p_b - p_a) along
 * this step's normal is under d + keep becomes a row after the exact ones (d = s, the points
 * in the world, the rest as its pair's row), its pair written to owners; the pair then
 * remembers those (the last W - 1) and this step's points. Returns the number of rows. */
static Py_ssize_t witness_rows_c(const double *poses, double *rows, const double *found,
                                 Py_ssize_t count, double *memory, Py_ssize_t W, double *state,
                                 double tick, double keep, double apart, double *owners)
{
    Py_ssize_t total = count;
    for (Py_ssize_t i = 0; i < count; i++) {
        Py_ssize_t k = (Py_ssize_t)found[i];
        double *row = rows + 13 * i, *st = state + 2 * k, *mem = memory + 6 * W * k;
        const double *H[2] = {poses + 16 * (Py_ssize_t)row[2], poses + 16 * (Py_ssize_t)row[3]};
        Py_ssize_t filled = st[1] == tick - 1.0 ? (Py_ssize_t)st[0] : 0;
        st[1] = tick;
        if (!(row[0] - row[1] < keep)) {  /* far from its margin: its row binds nothing */
            st[0] = 0.0;
            continue;
        }
        double now[6];
        for (int side = 0; side < 2; side++) {
            const double *M = H[side], *p = row + 7 + 3 * side;
            double dx = p[0] - M[3], dy = p[1] - M[7], dz = p[2] - M[11];
            for (int c = 0; c < 3; c++)  /* R^T (p - t) */
                now[3 * side + c] = M[c] * dx + M[4 + c] * dy + M[8 + c] * dz;
        }
        double kept[64][6];
        Py_ssize_t nk = 0;
        for (Py_ssize_t w = 0; w < filled; w++) {
            const double *m = mem + 6 * w;
            double far = 0.0, world[6];
            for (int c = 0; c < 6; c++) far = dmax(far, fabs(m[c] - now[c]));
            if (!(far > apart)) continue;
            for (int side = 0; side < 2; side++) {
                const double *M = H[side], *l = m + 3 * side;
                for (int r = 0; r < 3; r++)
                    world[3 * side + r] = M[4 * r] * l[0] + M[4 * r + 1] * l[1]
                                          + M[4 * r + 2] * l[2] + M[4 * r + 3];
            }
            double s = row[4] * (world[3] - world[0]) + row[5] * (world[4] - world[1])
                       + row[6] * (world[5] - world[2]);
            if (!(s - row[0] < keep)) continue;
            double *out = rows + 13 * total;
            for (int c = 0; c < 13; c++) out[c] = row[c];
            out[0] = s;
            for (int c = 0; c < 6; c++) out[7 + c] = world[c];
            owners[total - count] = (double)k;
            total++;
            if (nk < 64) {
                for (int c = 0; c < 6; c++) kept[nk][c] = m[c];
                nk++;
            }
        }
        Py_ssize_t start = nk > W - 1 ? nk - (W - 1) : 0, n = 0;
        for (Py_ssize_t w = start; w < nk; w++, n++)
            for (int c = 0; c < 6; c++) mem[6 * n + c] = kept[w][c];
        for (int c = 0; c < 6; c++) mem[6 * n + c] = now[c];
        st[0] = (double)(n + 1);
    }
    return total;
}

/* the 4x4 world pose of joint j (Pinocchio's data.oMi[j].homogeneous) into out (row-major) */
static int fetch_pose(PyObject *oMi, Py_ssize_t j, double *out)
{
    static PyObject *s_homogeneous = NULL;
    if (!s_homogeneous && !(s_homogeneous = PyUnicode_InternFromString("homogeneous")))
        return -1;
    PyObject *index = PyLong_FromSsize_t(j);
    PyObject *M = index ? PyObject_GetItem(oMi, index) : NULL;
    Py_XDECREF(index);
    PyObject *H = M ? PyObject_GetAttr(M, s_homogeneous) : NULL;
    Py_XDECREF(M);
    if (!H) return -1;
    Arg a = {0};
    int bad = acquire(H, &a, 0, 2, "oMi[j].homogeneous");
    if (!bad) {
        Mat Hm = mat(&a);
        if (Hm.m != 4 || Hm.n != 4) {
            PyErr_SetString(PyExc_ValueError, "oMi[j].homogeneous must be 4x4");
            bad = 1;
        } else {
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 4; c++) out[4 * r + c] = AT(Hm, r, c);
        }
        release(&a);
    }
    Py_DECREF(H);
    return bad ? -1 : 0;
}

static PyObject *py_witness_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "witness_rows")) return NULL;
    PyObject *oMi = args[0];
    args++;  /* the rest as without oMi */
    double tick = PyFloat_AsDouble(args[5]), keep = PyFloat_AsDouble(args[6]);
    double apart = PyFloat_AsDouble(args[7]);
    if (PyErr_Occurred()) return NULL;
    Arg poses = {0}, rows = {0}, memory = {0}, state = {0}, owners = {0};
    PyObject *result = NULL, *found = NULL;
    double *fv = NULL;
    char *fetched = NULL;
    if (acquire(args[0], &poses, oMi != Py_None, 2, "poses")
        || acquire(args[1], &rows, 1, 2, "rows")
        || acquire(args[3], &memory, 1, 2, "memory") || acquire(args[4], &state, 1, 2, "state")
        || acquire(args[8], &owners, 1, 1, "owners"))
        goto done;
    double *pv = out_mat(&poses, "poses"), *rv = out_mat(&rows, "rows");
    double *mv = out_mat(&memory, "memory");
    double *sv = out_mat(&state, "state"), *ov = out_vec(&owners, "owners");
    if (!pv || !rv || !mv || !sv || !ov) goto done;
    found = PySequence_Fast(args[2], "found must be a sequence of pair indices");
    if (!found) goto done;
    Py_ssize_t count = PySequence_Fast_GET_SIZE(found), N = rows.view.shape[0];
    Py_ssize_t npairs = state.view.shape[0];
    fv = (double *)malloc((size_t)(count > 0 ? count : 1) * sizeof(double));
    if (!fv) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        fv[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(found, i));
        if (fv[i] == -1.0 && PyErr_Occurred()) goto done;
    }
    Py_ssize_t W = npairs > 0 ? memory.view.shape[0] / npairs : 0;
    if (poses.view.shape[1] != 16 || rows.view.shape[1] != 13
        || memory.view.shape[1] != 6 || state.view.shape[1] != 2 || W < 1 || W > 64
        || memory.view.shape[0] != W * npairs || N < count * (1 + W)
        || length(&owners) < count * W) {
        PyErr_Format(PyExc_ValueError, "witness_rows: poses (njoints, 16), rows (>= count (1 + W), "
                     "13), memory (npairs W, 6) with 1 <= W <= 64, state (npairs, 2) and owners "
                     "(>= count W,) do not fit (count %zd, rows %zd, npairs %zd)", count, N,
                     npairs);
        goto done;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        if (!(fv[i] >= 0.0 && fv[i] < (double)npairs)) {
            PyErr_Format(PyExc_ValueError, "found[%zd] is no pair (npairs %zd)", i, npairs);
            goto done;
        }
        for (int side = 0; side < 2; side++) {
            double j = rv[13 * i + 2 + side];
            if (!(j >= 0.0 && j < (double)poses.view.shape[0])) {
                PyErr_Format(PyExc_ValueError, "rows[%zd] names joint %zd; poses has %zd", i,
                             (Py_ssize_t)j, poses.view.shape[0]);
                goto done;
            }
        }
    }
    if (oMi != Py_None) {  /* the poses of the joints of the pairs that remember */
        Py_ssize_t nj = poses.view.shape[0];
        fetched = (char *)calloc((size_t)nj, 1);
        if (!fetched) {
            PyErr_NoMemory();
            goto done;
        }
        double *P = (double *)poses.view.buf;
        for (int c = 0; c < 16; c++) P[c] = c % 5 == 0 ? 1.0 : 0.0;
        fetched[0] = 1;
        for (Py_ssize_t i = 0; i < count; i++) {
            const double *row = rv + 13 * i;
            if (!(row[0] - row[1] < keep)) continue;
            for (int side = 0; side < 2; side++) {
                Py_ssize_t j = (Py_ssize_t)row[2 + side];
                if (fetched[j]) continue;
                if (fetch_pose(oMi, j, P + 16 * j)) goto done;
                fetched[j] = 1;
            }
        }
    }
    result = PyLong_FromSsize_t(witness_rows_c(pv, rv, fv, count, mv, W, sv, tick, keep, apart,
                                               ov));
done:
    Py_XDECREF(found);
    free(fv);
    free(fetched);
    release(&poses); release(&rows); release(&memory); release(&state); release(&owners);
    return result;
}

/* 3 doubles from a float64 array-like (coal's vectors) */
static int read3(PyObject *obj, double *out, const char *name)
{
    Arg a = {0};
    if (acquire(obj, &a, 0, 1, name)) return -1;
    double *v = length(&a) == 3 ? vec(&a, name) : NULL;
    if (!v) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_ValueError, "%s must hold 3 numbers", name);
        release(&a);
        return -1;
    }
    out[0] = v[0];
    out[1] = v[1];
    out[2] = v[2];
    release(&a);
    return 0;
}

/* query_rows(compute, geometry, geometry_data, near, bound, floor, margins, joints, influence,
 * rows) -> list: the collision limit's exact distance queries (limits/collision.py, _rows):
 * for each pair k of the list `near`, res = compute(geometry, geometry_data, k) (Pinocchio's
 * computeDistance), d = res.min_distance; with a bound (npairs,) (else None) floor[k] =
 * d - bound[k] (-inf for a failed query: d -inf or NaN); a pair with -inf < d < influence
 * gets the next row of rows (N, 13) as damper_rows reads it: d, margins[k], joints[k] (npairs,
 * 2), res.normal, res.getNearestPoint1(), res.getNearestPoint2(). Returns those pairs. */
static PyObject *py_query_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "query_rows")) return NULL;
    static PyObject *s_distance = NULL, *s_normal = NULL, *s_p1 = NULL, *s_p2 = NULL;
    if (!s_distance) {
        s_distance = PyUnicode_InternFromString("min_distance");
        s_normal = PyUnicode_InternFromString("normal");
        s_p1 = PyUnicode_InternFromString("getNearestPoint1");
        s_p2 = PyUnicode_InternFromString("getNearestPoint2");
        if (!s_distance || !s_normal || !s_p1 || !s_p2) return NULL;
    }
    double influence = PyFloat_AsDouble(args[8]);
    if (influence == -1.0 && PyErr_Occurred()) return NULL;
    int has_bound = args[4] != Py_None;
    Arg bound = {0}, floor_ = {0}, margins = {0}, joints = {0}, rows = {0};
    PyObject *found = NULL, *near = NULL, *result = NULL;
    if ((has_bound && acquire(args[4], &bound, 0, 1, "bound"))
        || acquire(args[5], &floor_, 1, 1, "floor") || acquire(args[6], &margins, 0, 1, "margins")
        || acquire(args[7], &joints, 0, 2, "joints") || acquire(args[9], &rows, 1, 2, "rows"))
        goto done;
    double *bv = has_bound ? vec(&bound, "bound") : NULL, *fv = out_vec(&floor_, "floor");
    double *mv = vec(&margins, "margins"), *rv = out_mat(&rows, "rows");
    if ((has_bound && !bv) || !fv || !mv || !rv) goto done;
    Mat Jm = mat(&joints);
    Py_ssize_t npairs = length(&floor_), N = rows.view.shape[0];
    if (length(&margins) != npairs || Jm.m != npairs || Jm.n != 2 || rows.view.shape[1] != 13
        || (has_bound && length(&bound) != npairs)) {
        PyErr_Format(PyExc_ValueError, "query_rows: bound, floor, margins (npairs,), joints "
                     "(npairs, 2) and rows (N, 13) do not fit (npairs %zd)", npairs);
        goto done;
    }
    near = PySequence_Fast(args[3], "near must be a sequence of pair indices");
    if (!near) goto done;
    found = PyList_New(0);
    if (!found) goto done;
    Py_ssize_t m = PySequence_Fast_GET_SIZE(near), count = 0;
    PyObject **items = PySequence_Fast_ITEMS(near);
    for (Py_ssize_t i = 0; i < m; i++) {
        Py_ssize_t k = PyLong_AsSsize_t(items[i]);
        if (k == -1 && PyErr_Occurred()) goto fail;
        if (k < 0 || k >= npairs) {
            PyErr_Format(PyExc_ValueError, "near[%zd] = %zd is no pair (npairs %zd)", i, k,
                         npairs);
            goto fail;
        }
        PyObject *call[3] = {args[1], args[2], items[i]};
        PyObject *res = PyObject_Vectorcall(args[0], call, 3, NULL);
        if (!res) goto fail;
        PyObject *dobj = PyObject_GetAttr(res, s_distance);
        double d = dobj ? PyFloat_AsDouble(dobj) : -1.0;
        Py_XDECREF(dobj);
        if (!dobj || (d == -1.0 && PyErr_Occurred())) {
            Py_DECREF(res);
            goto fail;
        }
        if (has_bound) fv[k] = d > -INFINITY ? d - bv[k] : -INFINITY;  /* NaN: -inf */
        if (!(d > -INFINITY && d < influence)) {
            Py_DECREF(res);
            continue;
        }
        if (count >= N) {
            Py_DECREF(res);
            PyErr_SetString(PyExc_ValueError, "query_rows: more pairs within influence than rows");
            goto fail;
        }
        double *row = rv + 13 * count;
        PyObject *normal = PyObject_GetAttr(res, s_normal);
        PyObject *p1 = normal ? PyObject_CallMethodNoArgs(res, s_p1) : NULL;
        PyObject *p2 = p1 ? PyObject_CallMethodNoArgs(res, s_p2) : NULL;
        int bad = !p2 || read3(normal, row + 4, "normal") || read3(p1, row + 7, "nearest point 1")
                  || read3(p2, row + 10, "nearest point 2");
        Py_XDECREF(normal);
        Py_XDECREF(p1);
        Py_XDECREF(p2);
        Py_DECREF(res);
        if (bad) goto fail;
        row[0] = d;
        row[1] = mv[k];
        row[2] = AT(Jm, k, 0);
        row[3] = AT(Jm, k, 1);
        if (PyList_Append(found, items[i]) < 0) goto fail;
        count++;
    }
    result = found;
    found = NULL;
    goto done;
fail:
    Py_CLEAR(found);
done:
    Py_XDECREF(near);
    Py_XDECREF(found);
    if (has_bound) release(&bound);
    release(&floor_); release(&margins); release(&joints); release(&rows);
    return result;
}

/* near_pairs(q, reference, lower, upper, lever, slack, bound, near, floor, influence) ->
 * list | None: the collision limit's skip of its broad phase and of its queries
 * (limits/collision.py, _near and _rows) for q in its own tangent space (revolute and
 * prismatic joints): bound (npairs,) = lever (npairs, nv) |q - reference|; None when q leaves
 * the box lower <= q <= upper (n,) the levers hold in, or when some pair's bound reaches its
 * slack (npairs,) (the broad phase must run again); else the pairs of the list `near` whose floor - bound is
 * not above influence (those to query). */
static PyObject *py_near_pairs(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "near_pairs")) return NULL;
    double influence = PyFloat_AsDouble(args[9]);
    if (influence == -1.0 && PyErr_Occurred()) return NULL;
    Arg q = {0}, ref = {0}, lo = {0}, hi = {0}, lever = {0}, slack = {0}, bound = {0},
        floor_ = {0};
    PyObject *result = NULL, *near = NULL, *out = NULL;
    double *moved = NULL;
    if (acquire(args[0], &q, 0, 1, "q") || acquire(args[1], &ref, 0, 1, "reference")
        || acquire(args[2], &lo, 0, 1, "lower") || acquire(args[3], &hi, 0, 1, "upper")
        || acquire(args[4], &lever, 0, 2, "lever") || acquire(args[5], &slack, 0, 1, "slack")
        || acquire(args[6], &bound, 1, 1, "bound") || acquire(args[8], &floor_, 0, 1, "floor"))
        goto done;
    double *qv = vec(&q, "q"), *rv = vec(&ref, "reference"), *sv = vec(&slack, "slack");
    double *lov = vec(&lo, "lower"), *hiv = vec(&hi, "upper");
    double *bv = out_vec(&bound, "bound"), *fv = vec(&floor_, "floor");
    if (!qv || !rv || !lov || !hiv || !sv || !bv || !fv) goto done;
    Mat L = mat(&lever);
    Py_ssize_t n = length(&q), npairs = L.m;
    if (length(&ref) != n || length(&lo) != n || length(&hi) != n || L.n != n
        || length(&slack) != npairs || length(&bound) != npairs || length(&floor_) != npairs) {
        PyErr_Format(PyExc_ValueError, "near_pairs: q, reference, lower, upper (n,), lever "
                     "(npairs, n), slack, bound and floor (npairs,) do not fit (n %zd, "
                     "npairs %zd)", n, npairs);
        goto done;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        if (!(qv[j] >= lov[j] && qv[j] <= hiv[j])) {
            result = Py_None;
            Py_INCREF(result);
            goto done;
        }
    }
    moved = (double *)malloc((size_t)(n > 0 ? n : 1) * sizeof(double));
    if (!moved) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t j = 0; j < n; j++) moved[j] = fabs(qv[j] - rv[j]);
    int within = 1;
    for (Py_ssize_t k = 0; k < npairs; k++) {
        double acc = 0.0;
        for (Py_ssize_t j = 0; j < n; j++) acc += AT(L, k, j) * moved[j];
        bv[k] = acc;
        if (!(acc < sv[k])) within = 0;
    }
    if (!within) {
        result = Py_None;
        Py_INCREF(result);
        goto done;
    }
    near = PySequence_Fast(args[7], "near must be a sequence of pair indices");
    if (!near) goto done;
    out = PyList_New(0);
    if (!out) goto done;
    Py_ssize_t m = PySequence_Fast_GET_SIZE(near);
    PyObject **items = PySequence_Fast_ITEMS(near);
    for (Py_ssize_t i = 0; i < m; i++) {
        Py_ssize_t k = PyLong_AsSsize_t(items[i]);
        if (k == -1 && PyErr_Occurred()) goto done;
        if (k < 0 || k >= npairs) {
            PyErr_Format(PyExc_ValueError, "near[%zd] = %zd is no pair (npairs %zd)", i, k,
                         npairs);
            goto done;
        }
        if (!(fv[k] - bv[k] > influence) && PyList_Append(out, items[i]) < 0) goto done;
    }
    result = out;
    out = NULL;
done:
    Py_XDECREF(out);
    Py_XDECREF(near);
    free(moved);
    release(&q); release(&ref); release(&lo); release(&hi); release(&lever); release(&slack); release(&bound);
    release(&floor_);
    return result;
}

static PyMethodDef methods[] = {
    {"transpose_step", (PyCFunction)(void (*)(void))py_transpose_step, METH_FASTCALL,
     "transpose_step(J, e, ff, q, work, step) -> status: one step of a Jacobian-transpose-type "
     "CLIK law (JT eq. 10, SJT eq. 21, the damped forms), then the limits."},
    {"least_squares_step", (PyCFunction)(void (*)(void))py_least_squares_step, METH_FASTCALL,
     "least_squares_step(J, e, ff, q, work, step) -> status: one step of the pseudoinverse "
     "(eq. 8) or damped least-squares CLIK law, then the limits."},
    {"cholesky_solve", (PyCFunction)(void (*)(void))py_cholesky_solve, METH_FASTCALL,
     "cholesky_solve(A, shift, rhs, out) -> bool: out = (A + shift I)^-1 rhs (A overwritten)."},
    {"loop_bound", (PyCFunction)(void (*)(void))py_loop_bound, METH_FASTCALL,
     "loop_bound(A, products, B, C) -> float: an upper bound of lambda_max of the PSD A."},
    {"symmetric_eigen", (PyCFunction)(void (*)(void))py_symmetric_eigen, METH_FASTCALL,
     "symmetric_eigen(A, V): Jacobi eigen-decomposition in place (diag A, columns of V)."},
    {"frame_velocity", (PyCFunction)(void (*)(void))py_frame_velocity, METH_FASTCALL,
     "frame_velocity(oMf, oMd, velocity, out): a desired twist seen from the frame (LOCAL)."},
    {"rotation_defect", (PyCFunction)(void (*)(void))py_rotation_defect, METH_FASTCALL,
     "rotation_defect(M) -> float: max |R^T R - I| of a 4x4 (inf: not rigid, nan: not finite)."},
    {"position_rows", (PyCFunction)(void (*)(void))py_position_rows, METH_FASTCALL,
     "position_rows(J6, oMf, p_d, velocity, out): a position task's rows into out."},
    {"unit_defect", (PyCFunction)(void (*)(void))py_unit_defect, METH_FASTCALL,
     "unit_defect(q, blocks) -> float: largest |squared norm - 1| of the unit blocks"},
    {"search_iteration", (PyCFunction)(void (*)(void))py_search_iteration, METH_FASTCALL,
     "search_iteration(J, e, q, J_cur, e_cur, q_cur, limits, work, state, step) -> status: "
     "one Levenberg-Marquardt iteration of solve()."},
    {"search_pose", (PyCFunction)(void (*)(void))py_search_pose, METH_FASTCALL,
     "search_pose(jacobian, arguments, rotation, translation, target, joints, q, q_cur, J_cur, "
     "e, e_cur, limits, work, state, step, count) -> (status, iterations): up to count "
     "iterations of solve() on one pose task, each calling jacobian(*arguments) once."},
    {"nonnegative_qp", (PyCFunction)(void (*)(void))py_nonnegative_qp, METH_FASTCALL,
     "nonnegative_qp(Q, r, y) -> int: y = argmin 1/2 y^T Q y + r^T y over y >= 0 (NNLS)."},
    {"project_rows", (PyCFunction)(void (*)(void))py_project_rows, METH_FASTCALL,
     "project_rows(dq, Jw, A, b, lower, upper, moving, out) -> int: the constraint stage's "
     "smallest correction of dq onto A x <= b and the box (constraints.project)."},
    {"rows_step", (PyCFunction)(void (*)(void))py_rows_step, METH_FASTCALL,
     "rows_step(J, q, A, b, lower, upper, work, step) -> int: a kernel step against general "
     "rows and bounds: 0 kept, 1 projected in place, -1 outside the bounds."},
    {"damper_rows", (PyCFunction)(void (*)(void))py_damper_rows, METH_FASTCALL,
     "damper_rows(J, support, pairs, gain_rate, A, b): the collision limit's velocity-damper "
     "rows of the pairs (d, margin, joint a, joint b, normal, p_a, p_b) into A and b."},
    {"smooth_rows_step", (PyCFunction)(void (*)(void))py_smooth_rows_step, METH_FASTCALL,
     "smooth_rows_step(J, q, A, b, lower, upper, previous, work, step) -> int: a step of the "
     "compiled acceleration/jerk stage against general rows and bounds: 0 kept, 1 projected "
     "within every box, 2 projected with smoothness yielding, -1 a bound outside the hard box."},
    {"witness_rows", (PyCFunction)(void (*)(void))py_witness_rows, METH_FASTCALL,
     "witness_rows(oMi, poses, rows, found, memory, state, tick, keep, apart, owners) -> int: the "
     "collision limit's rows of its pairs' remembered closest points after their own rows."},
    {"query_rows", (PyCFunction)(void (*)(void))py_query_rows, METH_FASTCALL,
     "query_rows(compute, geometry, geometry_data, near, bound, floor, margins, joints, "
     "influence, rows) -> list: the collision limit's distance queries and its pairs' rows."},
    {"near_pairs", (PyCFunction)(void (*)(void))py_near_pairs, METH_FASTCALL,
     "near_pairs(q, reference, lower, upper, lever, slack, bound, near, floor, influence) -> "
     "list | None: "
     "the collision limit's pairs to query, or None when its broad phase must run again."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "The compiled inner loops of sjt-pin (see sjt_pin/kernels/__init__.py).", -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void)
{
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    /* every slot by its name: kernels/layout.py takes them from here (no Python module holds
     * a slot's number) */
    for (int i = 0; i < P_COUNT; i++)
        if (PyModule_AddIntConstant(m, PARAMETER_NAMES[i], i) < 0) goto fail;
    for (int i = 0; i < I_COUNT; i++)
        if (PyModule_AddIntConstant(m, RESULT_NAMES[i], i) < 0) goto fail;
    for (int i = 0; i < S_COUNT; i++)
        if (PyModule_AddIntConstant(m, SEARCH_STATE_NAMES[i], i) < 0) goto fail;
    for (int i = 0; i < SM_COUNT; i++)
        if (PyModule_AddIntConstant(m, SMOOTH_PART_NAMES[i], i) < 0) goto fail;
    for (int i = 0; i < L_COUNT; i++)
        if (PyModule_AddIntConstant(m, LIMIT_CODE_NAMES[i], i) < 0) goto fail;
    if (PyModule_AddIntConstant(m, "SMOOTH_SIZE", SM_COUNT) < 0) goto fail;
    /* the modes, status bits and tolerances the kernels and their Python side share, by name */
#define EXPORT_INT(name) if (PyModule_AddIntConstant(m, #name, name) < 0) goto fail;
#define EXPORT_FLOAT(name) \
    if (PyModule_AddObjectRef(m, #name, value = PyFloat_FromDouble(name)) < 0) goto fail; \
    Py_DECREF(value);
    PyObject *value = NULL;
    EXPORT_INT(GAIN_FIXED) EXPORT_INT(GAIN_AUTO) EXPORT_INT(FF_TRANSPOSE) EXPORT_INT(FF_DAMPED)
    EXPORT_INT(FB_TRANSPOSE) EXPORT_INT(FB_DAMPED) EXPORT_INT(NON_FINITE) EXPORT_INT(STALLED)
    EXPORT_INT(CLAMPED) EXPORT_INT(SCALED) EXPORT_INT(BOUND_PRODUCTS) EXPORT_INT(CONTINUE)
    EXPORT_INT(CONVERGED) EXPORT_INT(SEARCH_STALLED) EXPORT_INT(BRAKING_STEPS)
    EXPORT_FLOAT(EIGEN_FLOOR) EXPORT_FLOAT(BOUND_TOL) EXPORT_FLOAT(RANK_TOL)
    EXPORT_FLOAT(BRAKING_TOL) EXPORT_FLOAT(DUAL_RIDGE)
#undef EXPORT_INT
#undef EXPORT_FLOAT
    if (PyModule_AddIntConstant(m, "INFO", INFO) < 0
        || PyModule_AddIntConstant(m, "INFO_SIZE", I_COUNT) < 0
        || PyModule_AddIntConstant(m, "STATE_SIZE", S_COUNT) < 0)
        goto fail;
    return m;
fail:
    Py_DECREF(m);
    return NULL;
}
