"""Small dense linear algebra for the step kernels: Gram matrices, Cholesky, Jacobi eigenvalues
and the bound of a loop matrix's largest eigenvalue."""

from __future__ import annotations

import math

from .compile import compiled


@compiled(inline=True)
def gram(J, sw, s, use_rows, out):
    """The p x p loop matrix of ``J_w S J_w^T`` (m x m when ``use_rows``, m <= n), or of
    ``S^1/2 J_w^T J_w S^1/2`` (n x n): both have the same non-zero eigenvalues."""
    m, n = J.shape
    if use_rows:
        for a in range(m):
            for b in range(a + 1):
                acc = 0.0
                for j in range(n):
                    acc += s[j] * J[a, j] * J[b, j]
                out[a, b] = out[b, a] = acc * sw[a] * sw[b]
    else:
        for i in range(n):
            for j in range(i + 1):
                acc = 0.0
                if s[i] > 0.0 and s[j] > 0.0:
                    for a in range(m):
                        acc += sw[a] * sw[a] * J[a, i] * J[a, j]
                    acc *= math.sqrt(s[i] * s[j])
                out[i, j] = out[j, i] = acc


@compiled
def loop_bound(A, products, B, C):
    """An upper bound of lambda_max of the symmetric PSD matrix ``A``: (tr A^(2^(s+1)))^(1/2^(s+1))
    with s = ``products`` matrix products, at most rank^(1/2^(s+1)) times lambda_max (s = 2:
    within 25 % for rank 6). ``B`` and ``C`` are scratch of A's shape. 0 for A = 0."""
    p = A.shape[0]
    trace = 0.0
    for i in range(p):
        trace += A[i, i]
    if trace <= 0.0:
        return 0.0
    # invariant: A^(2^j) = exp(log_scale) B with tr(B) = 1
    log_scale = math.log(trace)
    for i in range(p):
        for j in range(p):
            B[i, j] = A[i, j] / trace
    for _ in range(products):
        frob = 0.0
        for i in range(p):
            for j in range(p):
                frob += B[i, j] * B[i, j]
        for i in range(p):
            for j in range(i + 1):
                acc = 0.0
                for k in range(p):
                    acc += B[i, k] * B[k, j]
                C[i, j] = C[j, i] = acc / frob
        for i in range(p):
            for j in range(p):
                B[i, j] = C[i, j]
        log_scale = 2.0 * log_scale + math.log(frob)
    frob = 0.0
    for i in range(p):
        for j in range(p):
            frob += B[i, j] * B[i, j]
    exponent = 2.0 ** (products + 1)
    return math.exp((2.0 * log_scale + math.log(frob)) / exponent)


@compiled(inline=True)
def cholesky_factor(A, shift):
    """Overwrite the lower triangle of the symmetric ``A`` with the Cholesky factor L of
    ``A + shift I``. Returns False if that matrix is not positive definite."""
    p = A.shape[0]
    for j in range(p):
        d = A[j, j] + shift
        for k in range(j):
            d -= A[j, k] * A[j, k]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, p):
            acc = A[i, j]
            for k in range(j):
                acc -= A[i, k] * A[j, k]
            A[i, j] = acc / d
    return True


@compiled(inline=True)
def cholesky_substitute(L, rhs, out):
    """``out = (L L^T)^-1 rhs`` for the lower-triangular factor ``L``."""
    p = L.shape[0]
    for i in range(p):  # L y = rhs
        acc = rhs[i]
        for k in range(i):
            acc -= L[i, k] * out[k]
        out[i] = acc / L[i, i]
    for i in range(p - 1, -1, -1):  # L^T x = y
        acc = out[i]
        for k in range(i + 1, p):
            acc -= L[k, i] * out[k]
        out[i] = acc / L[i, i]


@compiled(inline=True)
def cholesky_solve(A, shift, rhs, out):
    """``out = (A + shift I)^-1 rhs`` for a symmetric PSD ``A``, ``shift`` > 0 (A is overwritten
    by its Cholesky factor). Returns False if the shifted matrix is not positive definite."""
    if not cholesky_factor(A, shift):
        return False
    cholesky_substitute(A, rhs, out)
    return True


@compiled
def symmetric_eigen(A, V):
    """Eigen-decomposition of the symmetric ``A`` by cyclic Jacobi rotations, in place: on
    return A's diagonal holds the eigenvalues and ``V``'s columns the eigenvectors."""
    p = A.shape[0]
    for i in range(p):
        for j in range(p):
            V[i, j] = 1.0 if i == j else 0.0
    for _ in range(50):
        off, diag = 0.0, 0.0
        for i in range(p):
            diag += A[i, i] * A[i, i]
            for j in range(i):
                off += A[i, j] * A[i, j]
        if off <= 1e-32 * diag or off == 0.0:
            break
        for a in range(p - 1):
            for b in range(a + 1, p):
                apq = A[a, b]
                if apq == 0.0:
                    continue
                theta = (A[b, b] - A[a, a]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(p):
                    if k != a and k != b:
                        akp, akq = A[k, a], A[k, b]
                        A[k, a] = A[a, k] = c * akp - s * akq
                        A[k, b] = A[b, k] = s * akp + c * akq
                A[a, a] -= t * apq
                A[b, b] += t * apq
                A[a, b] = A[b, a] = 0.0
                for k in range(p):
                    vkp, vkq = V[k, a], V[k, b]
                    V[k, a] = c * vkp - s * vkq
                    V[k, b] = s * vkp + c * vkq
