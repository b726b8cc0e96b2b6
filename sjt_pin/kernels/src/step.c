/* One step's pipeline (method, stall check, escape, limits) and its Python entries. */

#include "kernels.h"

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
int step_c(int kind, Mat J, const double *e, const double *ff, const double *q,
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

PyObject *py_transpose_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return step_wrapper(TRANSPOSE, args, nargs, "transpose_step");
}

PyObject *py_least_squares_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return step_wrapper(LEAST_SQUARES, args, nargs, "least_squares_step");
}

/* follow_motion(step, dt, dq, ddq): the motion state a step commands, in place: its velocity
 * dq = step / dt (rad/s) and acceleration ddq = (dq - the previous dq) / dt (rad/s^2), as
 * Solver._follow_motion computes them (the state a user's limits read next step) */
PyObject *py_follow_motion(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 4, "follow_motion")) return NULL;
    double dt = PyFloat_AsDouble(args[1]);
    if (dt == -1.0 && PyErr_Occurred()) return NULL;
    Arg step = {0}, dq = {0}, ddq = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &step, 0, 1, "step") || acquire(args[2], &dq, 1, 1, "dq")
        || acquire(args[3], &ddq, 1, 1, "ddq"))
        goto done;
    double *s = vec(&step, "step"), *v = out_vec(&dq, "dq"), *a = out_vec(&ddq, "ddq");
    if (!s || !v || !a) goto done;
    Py_ssize_t n = length(&step);
    if (length(&dq) != n || length(&ddq) != n) {
        PyErr_SetString(PyExc_ValueError, "follow_motion: step, dq and ddq must have one length");
        goto done;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        double velocity = s[j] / dt;
        a[j] = (velocity - v[j]) / dt;
        v[j] = velocity;
    }
    result = Py_NewRef(Py_None);
done:
    release(&step); release(&dq); release(&ddq);
    return result;
}
