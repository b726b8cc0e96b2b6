/* The Python side's buffers: float64 arrays (numpy's read directly, any other object through
 * the buffer protocol), and the checks of a solver's work vector and index tables. */

#include "kernels.h"

/* numpy's C API, in this file only (the others read an Arg): built against numpy 2, for every
 * numpy the package supports (pyproject.toml: numpy>=1.24) */
#define NPY_NO_DEPRECATED_API NPY_1_24_API_VERSION
#define NPY_TARGET_VERSION NPY_1_24_API_VERSION
#include <numpy/arrayobject.h>

int args_init(void)
{
    import_array1(-1);
    return 0;
}

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

/* a numpy array's float64 data read in place: what the buffer protocol gives, without its
 * cost (about 50 ns an argument, most of a small kernel's call); 1 when obj is no such array
 * of at most 2 dimensions (the caller then asks the buffer protocol, which also makes the
 * errors). As numpy's buffers do, a C-contiguous array has C strides (numpy may give a
 * dimension of length 0 or 1 any stride). */
static int acquire_array(PyObject *obj, Arg *a, int writable, int ndim)
{
    if (!PyArray_Check(obj)) return 1;
    PyArrayObject *arr = (PyArrayObject *)obj;
    int nd = PyArray_NDIM(arr);
    if (PyArray_TYPE(arr) != NPY_DOUBLE || !PyArray_ISNOTSWAPPED(arr) || nd > 2
        || (writable && !PyArray_ISWRITEABLE(arr)) || (ndim >= 0 && nd != ndim))
        return 1;
    a->view.buf = PyArray_DATA(arr);
    a->view.ndim = nd;
    a->view.shape = PyArray_DIMS(arr);  /* (npy_intp is Py_ssize_t) */
    a->view.strides = PyArray_STRIDES(arr);
    if (nd > 0 && PyArray_IS_C_CONTIGUOUS(arr)) {
        a->strides[nd - 1] = 8;
        if (nd == 2) a->strides[0] = 8 * a->view.shape[1];
        a->view.strides = a->strides;
    }
    return 0;
}

/* a new C-contiguous float64 array of `nd` (1 or 2) dimensions, its data in *data; NULL with
 * a Python error set */
PyObject *new_array(int nd, const Py_ssize_t *dims, double **data)
{
    npy_intp shape[2] = {dims[0], nd > 1 ? dims[1] : 0};
    PyObject *out = PyArray_SimpleNew(nd, shape, NPY_DOUBLE);
    if (out) *data = (double *)PyArray_DATA((PyArrayObject *)out);
    return out;
}

/* an array new_array made, read-only from now on */
void freeze_array(PyObject *array)
{
    PyArray_CLEARFLAGS((PyArrayObject *)array, NPY_ARRAY_WRITEABLE);
}

/* a float64 buffer of `ndim` dimensions (-1: any) */
int acquire(PyObject *obj, Arg *a, int writable, int ndim, const char *name)
{
    a->held = 0;
    a->copy = NULL;
    if (!acquire_array(obj, a, writable, ndim)) return 0;
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
