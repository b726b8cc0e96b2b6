/* The derivative of SE(3)'s logarithm: with e = log6(N) a pose error (m, rad) and J its CLIK
 * rows, Jlog6(N^-1) J is the exact derivative of e, where J alone is its first order near the
 * target (the set-point search's model on its general path, Task.error_jacobian). */

#include "kernels.h"

/* c = a b for 3 x 3 row-major matrices */
static void mul3(const double *a, const double *b, double *c)
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            c[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
}

static void skew(const double *x, double *S)
{
    S[0] = 0.0, S[1] = -x[2], S[2] = x[1];
    S[3] = x[2], S[4] = 0.0, S[5] = -x[0];
    S[6] = -x[1], S[7] = x[0], S[8] = 0.0;
}

/* The coefficients of the coupling block Q(v, w) of SE(3)'s Jacobian (Barfoot and Furgale,
 * IEEE T-RO 2014, eq. 102) at t = |w|: (t - sin t) / t^3, (1 - t^2/2 - cos t) / t^4 and
 * ((1 - t^2/2 - cos t) / t^4 - 3 (t - sin t - t^3/6) / t^5) / 2, as series below 0.3 rad
 * (to t^8: the closed forms cancel there). */
static void coupling_coefficients(double t, double *c1, double *c2, double *c3)
{
    double t2 = t * t, d;
    if (t < 0.3) {
        *c1 = 1.0 / 6 + t2 * (-1.0 / 120 + t2 * (1.0 / 5040 + t2 * (-1.0 / 362880
              + t2 / 39916800)));
        *c2 = -1.0 / 24 + t2 * (1.0 / 720 + t2 * (-1.0 / 40320 + t2 * (1.0 / 3628800
              - t2 / 479001600)));
        d = -1.0 / 120 + t2 * (1.0 / 5040 + t2 * (-1.0 / 362880 + t2 * (1.0 / 39916800
            - t2 / 6227020800.0)));
    } else {
        double s = sin(t), c = cos(t);
        *c1 = (t - s) / (t2 * t);
        *c2 = (1.0 - 0.5 * t2 - c) / (t2 * t2);
        d = (t - s - t2 * t / 6.0) / (t2 * t2 * t);
    }
    *c3 = 0.5 * (*c2 - 3.0 * d);
}

/* G = Jlog6(N^-1) (6 x 6, row-major, [linear; angular]) from xi = (v, w) = log6(N):
 * [[A, -A Q(v, w) A], [0, A]] with A = Jlog3(-w) = I - W/2 + k W^2, k = 1/t^2 - cot(t/2)/(2t),
 * and Q the coupling block of SE(3)'s left Jacobian at (v, w). */
static void jlog6_inverse_c(const double *xi, double *G)
{
    double W[9], V[9], WW[9], WV[9], VW[9], WVW[9], T[9], A[9], Q[9], AQ[9], B[9];
    skew(xi, V);
    skew(xi + 3, W);
    double t = sqrt(xi[3] * xi[3] + xi[4] * xi[4] + xi[5] * xi[5]), c1, c2, c3;
    double k = t < 1e-2 ? 1.0 / 12 + t * t / 720 + t * t * t * t / 30240
                        : 1.0 / (t * t) - 1.0 / (2.0 * t * tan(0.5 * t));
    coupling_coefficients(t, &c1, &c2, &c3);
    mul3(W, W, WW);
    mul3(W, V, WV);
    mul3(V, W, VW);
    mul3(WV, W, WVW);
    for (int i = 0; i < 9; i++) {
        A[i] = (i % 4 == 0 ? 1.0 : 0.0) - 0.5 * W[i] + k * WW[i];
        Q[i] = 0.5 * V[i] + c1 * (WV[i] + VW[i] + WVW[i]) + 3.0 * c2 * WVW[i];
    }
    mul3(W, WV, T);  /* W W V */
    for (int i = 0; i < 9; i++) Q[i] -= c2 * T[i];
    mul3(VW, W, T);  /* V W W */
    for (int i = 0; i < 9; i++) Q[i] -= c2 * T[i];
    mul3(WVW, W, T);  /* W V W W */
    for (int i = 0; i < 9; i++) Q[i] -= c3 * T[i];
    mul3(W, WVW, T);  /* W W V W */
    for (int i = 0; i < 9; i++) Q[i] -= c3 * T[i];
    mul3(A, Q, AQ);
    mul3(AQ, A, B);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            G[6 * i + j] = G[6 * (i + 3) + j + 3] = A[3 * i + j];
            G[6 * i + j + 3] = -B[3 * i + j];
            G[6 * (i + 3) + j] = 0.0;
        }
}

/* jlog6_inverse(xi, out): out (6 x 6) = Jlog6(N^-1) for xi = log6(N) */
PyObject *py_jlog6_inverse(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 2, "jlog6_inverse")) return NULL;
    Arg xi = {0}, out = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &xi, 0, 1, "xi") || acquire(args[1], &out, 1, 2, "out")) goto done;
    double *x = vec(&xi, "xi"), *G = out_mat(&out, "out");
    if (!x || !G) goto done;
    if (length(&xi) != 6 || out.view.shape[0] != 6 || out.view.shape[1] != 6) {
        PyErr_SetString(PyExc_ValueError, "jlog6_inverse: xi must have 6 entries, out 6 x 6");
        goto done;
    }
    jlog6_inverse_c(x, G);
    result = Py_NewRef(Py_None);
done:
    release(&xi); release(&out);
    return result;
}
