"""Compiled inner loops (numba): each stage of a step in one call instead of a dozen numpy calls.

On arrays of 6 x n numbers every numpy call costs about 0.3 us whatever it computes, so a step
would spend more in call overhead than in arithmetic. Each function here does its whole loop in
one compiled call; ``tests/test_kernels.py`` checks them against the numpy reference formulas of
:mod:`.mappings`. They are compiled on first use and cached in a per-user folder
(``$XDG_CACHE_HOME/sjt-pin/numba``, or ``$NUMBA_CACHE_DIR`` when set), never inside the
installed package.

Conventions: ``J`` (m, n) holds unweighted task rows, ``sw`` (m) the square roots of the row
weights, so the mappings see ``J_w = diag(sw) J``; ``step`` (n) is the joint displacement
``q_dot dt`` of one control period.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
from numba.core import config as _numba_config

#: Where the compiled kernels are cached (unless ``NUMBA_CACHE_DIR`` says otherwise).
CACHE_DIR = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"),
                         "sjt-pin", "numba")


def compiled(function):
    """``numba.njit(cache=True, nogil=True)``, caching under :data:`CACHE_DIR`.

    numba reads its cache folder when a function is decorated; it is set only for the duration
    of the decoration, so other packages in the same process keep their own setting.
    """
    saved = _numba_config.CACHE_DIR
    if not saved:
        _numba_config.CACHE_DIR = CACHE_DIR
    try:
        return numba.njit(cache=True, nogil=True)(function)
    finally:
        _numba_config.CACHE_DIR = saved


# -- parameter and result slots of the method kernels ---------------------------------------------
#: ``prm`` of :func:`transpose_step` and :func:`least_squares_step`.
P_DT, P_GAIN_MODE, P_GAIN_ARG, P_FF_MODE, P_MU, P_COL_TOL, P_SCALED, P_RCOND, P_LENGTH2, \
    P_FB_MODE, P_LM, P_ERROR_ROWS = range(12)
#: gain modes: K as given; "auto" c K / (dt lambda_hat), lambda_hat >= lambda_max(J M)
GAIN_FIXED, GAIN_AUTO = 0, 1
#: feed-forward: none; through the feedback's own mapping (paper eq. 21); damped sqrt(D) solve
FF_NONE, FF_TRANSPOSE, FF_DAMPED = 0, 1, 2
#: feedback of the transpose methods: S J^T K e (eq. 10, 21), or through the damped solve
FB_TRANSPOSE, FB_DAMPED = 0, 1
#: results of the method kernels, at ``work[INFO + I_*]``
I_E_SQ, I_FF_SQ, I_GAIN, I_LOOP, I_STALL, I_TRACE, I_EW_SQ = range(7)
INFO_SIZE = 7
#: layout of ``work``: parameters, results, scratch
INFO, SCRATCH = 12, 20
#: smallest eigenvalue of J J^T, relative to the largest, that the pseudoinverse inverts: the
#: eigenvalues of a Gram matrix are exact to about 1e3 eps of the largest
EIGEN_FLOOR = 1e3 * 2.220446049250313e-16
#: automatic gain: matrix products of the loop-eigenvalue bound (tr A^(2^(s+1)))^(1/2^(s+1))
BOUND_PRODUCTS = 2


def work_size(m: int, n: int) -> int:
    """Length of ``work`` the method kernels need for m task rows and n joints."""
    p = min(m, n)
    return SCRATCH + 4 * m + 6 * n + 3 * p * p


# -- small dense linear algebra ----------------------------------------------------------------
@compiled
def _gram(J, sw, s, use_rows, out):
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


@compiled
def cholesky_solve(A, shift, rhs, out):
    """``out = (A + shift I)^-1 rhs`` for a symmetric PSD ``A``, ``shift`` > 0 (A is overwritten
    by its Cholesky factor). Returns False if the shifted matrix is not positive definite."""
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
    for i in range(p):  # L y = rhs
        acc = rhs[i]
        for k in range(i):
            acc -= A[i, k] * out[k]
        out[i] = acc / A[i, i]
    for i in range(p - 1, -1, -1):  # L^T x = y
        acc = out[i]
        for k in range(i + 1, p):
            acc -= A[k, i] * out[k]
        out[i] = acc / A[i, i]
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


# -- the method kernels ------------------------------------------------------------------------
@compiled
def transpose_step(J, e, ff, rows, mask, work, step):
    """One step of a Jacobian-transpose-type CLIK law (JT eq. 10, SJT eq. 21)::

        step = dt [ S J_w^T (gain K e_w) + feed-forward ],     e_w = sw e

    ``ff`` is the desired task velocity (read only with a feed-forward mode), ``rows`` holds
    the row weights' square roots sw and the per-row gains K (1/s); ``work`` holds the
    parameters (slots ``P_*``), receives the results (slots ``I_*``, offset :data:`INFO`) and is
    the scratch space from :data:`SCRATCH` on.

    S = D = diag(alpha_i), alpha_i = 1 / max(|J_w,i|^2, l^2) (eq. 18, with the characteristic
    length l^2 = ``P_LENGTH2`` as a floor) for SJT (``P_SCALED``), S = I for JT; both zero on
    joints with ``mask == 0``, and alpha zero on columns whose squared norm is not above
    ``P_COL_TOL``. ``gain`` is 1 (fixed K) or, "auto", c / (dt lambda_hat) with
    lambda_hat >= lambda_max(J_w S J_w^T) from :func:`loop_bound` and c = ``P_GAIN_ARG``. The
    feed-forward is S J_w^T ff_w (the paper's eq. 21) or D J_w^T (J_w D J_w^T + mu^2 I)^-1 ff_w,
    a damped solve on the unit-norm columns J_w sqrt(D) (unit-free; mu = ``P_MU``). With the
    damped feedback (``P_FB_MODE``) the feedback goes through that solve too,
    ``D J_w^T (J_w D J_w^T + (mu^2 + lm |e_w|^2) I)^-1 (ff_w + gain K e_w)`` with the
    Levenberg-Marquardt weight lm = ``P_LM``; its loop eigenvalues are below 1, so "auto" is
    gain = c / dt.

    Results: |e|^2, |ff|^2, the gain factor, lambda_hat (1 when not computed), the stall ratio
    (K e_w)^T J_w S J_w^T (K e_w) / (|K e_w|^2 tr) in [0, 1], tr(J_w S J_w^T) and |e_w|^2; the
    error norms count the first ``P_ERROR_ROWS`` rows, the tasks that take targets (a posture
    task's rows come after them).
    """
    m, n = J.shape
    dt = work[P_DT]
    tol = work[P_COL_TOL]
    length2 = work[P_LENGTH2]
    scaled = work[P_SCALED] != 0.0
    damped = work[P_FB_MODE] == FB_DAMPED
    kew = work[SCRATCH:SCRATCH + m]
    alpha = work[SCRATCH + m:SCRATCH + m + n]
    s = work[SCRATCH + m + n:SCRATCH + m + 2 * n]
    g = work[SCRATCH + m + 2 * n:SCRATCH + m + 3 * n]
    error_rows = int(work[P_ERROR_ROWS])
    e_sq, ew_sq, kew_sq = 0.0, 0.0, 0.0
    for i in range(m):
        ew = rows[0, i] * e[i]
        kew[i] = rows[1, i] * ew
        kew_sq += kew[i] * kew[i]
        if i < error_rows:
            e_sq += e[i] * e[i]
            ew_sq += ew * ew
    trace = 0.0
    for j in range(n):
        norm, acc = 0.0, 0.0
        if mask[j] != 0.0:
            for i in range(m):
                wij = rows[0, i] * J[i, j]
                norm += wij * wij
                acc += wij * kew[i]
        alpha[j] = 1.0 / max(norm, length2) if norm > tol else 0.0
        s[j] = alpha[j] if scaled else mask[j]
        g[j] = acc
        trace += s[j] * norm
    bound = 1.0
    if work[P_GAIN_MODE] == GAIN_FIXED:
        gain = 1.0
    elif damped:
        gain = work[P_GAIN_ARG] / dt
    else:
        bound = _loop_bound(J, rows[0], s, work, m, n)
        gain = work[P_GAIN_ARG] / (dt * bound) if bound > 0.0 else 0.0
    stall = 0.0
    for j in range(n):
        stall += s[j] * g[j] * g[j]
        step[j] = 0.0 if damped else dt * gain * s[j] * g[j]
    stall = stall / (kew_sq * trace) if kew_sq > 0.0 and trace > 0.0 else 0.0
    ff_sq = 0.0
    ff_mode = work[P_FF_MODE]
    if ff_mode != FF_NONE:
        for i in range(m):
            ff_sq += ff[i] * ff[i]
    if damped:
        v = work[SCRATCH + 4 * m + 6 * n - m:SCRATCH + 4 * m + 6 * n]
        for i in range(m):
            v[i] = gain * rows[1, i] * e[i]
            if ff_mode != FF_NONE:
                v[i] += ff[i]
        _damped_solve(J, v, rows[0], alpha, work, m, n, dt, step, work[P_LM] * ew_sq)
    elif ff_mode == FF_TRANSPOSE:
        for j in range(n):
            acc = 0.0
            for i in range(m):
                acc += rows[0, i] * rows[0, i] * J[i, j] * ff[i]
            step[j] += dt * s[j] * acc
    elif ff_mode == FF_DAMPED:
        _damped_solve(J, ff, rows[0], alpha, work, m, n, dt, step, 0.0)
    work[INFO + I_E_SQ] = e_sq
    work[INFO + I_FF_SQ] = ff_sq
    work[INFO + I_GAIN] = gain
    work[INFO + I_LOOP] = bound
    work[INFO + I_STALL] = stall
    work[INFO + I_TRACE] = trace
    work[INFO + I_EW_SQ] = ew_sq


@compiled
def _matrices(work, m, n):
    """Three p x p scratch matrices, p = min(m, n), after the vectors of the scratch space."""
    p = min(m, n)
    base = SCRATCH + 4 * m + 6 * n
    A = work[base:base + p * p].reshape((p, p))
    B = work[base + p * p:base + 2 * p * p].reshape((p, p))
    C = work[base + 2 * p * p:base + 3 * p * p].reshape((p, p))
    return A, B, C


@compiled
def _loop_bound(J, sw, s, work, m, n):
    """:func:`loop_bound` of J_w S J_w^T."""
    A, B, C = _matrices(work, m, n)
    _gram(J, sw, s, m <= n, A)
    return loop_bound(A, BOUND_PRODUCTS, B, C)


@compiled
def _damped_solve(J, ff, sw, alpha, work, m, n, dt, step, extra):
    """``step += dt D J_w^T (J_w D J_w^T + mu^2 I)^-1 ff_w`` (m x m solve when m <= n), or the
    same as ``dt sqrt(D) (G + mu^2 I)^-1 sqrt(D) J_w^T ff_w`` with G = sqrt(D) J_w^T J_w sqrt(D)
    (push-through identity; n x n solve). The vectors use the scratch space after ``g``."""
    A, _, _ = _matrices(work, m, n)
    mu2 = work[P_MU] * work[P_MU] + extra
    vec = work[SCRATCH + m + 3 * n:SCRATCH + 3 * m + 6 * n]
    _gram(J, sw, alpha, m <= n, A)
    if m <= n:
        rhs, y = vec[0:m], vec[m:2 * m]
        for i in range(m):
            rhs[i] = sw[i] * ff[i]
        cholesky_solve(A, mu2, rhs, y)
        for j in range(n):
            acc = 0.0
            for i in range(m):
                acc += sw[i] * J[i, j] * y[i]
            step[j] += dt * alpha[j] * acc
    else:
        rhs, x = vec[0:n], vec[n:2 * n]
        for j in range(n):
            acc = 0.0
            for i in range(m):
                acc += sw[i] * sw[i] * J[i, j] * ff[i]
            rhs[j] = math.sqrt(alpha[j]) * acc
        cholesky_solve(A, mu2, rhs, x)
        for j in range(n):
            step[j] += dt * math.sqrt(alpha[j]) * x[j]


@compiled
def least_squares_step(J, e, ff, rows, mask, work, step):
    """One step of the pseudoinverse (JP, eq. 8) or damped least-squares CLIK law::

        step = dt M(J_w) (ff_w + gain K e_w),  M = J^+  or  J^T (J J^T + lambda^2 I)^-1

    on the columns with ``mask != 0`` (``rows`` and ``work`` as for :func:`transpose_step`).
    ``P_MU`` is the damping lambda (task units; DLS), or 0 for the pseudoinverse, whose
    singular values below ``P_RCOND`` sigma_max count as zero. The gain factor is
    ``P_GAIN_ARG / dt`` for "auto" (both methods' loop eigenvalues are at most 1) and 1 for a
    fixed K.
    """
    m, n = J.shape
    p = min(m, n)
    use_rows = m <= n
    dt = work[P_DT]
    gain = work[P_GAIN_ARG] / dt if work[P_GAIN_MODE] != GAIN_FIXED else 1.0
    sw = rows[0]
    vec = work[SCRATCH:SCRATCH + 4 * m + 6 * n]
    v, r, sol = vec[0:m], vec[m:m + n], vec[m + n:m + n + p]
    s = vec[m + 2 * n:m + 3 * n]
    A, V, _ = _matrices(work, m, n)
    e_sq, ew_sq, ff_sq = 0.0, 0.0, 0.0
    has_ff = work[P_FF_MODE] != FF_NONE
    error_rows = int(work[P_ERROR_ROWS])
    for i in range(m):
        ew = sw[i] * e[i]
        if i < error_rows:
            e_sq += e[i] * e[i]
            ew_sq += ew * ew
        v[i] = gain * rows[1, i] * ew
        if has_ff:
            v[i] += sw[i] * ff[i]
            ff_sq += ff[i] * ff[i]
    for j in range(n):
        s[j] = mask[j]
    _gram(J, sw, s, use_rows, A)
    # the right-hand side in the Gram matrix's space: v (rows) or J_w^T v (columns)
    for j in range(n):
        acc = 0.0
        if not use_rows:
            for i in range(m):
                acc += sw[i] * J[i, j] * v[i]
        r[j] = mask[j] * acc
    rhs = v if use_rows else r
    damping = work[P_MU]
    if damping > 0.0:
        cholesky_solve(A, damping * damping, rhs, sol)
    else:
        symmetric_eigen(A, V)
        top = 0.0
        for c in range(p):
            top = max(top, A[c, c])
        cutoff = max(work[P_RCOND] * work[P_RCOND], EIGEN_FLOOR) * top
        for i in range(p):
            sol[i] = 0.0
        for c in range(p):
            lam = A[c, c]
            if lam <= cutoff or lam <= 0.0:
                continue
            proj = 0.0
            for i in range(p):
                proj += V[i, c] * rhs[i]
            proj /= lam
            for i in range(p):
                sol[i] += proj * V[i, c]
    for j in range(n):
        if use_rows:
            acc = 0.0
            for i in range(m):
                acc += sw[i] * J[i, j] * sol[i]
            step[j] = dt * mask[j] * acc
        else:
            step[j] = dt * mask[j] * sol[j]
    work[INFO + I_E_SQ] = e_sq
    work[INFO + I_FF_SQ] = ff_sq
    work[INFO + I_GAIN] = gain
    work[INFO + I_LOOP] = 1.0
    work[INFO + I_STALL] = 1.0
    work[INFO + I_TRACE] = 0.0
    work[INFO + I_EW_SQ] = ew_sq


# -- tasks ---------------------------------------------------------------------------------------
@compiled
def frame_velocity(oMf, oMd, velocity, out):
    """The desired velocity (``velocity`` = [p_dot_d, omega_d], world axes at the desired
    origin) as a twist of the frame at ``oMf``, in its LOCAL axes:
    ``[R^T (p_dot_d + omega_d x (p_f - p_d)), R^T omega_d]``; ``oMf``, ``oMd`` are 4x4."""
    d0 = oMf[0, 3] - oMd[0, 3]
    d1 = oMf[1, 3] - oMd[1, 3]
    d2 = oMf[2, 3] - oMd[2, 3]
    w0, w1, w2 = velocity[3], velocity[4], velocity[5]
    v0 = velocity[0] + w1 * d2 - w2 * d1
    v1 = velocity[1] + w2 * d0 - w0 * d2
    v2 = velocity[2] + w0 * d1 - w1 * d0
    for a in range(3):
        out[a] = oMf[0, a] * v0 + oMf[1, a] * v1 + oMf[2, a] * v2
        out[3 + a] = oMf[0, a] * w0 + oMf[1, a] * w1 + oMf[2, a] * w2


@compiled
def rotation_defect(M):
    """max |R^T R - I| of the rotation block of the 4x4 ``M``: 0 for a rigid transform, ``inf``
    when det R <= 0 or the last row is not [0 0 0 1], NaN when R holds a NaN."""
    defect = 0.0
    for a in range(3):
        for b in range(3):
            acc = -1.0 if a == b else 0.0
            for c in range(3):
                acc += M[c, a] * M[c, b]
            defect = max(defect, abs(acc))
    det = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
           - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
           + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))
    if defect != defect or det != det:
        return math.nan
    if not det > 0.0 or M[3, 0] != 0.0 or M[3, 1] != 0.0 or M[3, 2] != 0.0 or M[3, 3] != 1.0:
        return math.inf
    return defect


# -- limits ------------------------------------------------------------------------------------
@compiled
def limits_violated(q, step, q_index, v_index, lower, upper, inv_speed):
    """Whether ``q + step`` leaves a position limit (bit 1: a limited 1-DoF joint k, at
    ``q_index[k]`` / ``v_index[k]``, would end outside [lower_k, upper_k], or starts there) or
    some ``|step_j| inv_speed_j`` exceeds 1 (bit 2; ``inv_speed = 1 / (v_max dt)``)."""
    bits = 0
    for c in range(q_index.shape[0]):
        new = q[q_index[c]] + step[v_index[c]]
        if new > upper[c] or new < lower[c]:
            bits = 1
            break
    for j in range(step.shape[0]):
        if abs(step[j]) * inv_speed[j] > 1.0:
            bits |= 2
            break
    return bits


@compiled
def clamp_pass(q, step, q_index, v_index, lower, upper, recovery, fixed, fixed_step):
    """Fix the joints that ``q + step`` takes out of ``[lower, upper]``; returns how many.

    A fixed joint inside its range moves exactly onto the limit. A joint that starts outside
    (a start configuration out of range) is driven back toward the range by at most
    ``recovery`` (its speed limit times dt) and no further than the limit. ``fixed`` and
    ``fixed_step`` (tangent-indexed) are updated in place.
    """
    count = 0
    for c in range(q_index.shape[0]):
        v = v_index[c]
        if fixed[v]:
            continue
        qc, lo, hi = q[q_index[c]], lower[c], upper[c]
        new = qc + step[v]
        if lo <= qc <= hi:
            if lo <= new <= hi:
                continue
            fixed_step[v] = min(max(new, lo), hi) - qc
        elif qc > hi:
            fixed_step[v] = -min(recovery[c], qc - hi)
        else:
            fixed_step[v] = min(recovery[c], lo - qc)
        fixed[v] = True
        count += 1
    return count


# -- solve (set-point IK) ------------------------------------------------------------------------
@compiled
def _scaled_gradient(J, r, scale, out):
    """``out = S J^T r``; returns ``|out|^2``."""
    m, n = J.shape
    total = 0.0
    for j in range(n):
        acc = 0.0
        for i in range(m):
            acc += J[i, j] * r[i]
        out[j] = scale[j] * acc
        total += out[j] * out[j]
    return total


@compiled
def cgls(J, e, scale, iterations, tol, out):
    """Preconditioned CGLS for ``min |J d - e|`` with ``d = S y``, S = diag(``scale``), into
    ``out``. Stops after ``iterations`` or once ``|S J^T r|^2`` has fallen below ``tol`` times
    its start. Only products with J and J^T: nothing to factorise, nothing that breaks at a
    singularity."""
    m, n = J.shape
    y = np.zeros(n)
    r = e.copy()
    s = np.empty(n)
    p = np.empty(n)
    Jp = np.empty(m)
    gamma = gamma0 = _scaled_gradient(J, r, scale, s)
    p[:] = s
    for _ in range(iterations):
        if gamma == 0.0 or gamma <= tol * gamma0:
            break
        curvature = 0.0
        for i in range(m):
            acc = 0.0
            for j in range(n):
                acc += J[i, j] * scale[j] * p[j]
            Jp[i] = acc
            curvature += acc * acc
        if curvature <= 0.0:
            break
        t = gamma / curvature
        for j in range(n):
            y[j] += t * p[j]
        for i in range(m):
            r[i] -= t * Jp[i]
        gamma_new = _scaled_gradient(J, r, scale, s)
        beta = gamma_new / gamma
        for j in range(n):
            p[j] = s[j] + beta * p[j]
        gamma = gamma_new
    for j in range(n):
        out[j] = y[j] * scale[j]


@compiled
def pose_feedforward(oMf, oMd, velocity, out):
    """:func:`frame_velocity` into ``out`` when ``velocity`` has 6 entries (nothing when it is
    empty); returns :func:`rotation_defect` of ``oMd`` (the pose tasks' check of a target)."""
    if velocity.shape[0] == 6:
        frame_velocity(oMf, oMd, velocity, out)
    return rotation_defect(oMd)


@compiled
def position_rows(J6, oMf, p_d, velocity, axes, J_out, e_out, ff_out):
    """A position task's rows: the world-axis rows ``axes`` of the LOCAL_WORLD_ALIGNED Jacobian
    ``J6``, ``e = p_d - p`` and the desired linear velocity (``velocity[:3]``, world axes; not
    written when ``velocity`` is empty)."""
    n = J6.shape[1]
    for r in range(axes.shape[0]):
        a = axes[r]
        for j in range(n):
            J_out[r, j] = J6[a, j]
        e_out[r] = p_d[a] - oMf[a, 3]
        if velocity.shape[0] >= 3:
            ff_out[r] = velocity[a]
