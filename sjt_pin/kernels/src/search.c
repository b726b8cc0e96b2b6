/* The set-point search of solve(): Levenberg-Marquardt iterations, one start per call on a
 * single pose task. */

#include "kernels.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* the Levenberg-Marquardt damping's factors down and up, and its range */
#define NU_DOWN 3.0
#define NU_UP 4.0
#define NU_MIN 1e-6
#define NU_MAX 1e8

/* The acquired buffers of search_pose, in its argument order. */
typedef struct {
    Arg R, p, Md, tab, q, qc, Jc, e, ec, lim, work, state, step;
} SearchArgs;

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
        state[S_REJECTED] = 1.0;
    }
    if (f < state[S_PROGRESS] * state[S_BEST] || first) {
        state[S_BEST] = dmin(f, state[S_F]);
        state[S_STALE] = 0.0;
    } else {
        state[S_STALE] += 1.0;
    }
    if (state[S_STALE] >= state[S_STALE_LIMIT] || state[S_NU] > NU_MAX || !isfinite(f))
        return SEARCH_STALLED;
    /* the quick test (a stricter progress over fewer iterations): with a joint held at its limit
     * (heading for a minimum on the boundary of the box), or once a step of the start has been
     * rejected (its damping found: Levenberg-Marquardt then converges fast or not at all; before
     * that, on a robot of metres-long links, the first damping holds a good start back for
     * several iterations) */
    if (f < state[S_HELD_PROGRESS] * state[S_HELD_BEST] || first) {
        state[S_HELD_BEST] = dmin(f, state[S_F]);
        state[S_HELD_STALE] = 0.0;
    } else {
        state[S_HELD_STALE] += 1.0;
    }
    if (state[S_HELD_STALE] >= state[S_HELD_LIMIT]
        && (state[S_REJECTED] != 0.0 || search_held(q_cur, limits, c)))
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

/* search_iteration(J, e, q, J_cur, e_cur, q_cur, limits, work, state, step) -> int */
PyObject *py_search_iteration(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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

/* Up to `count` iterations of the set-point search on a pose task: the pose error (rad, m) of
 * the frame whose rotation and translation views follow q, one search_iteration_c, and the
 * integration of its step, until it stops. Returns the status and the iterations in *done;
 * -1 with the exception set on an error. */
static int search_pose_run(PyObject *jacobian, PyObject *arguments, SearchArgs *a, long count,
                           long *done_)
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
    *done_ = 0;
    while (done < count) {
        Arg Ja = {0};
        Mat Jm;
        PyObject *J = search_jacobian(jacobian, arguments, n, &Ja, &Jm);
        if (!J) return -1;
        search_pose_error(Rm, pv, p_stride, Mm, ev);
        status = search_iteration_c(Jm, ev, qv, nq, Jcv, ecv, qcv, limv,
                                    a->lim.view.shape[1], wv, sv, stv);
        release(&Ja);
        Py_DECREF(J);
        done++;
        if (status != CONTINUE) break;
        search_integrate(qcv, stv, tabv, k, nq, qv);
    }
    *done_ = done;
    return status;
}

/* The table's starts of solve() (sjt_pin.restarts.NearStarts) in one call: up to `starts` starts,
 * each from the configuration of the table whose distance is the smallest left (then marked
 * used: +inf), its state reset to `initial`, of at most min(max_iters, iterations left of
 * `count`) iterations (search_pose_run), until one converges, the iterations run out, or a
 * start ends with a non-finite error (for Python to report). best (|e| of the best start so
 * far, task units) and best_q follow every start whose |e| is below it, as solve() keeps them.
 * Returns (status of the last start, iterations, starts made, best |e|), NULL on an error. */
static PyObject *search_table_loop(PyObject *jacobian, PyObject *arguments, SearchArgs *a,
                                   const double *configurations, Py_ssize_t size,
                                   double *distance, const double *initial, double *best_q,
                                   long count, long max_iters, long starts, double best)
{
    double *qv = (double *)a->q.view.buf, *qcv = (double *)a->qc.view.buf;
    double *sv = (double *)a->state.view.buf;
    Py_ssize_t nq = length(&a->q);
    int status = CONTINUE;
    long used = 0, made = 0;
    while (made < starts && used < count) {
        Py_ssize_t nearest = 0;
        for (Py_ssize_t i = 1; i < size; i++)
            if (distance[i] < distance[nearest]) nearest = i;
        distance[nearest] = INFINITY;
        memcpy(qv, configurations + nearest * nq, (size_t)nq * sizeof(double));
        memcpy(sv, initial, S_COUNT * sizeof(double));
        long limit = count - used < max_iters ? count - used : max_iters, done;
        status = search_pose_run(jacobian, arguments, a, limit, &done);
        if (status < 0) return NULL;
        used += done;
        made++;
        double error = sqrt(sv[S_E_SQ]);
        if (!isfinite(error)) break;
        if (error < best) {
            best = error;
            memcpy(best_q, qcv, (size_t)nq * sizeof(double));
        }
        if (status == CONVERGED) break;
    }
    return Py_BuildValue("(illd)", status, used, made, best);
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
 *             e_cur, limits, work, state, step, count) -> (status, iterations): one start;
 * with seven more arguments (configurations, distance, initial, best_q, starts, max_iters,
 * best) -> (status, iterations, starts made, best |e|): the table's starts (search_table_loop),
 * count iterations over all of them */
PyObject *py_search_pose(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 16 && nargs != 23) {
        PyErr_Format(PyExc_TypeError, "search_pose takes 16 or 23 arguments (%zd given)", nargs);
        return NULL;
    }
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
    if (search_pose_fits(&a) != 0) goto done;
    if (nargs == 16) {
        long iterations;
        int status = search_pose_run(jacobian, arguments, &a, count, &iterations);
        if (status >= 0) result = Py_BuildValue("(il)", status, iterations);
        goto done;
    }
    Arg conf = {0}, dist = {0}, init = {0}, bq = {0};
    long starts = PyLong_AsLong(args[20]), max_iters = PyLong_AsLong(args[21]);
    double best = PyFloat_AsDouble(args[22]);
    if (!PyErr_Occurred() && !acquire(args[16], &conf, 0, 2, "configurations")
        && !acquire(args[17], &dist, 1, 1, "distance") && !acquire(args[18], &init, 0, 1, "initial")
        && !acquire(args[19], &bq, 1, 1, "best_q")) {
        double *cv = out_mat(&conf, "configurations"), *dv = out_vec(&dist, "distance");
        double *iv = vec(&init, "initial"), *bv = out_vec(&bq, "best_q");
        Py_ssize_t nq = length(&a.q);
        if (cv && dv && iv && bv) {
            if (conf.view.ndim != 2 || conf.view.shape[1] != nq
                || length(&dist) != conf.view.shape[0] || conf.view.shape[0] < 1
                || length(&init) < S_COUNT || length(&bq) != nq)
                PyErr_SetString(PyExc_ValueError, "search_pose: the table's arrays do not fit");
            else
                result = search_table_loop(jacobian, arguments, &a, cv, conf.view.shape[0], dv,
                                           iv, bv, count, max_iters, starts, best);
        }
    }
    release(&conf); release(&dist); release(&init); release(&bq);
done:
    release(&a.R); release(&a.p); release(&a.Md); release(&a.tab); release(&a.q);
    release(&a.qc); release(&a.Jc); release(&a.e); release(&a.ec); release(&a.lim);
    release(&a.work); release(&a.state); release(&a.step);
    return result;
}
