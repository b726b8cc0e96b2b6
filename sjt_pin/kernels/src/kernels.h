/* The compiled kernels' shared declarations: the work vector's slots (exported by name to
 * sjt_pin/kernels/layout.py), modes, status bits and tolerances, the matrix view, and the
 * functions one file of sjt_pin/kernels/src/ offers the others. */

#ifndef SJT_KERNELS_H
#define SJT_KERNELS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* -- the work vector's slots: named here once, exported by name to sjt_pin/kernels/layout.py - */
#define PARAMETERS(X) X(P_DT) X(P_GAIN_MODE) X(P_GAIN_ARG) X(P_FF_MODE) X(P_MU) X(P_COL_TOL) \
    X(P_SCALED) X(P_RCOND) X(P_LENGTH2) X(P_FB_MODE) X(P_LM) X(P_ERROR_ROWS) X(P_STALL_RATIO) \
    X(P_STALL_ERROR) X(P_ROWS) X(P_MASK) X(P_BOX) X(P_BOX_COUNT) X(P_SPEED) X(P_SCRATCH) \
    X(P_EXTRA) X(P_CLAMPED) X(P_ESCAPING) X(P_HAS_FF) X(P_IDENTITY_ROWS) X(P_STALL_RUN) \
    X(P_STALL_WAIT) X(P_SMOOTH) X(P_JERK)
#define RESULTS(X) X(I_E_SQ) X(I_FF_SQ) X(I_GAIN) X(I_LOOP) X(I_STALL) X(I_TRACE) X(I_EW_SQ) \
    X(I_SCALE) X(I_REGULAR)
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
enum { SMOOTH_PARTS(SLOT_ENUM) SM_COUNT };
enum { LIMIT_CODES(SLOT_ENUM) L_COUNT };
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

/* a read-only matrix with element strides */
typedef struct { const double *p; Py_ssize_t m, n, s0, s1; } Mat;
#define AT(M, i, j) ((M).p[(i) * (M).s0 + (j) * (M).s1])

static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

/* results of a mapping: |e|^2, |ff|^2, |e_w|^2, gain, lambda_hat, stall ratio, trace */
typedef struct { double e_sq, ff_sq, ew_sq, gain, bound, stall, trace; } Core;

/* a bound counts as reached within this many rad/s (m/s) of it (sjt_pin/constraints.py) */
#define BOUND_TOL 1e-12
/* the free joints span the task space while the smallest singular value of their normalised
 * task columns is above this fraction of the largest (Flacco's rank test) */
#define RANK_TOL 1e-6
/* the braking speed's root search (sjt_pin/limits/position.py, BRAKING_TOL, BRAKING_STEPS) */
#define BRAKING_TOL 9.094947017729282e-13
#define BRAKING_STEPS 60
/* Entry c of the position box in work (the joints with position limits): its velocity index
 * v, its coordinate x = q[index] (rad or m), its range [lower, upper] and its recovery speed
 * back (rad/s or m/s) toward the range from outside it. */
typedef struct { Py_ssize_t v; double x, lower, upper, back; } BoxEntry;

/* a float64 buffer acquired from a Python object */
typedef struct {
    Py_buffer view;
    int held;
    double *copy; /* a contiguous copy of a strided 1-D input */
    Py_ssize_t strides[2]; /* a C-contiguous array's canonical strides (view.strides) */
} Arg;

/* the dual's ridge relative to its largest diagonal entry (constraints.DUAL_RIDGE) */
#define DUAL_RIDGE 1e-13

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

/* the length of a 1-D buffer (1 for a 0-D one) */
static inline Py_ssize_t length(const Arg *a) { return a->view.ndim == 0 ? 1 : a->view.shape[0]; }

static inline BoxEntry box_entry(const double *q, const double *work, Py_ssize_t c)
{
    Py_ssize_t box = (Py_ssize_t)work[P_BOX], count = (Py_ssize_t)work[P_BOX_COUNT];
    BoxEntry b = {(Py_ssize_t)work[box + count + c], q[(Py_ssize_t)work[box + c]],
                  work[box + 2 * count + c], work[box + 3 * count + c],
                  work[box + 4 * count + c]};
    return b;
}

/* The doubles of work's clamped part for m task rows and n joints: the held joints, SNS's
 * scratch (saturation.c, 12 n + m + m^2 in all), then the method's velocity before the
 * saturation (rad/s, n; method_velocity). */
#define CLAMPED_SIZE(m, n) (13 * (n) + (m) + (m) * (m))

/* The method's velocity of the last kernel step before its position and speed box (rad/s, n;
 * written by saturate_c only when the box cut the step: the task scale below 1 or joints
 * held): scaled as a whole into the box (scaled_into_c), what a user's rows correct
 * (rows_step_c), continuous in the method's step where SNS's choice of held joints is not. */
static inline double *method_velocity(double *work, Py_ssize_t m, Py_ssize_t n)
{
    return work + (Py_ssize_t)work[P_CLAMPED] + 12 * n + m + m * m;
}

/* The speed limit of velocity coordinate j (rad/s or m/s; INFINITY for none): work keeps its
 * inverse, 0 for none. */
static inline double speed_limit(const double *work, Py_ssize_t j)
{
    double inv = work[(Py_ssize_t)work[P_SPEED] + j];
    return inv > 0.0 ? 1.0 / inv : INFINITY;
}

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

/* The acceleration and jerk limits' box [*lo, *hi] (rad/s) of one joint around the state
 * (v, a) the step starts from (AccelerationLimit, JerkLimit): v +- A dt, narrowed by jerk_bounds
 * where has_jerk and Jk is finite; *lo_by, *hi_by: the limit that set each bound (L_* codes,
 * -1 none). Where they contradict each other the acceleration limit's bound wins (an
 * acceleration beyond its limit, which a collision's rows may ask, cannot come back within one
 * step of the jerk limit: the jerk yields), else the middle of the two; returns 1 then. */
static inline int smoothness_limits(double v, double a, double A, double Jk, double vj,
                                    double dt, int has_jerk, double *lo, double *hi,
                                    double *lo_by, double *hi_by)
{
    *lo = -INFINITY;
    *hi = INFINITY;
    *lo_by = *hi_by = -1.0;
    if (v - A * dt > *lo) {
        *lo = v - A * dt;
        *lo_by = L_ACCELERATION;
    }
    if (v + A * dt < *hi) {
        *hi = v + A * dt;
        *hi_by = L_ACCELERATION;
    }
    if (has_jerk && isfinite(Jk)) {
        double jl, jh;
        jerk_bounds(v, a, Jk, vj, dt, &jl, &jh);
        if (jl > *lo) {
            *lo = jl;
            *lo_by = L_JERK;
        }
        if (jh < *hi) {
            *hi = jh;
            *hi_by = L_JERK;
        }
    }
    if (!(*lo > *hi)) return 0;
    if (*lo_by == L_ACCELERATION && *hi_by != L_ACCELERATION)
        *hi = *lo;
    else if (*hi_by == L_ACCELERATION && *lo_by != L_ACCELERATION)
        *lo = *hi;
    else
        *lo = *hi = 0.5 * (*lo + *hi);
    return 1;
}

/* what each file offers the others, in the order they build on each other */

/* args.c */
int args_init(void);
PyObject *new_array(int nd, const Py_ssize_t *dims, double **data);
void freeze_array(PyObject *array);
void release(Arg *a);
int acquire(PyObject *obj, Arg *a, int writable, int ndim, const char *name);
double *vec(Arg *a, const char *name);
double *out_vec(Arg *a, const char *name);
Mat mat(const Arg *a);
double *out_mat(Arg *a, const char *name);
int nargs_ok(Py_ssize_t got, Py_ssize_t want, const char *name);
int check_work(const Arg *work, Py_ssize_t m, Py_ssize_t n, Py_ssize_t nq);

/* linalg.c */
void gram(Mat J, const double *sw, const double *s, int use_rows, double *out);
double loop_bound_c(const double *A, Py_ssize_t p, int products, double *B, double *C);
int cholesky_factor(double *A, Py_ssize_t p, double shift);
void cholesky_substitute(const double *L, Py_ssize_t p, const double *rhs, double *out);
int cholesky_solve_c(double *A, Py_ssize_t p, double shift, const double *rhs, double *out);
void symmetric_eigen_c(double *A, double *V, Py_ssize_t p);
PyObject *py_cholesky_solve(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_loop_bound(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_symmetric_eigen(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

/* methods.c */
void damped_solve(Mat J, const double *v, const double *sw, const double *alpha,
                  double *work, double dt, double *step, double extra);
void pseudo_solve(double *A, double *V, Py_ssize_t p, const double *rhs, double *sol,
                  double rcond);
Core core(int kind, Mat J, const double *e, const double *ff, int has_ff,
          const double *mask, double *work, double *step);

/* saturation.c */
void exact_position(const double *q, const double *work, double *step);
double scaled_into_c(const double *a, const double *lo, const double *hi, const double *mask,
                     Py_ssize_t n, double *zero, double *out);
void core_scaled(int kind, Mat J, const double *e, const double *ff, int has_ff,
                 const double *mask, double *work, double *step, double factor,
                 double *save);
int sns_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
          const double *mask, double *work, const double *lo, const double *hi,
          double *dq, double factor, double *save, int escaping, double *scale_out);
int saturate_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
               const double *q, const double *mask, double *work, double *step,
               int escaping);

/* smooth_stage.c */
int smooth_stage_c(int kind, Mat J, const double *e, const double *ff, int has_ff,
                   const double *q, const double *mask, double *work, double *step,
                   int escaping);

/* step.c */
int step_c(int kind, Mat J, const double *e, const double *ff, const double *q,
           double *work, double *step);
PyObject *py_transpose_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_least_squares_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_follow_motion(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

/* projection.c */
PyObject *py_nonnegative_qp(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_project_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_rows_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *py_smooth_rows_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

#endif
