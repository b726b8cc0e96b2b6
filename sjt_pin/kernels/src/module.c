/* The compiled inner loops of sjt-pin: one step of each family of CLIK mappings (the paper's
 * eq. 8, 10, 21 and the damped forms) and their joint limits (the set-point search and the
 * tasks' small transforms are C++, in the module _core). Plain C on the CPython API, built by
 * `pip install`: nothing is compiled at run time. Arrays come in through the buffer protocol
 * (float64; 2-D arrays with any strides, 1-D inputs copied when not contiguous); the Python
 * reference formulas are in sjt_pin/mappings.py and tests/test_kernels.py checks these
 * functions against them.
 *
 * Every function keeps the name, arguments and results of the Python-visible kernel it
 * implements (see sjt_pin/kernels/__init__.py); the slot numbers of a solver's `work` vector
 * are those of sjt_pin/kernels/layout.py, exported below and checked by a test. */

#include "kernels.h"

static const char *const PARAMETER_NAMES[] = { PARAMETERS(SLOT_NAME) };
static const char *const RESULT_NAMES[] = { RESULTS(SLOT_NAME) };
static const char *const SMOOTH_PART_NAMES[] = { SMOOTH_PARTS(SLOT_NAME) };
static const char *const LIMIT_CODE_NAMES[] = { LIMIT_CODES(SLOT_NAME) };

static PyMethodDef methods[] = {
    {"transpose_step", (PyCFunction)(void (*)(void))py_transpose_step, METH_FASTCALL,
     "transpose_step(J, e, ff, q, work, step) -> status: one step of a Jacobian-transpose-type "
     "CLIK law (JT eq. 10, SJT eq. 21, the damped forms), then the limits."},
    {"least_squares_step", (PyCFunction)(void (*)(void))py_least_squares_step, METH_FASTCALL,
     "least_squares_step(J, e, ff, q, work, step) -> status: one step of the pseudoinverse "
     "(eq. 8) or damped least-squares CLIK law, then the limits."},
    {"follow_motion", (PyCFunction)(void (*)(void))py_follow_motion, METH_FASTCALL,
     "follow_motion(step, dt, dq, ddq): the velocity step / dt and acceleration (its change "
     "over dt) a step commands, into dq and ddq in place."},
    {"cholesky_solve", (PyCFunction)(void (*)(void))py_cholesky_solve, METH_FASTCALL,
     "cholesky_solve(A, shift, rhs, out) -> bool: out = (A + shift I)^-1 rhs (A overwritten)."},
    {"loop_bound", (PyCFunction)(void (*)(void))py_loop_bound, METH_FASTCALL,
     "loop_bound(A, products, B, C) -> float: an upper bound of lambda_max of the PSD A."},
    {"symmetric_eigen", (PyCFunction)(void (*)(void))py_symmetric_eigen, METH_FASTCALL,
     "symmetric_eigen(A, V): Jacobi eigen-decomposition in place (diag A, columns of V)."},
    {"nonnegative_qp", (PyCFunction)(void (*)(void))py_nonnegative_qp, METH_FASTCALL,
     "nonnegative_qp(Q, r, y) -> int: y = argmin 1/2 y^T Q y + r^T y over y >= 0 (NNLS)."},
    {"project_rows", (PyCFunction)(void (*)(void))py_project_rows, METH_FASTCALL,
     "project_rows(dq, Jw, A, b, lower, upper, moving, out) -> int: the constraint stage's "
     "smallest correction of dq onto A x <= b and the box (constraints.project)."},
    {"rows_step", (PyCFunction)(void (*)(void))py_rows_step, METH_FASTCALL,
     "rows_step(J, q, A, b, lower, upper, work, step) -> int: a kernel step against general "
     "rows and bounds: 0 kept, 1 projected in place, -1 outside the bounds."},
    {"smooth_rows_step", (PyCFunction)(void (*)(void))py_smooth_rows_step, METH_FASTCALL,
     "smooth_rows_step(J, q, A, b, lower, upper, previous, work, step) -> int: a step of the "
     "compiled acceleration/jerk stage against general rows and bounds: 0 kept, 1 projected "
     "within every box, 2 projected with smoothness yielding, -1 a bound outside the hard box."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "The compiled inner loops of sjt-pin (see sjt_pin/kernels/__init__.py).", -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void)
{
    if (args_init() < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    /* every slot by its name: kernels/layout.py takes them from here (no Python module holds
     * a slot's number) */
    for (int i = 0; i < P_COUNT; i++)
        if (PyModule_AddIntConstant(m, PARAMETER_NAMES[i], i) < 0) goto fail;
    for (int i = 0; i < I_COUNT; i++)
        if (PyModule_AddIntConstant(m, RESULT_NAMES[i], i) < 0) goto fail;
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
    EXPORT_INT(CLAMPED) EXPORT_INT(SCALED) EXPORT_INT(BOUND_PRODUCTS) EXPORT_INT(BRAKING_STEPS)
    EXPORT_FLOAT(EIGEN_FLOOR) EXPORT_FLOAT(BOUND_TOL) EXPORT_FLOAT(RANK_TOL)
    EXPORT_FLOAT(BRAKING_TOL) EXPORT_FLOAT(DUAL_RIDGE)
#undef EXPORT_INT
#undef EXPORT_FLOAT
    if (PyModule_AddIntConstant(m, "INFO", INFO) < 0
        || PyModule_AddIntConstant(m, "INFO_SIZE", I_COUNT) < 0)
        goto fail;
    return m;
fail:
    Py_DECREF(m);
    return NULL;
}
