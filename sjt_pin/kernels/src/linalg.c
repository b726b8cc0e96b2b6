/* Small dense linear algebra on row-major scratch: Gram matrices, a bound of the loop gain,
 * Cholesky, the Jacobi eigen-decomposition, the Woodbury identity; and their Python entries. */

#include "kernels.h"

/* -- small dense linear algebra ------------------------------------------------------------- */

/* The p x p loop matrix of J_w S J_w^T (m x m when use_rows, m <= n), or of
 * S^1/2 J_w^T J_w S^1/2 (n x n): both have the same non-zero eigenvalues. */
void gram(Mat J, const double *sw, const double *s, int use_rows, double *out)
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
double loop_bound_c(const double *A, Py_ssize_t p, int products, double *B, double *C)
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
int cholesky_factor(double *A, Py_ssize_t p, double shift)
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
void cholesky_substitute(const double *L, Py_ssize_t p, const double *rhs, double *out)
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

int cholesky_solve_c(double *A, Py_ssize_t p, double shift, const double *rhs, double *out)
{
    if (!cholesky_factor(A, p, shift)) return 0;
    cholesky_substitute(A, p, rhs, out);
    return 1;
}

/* Eigen-decomposition of the symmetric A (p x p) by cyclic Jacobi rotations, in place: A's
 * diagonal holds the eigenvalues and V's columns the eigenvectors. */
void symmetric_eigen_c(double *A, double *V, Py_ssize_t p)
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
PyObject *py_cholesky_solve(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
PyObject *py_loop_bound(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
PyObject *py_symmetric_eigen(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
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
