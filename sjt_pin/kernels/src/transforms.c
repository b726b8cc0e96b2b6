/* The tasks' small transforms: a desired twist in the frame, rotation and unit-block
 * defects, a position task's rows. */

#include "kernels.h"

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

static int is_4x4(const Arg *a, const char *name)
{
    if (a->view.shape[0] == 4 && a->view.shape[1] == 4) return 1;
    PyErr_Format(PyExc_ValueError, "%s must be a 4x4 matrix", name);
    return 0;
}

/* frame_velocity(oMf, oMd, velocity, out) -> None */
PyObject *py_frame_velocity(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
PyObject *py_rotation_defect(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
PyObject *py_position_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
PyObject *py_unit_defect(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
