/* The Python side's buffers: float64 arrays through the buffer protocol, and the checks of
 * a solver's work vector and index tables. */

#include "kernels.h"

/* -- the Python side: buffers ------------------------------------------------------------------- */

static int format_ok(const Py_buffer *b)
{
    const char *f = b->format ? b->format : "B";
    if (*f == '<' || *f == '=' || *f == '@') f++;
    if (b->itemsize != 8 || f[1] != '\0') return 0;
    return *f == 'd';
}

void release(Arg *a)
{
    if (a->held) PyBuffer_Release(&a->view);
    a->held = 0;
    free(a->copy);
    a->copy = NULL;
}

/* a float64 buffer of `ndim` dimensions (-1: any) */
int acquire(PyObject *obj, Arg *a, int writable, int ndim, const char *name)
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

/* a contiguous pointer to a 1-D buffer (a copy of a strided read-only one) */
double *vec(Arg *a, const char *name)
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
double *out_vec(Arg *a, const char *name)
{
    if (a->view.ndim != 1 || (a->view.strides[0] != 8 && a->view.shape[0] > 1)) {
        PyErr_Format(PyExc_ValueError, "%s must be a contiguous 1-D array", name);
        return NULL;
    }
    return (double *)a->view.buf;
}

Mat mat(const Arg *a)
{
    Mat M = {(const double *)a->view.buf, a->view.shape[0], a->view.shape[1],
             a->view.strides[0] / 8, a->view.strides[1] / 8};
    return M;
}

double *out_mat(Arg *a, const char *name)
{
    if (a->view.ndim != 2 || a->view.strides[1] != 8 || a->view.strides[0] != 8 * a->view.shape[1]) {
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous 2-D array", name);
        return NULL;
    }
    return (double *)a->view.buf;
}

int nargs_ok(Py_ssize_t got, Py_ssize_t want, const char *name)
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
int check_work(const Arg *work, Py_ssize_t m, Py_ssize_t n, Py_ssize_t nq)
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
        || !region_ok(w[P_CLAMPED], CLAMPED_SIZE(m, n), size)) goto bad;
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
int table_ok(const double *table, Py_ssize_t c, Py_ssize_t nq, Py_ssize_t n, int pairs,
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
