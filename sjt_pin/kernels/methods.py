"""One step of each family of CLIK mappings — the transpose type (JT, SJT) and the least-squares
type (JP, DLS) — with the joint limits, in one compiled call.

Both take ``(J, e, ff, q, work, step)``: ``J`` (m, n) the unweighted task rows, ``e`` (m,) the
error, ``ff`` (m,) the desired task velocity (read when ``work[P_HAS_FF]``), ``q`` the
configuration, ``work`` the solver's parameters, constants, results and scratch (:mod:`.layout`),
``step`` (n,) the joint displacement ``q_dot dt`` they write. Rows are weighted by the square
roots of their weights ``sw``: the mappings see ``J_w = diag(sw) J``.

After the mapping, :func:`_limits` applies the limits as :class:`~sjt_pin.limits.PositionLimit`
and :class:`~sjt_pin.limits.VelocityLimit` describe them (their Python methods are the
reference): the escape velocity is added, a joint that would leave its position range is fixed
onto its limit (one outside it returns at its speed limit) and the mapping solved again for the
other joints with the task velocity the fixed ones leave them; then the free joints' step is
scaled down together if one is faster than its speed limit, and a fixed joint's motion is
capped at its own. The kernels return the status bits of
:mod:`.layout` (0: nothing to do but integrate).
"""

from __future__ import annotations

import math

from .compile import compiled
from .layout import (
    BOUND_PRODUCTS,
    CLAMPED,
    EIGEN_FLOOR,
    FB_DAMPED,
    FF_DAMPED,
    FF_TRANSPOSE,
    GAIN_FIXED,
    I_E_SQ,
    I_EW_SQ,
    I_FF_SQ,
    I_GAIN,
    I_LOOP,
    I_REGULAR,
    I_SCALE,
    I_STALL,
    I_TRACE,
    INFO,
    NON_FINITE,
    P_BOX,
    P_BOX_COUNT,
    P_CLAMPED,
    P_COL_TOL,
    P_DT,
    P_ERROR_ROWS,
    P_ESCAPING,
    P_EXTRA,
    P_FB_MODE,
    P_FF_MODE,
    P_GAIN_ARG,
    P_GAIN_MODE,
    P_HAS_FF,
    P_LENGTH2,
    P_LM,
    P_MASK,
    P_MU,
    P_RCOND,
    P_ROWS,
    P_SCALED,
    P_SCRATCH,
    P_SPEED,
    P_STALL_ERROR,
    P_STALL_RATIO,
    SCALED,
    STALLED,
)
from .limits import clamp_pass
from .linalg import (
    cholesky_factor,
    cholesky_solve,
    cholesky_substitute,
    gram,
    loop_bound,
    symmetric_eigen,
)

TRANSPOSE, LEAST_SQUARES = 0, 1


@compiled(inline=True)
def _matrices(work, m, n):
    """Three p x p scratch matrices, p = min(m, n), after the scratch vectors."""
    p = min(m, n)
    base = int(work[P_SCRATCH]) + 4 * m + 6 * n
    A = work[base:base + p * p].reshape((p, p))
    B = work[base + p * p:base + 2 * p * p].reshape((p, p))
    C = work[base + 2 * p * p:base + 3 * p * p].reshape((p, p))
    return A, B, C


@compiled(inline=True)
def _damped_solve(J, v, sw, alpha, work, m, n, dt, step, extra):
    """``step += dt D J_w^T (J_w D J_w^T + (mu^2 + extra) I)^-1 (sw v)`` (m x m solve when
    m <= n), or the same as ``dt sqrt(D) (G + (mu^2 + extra) I)^-1 sqrt(D) J_w^T (sw v)`` with
    G = sqrt(D) J_w^T J_w sqrt(D) (push-through identity; n x n solve)."""
    A, _, _ = _matrices(work, m, n)
    mu2 = work[P_MU] * work[P_MU] + extra
    start = int(work[P_SCRATCH]) + m + 3 * n
    gram(J, sw, alpha, m <= n, A)
    if m <= n:
        rhs, y = work[start:start + m], work[start + m:start + 2 * m]
        for i in range(m):
            rhs[i] = sw[i] * v[i]
        cholesky_solve(A, mu2, rhs, y)
        for j in range(n):
            acc = 0.0
            for i in range(m):
                acc += sw[i] * J[i, j] * y[i]
            step[j] += dt * alpha[j] * acc
    else:
        rhs, x = work[start:start + n], work[start + n:start + 2 * n]
        for j in range(n):
            acc = 0.0
            for i in range(m):
                acc += sw[i] * sw[i] * J[i, j] * v[i]
            rhs[j] = math.sqrt(alpha[j]) * acc
        cholesky_solve(A, mu2, rhs, x)
        for j in range(n):
            step[j] += dt * math.sqrt(alpha[j]) * x[j]


@compiled
def _transpose_core(J, e, ff, has_ff, mask, work, step):
    """The transpose-type mapping (see :func:`transpose_step`) on the joints of ``mask``;
    returns (|e|^2, |ff|^2, |e_w|^2, gain, lambda_hat, stall ratio, trace)."""
    m, n = J.shape
    dt = work[P_DT]
    rows = int(work[P_ROWS])
    sw = work[rows:rows + m]
    k = work[rows + m:rows + 2 * m]
    scratch = int(work[P_SCRATCH])
    kew = work[scratch:scratch + m]
    alpha = work[scratch + m:scratch + m + n]
    s = work[scratch + m + n:scratch + m + 2 * n]
    tol, length2 = work[P_COL_TOL], work[P_LENGTH2]
    scaled = work[P_SCALED] != 0.0
    damped = work[P_FB_MODE] == FB_DAMPED
    error_rows = int(work[P_ERROR_ROWS])
    e_sq, ew_sq, kew_sq = 0.0, 0.0, 0.0
    for i in range(m):
        ew = sw[i] * e[i]
        kew[i] = k[i] * ew
        if i < error_rows:
            e_sq += e[i] * e[i]
            ew_sq += ew * ew
            kew_sq += kew[i] * kew[i]
    trace, stall, curvature = 0.0, 0.0, 0.0
    for j in range(n):
        norm, acc, acc_task = 0.0, 0.0, 0.0
        if mask[j] != 0.0:
            for i in range(m):
                wij = sw[i] * J[i, j]
                norm += wij * wij
                acc += wij * kew[i]
                if i < error_rows:
                    acc_task += wij * kew[i]
        alpha[j] = 1.0 / max(norm, length2) if norm > tol else 0.0
        s[j] = alpha[j] if scaled else mask[j]
        trace += s[j] * norm
        stall += s[j] * acc_task * acc_task
        # the second-order term of 1/2 |e|^2 along joint j is about |e| |J_j|: relative to
        # the loop's scale s_j, |e| |J_j| s_j (the curvature the gain must also respect)
        if norm > tol:
            curvature = max(curvature, math.sqrt(norm) * s[j])
        step[j] = acc  # J_w^T K e_w, scaled below
    stall = stall / (kew_sq * trace) if kew_sq > 0.0 and trace > 0.0 else 0.0
    bound = 1.0
    if work[P_GAIN_MODE] == GAIN_FIXED:
        gain = 1.0
    elif damped:
        gain = work[P_GAIN_ARG] / dt
    else:
        A, B, C = _matrices(work, m, n)
        gram(J, sw, s, m <= n, A)
        bound = loop_bound(A, BOUND_PRODUCTS, B, C) + math.sqrt(ew_sq) * curvature
        gain = work[P_GAIN_ARG] / (dt * bound) if bound > 0.0 else 0.0
    ff_sq = 0.0
    if has_ff:
        for i in range(m):
            ff_sq += ff[i] * ff[i]
    ff_mode = work[P_FF_MODE]
    if damped:
        v = work[scratch + 3 * m + 6 * n:scratch + 4 * m + 6 * n]
        for i in range(m):
            v[i] = gain * k[i] * e[i]
            if has_ff:
                v[i] += ff[i]
        for j in range(n):
            step[j] = 0.0
        # Levenberg-Marquardt: damping that grows with the error relative to the shortest lever
        # arm, |e_w| sqrt(max alpha): the curvature of 1/2 |e|^2 on the normalised columns
        # (unit-free), which the linear model J D J^T leaves out
        alpha_max = 0.0
        for j in range(n):
            alpha_max = max(alpha_max, alpha[j])
        _damped_solve(J, v, sw, alpha, work, m, n, dt, step,
                      work[P_LM] * math.sqrt(ew_sq * alpha_max))
    else:
        for j in range(n):
            step[j] *= dt * gain * s[j]
        if has_ff and ff_mode == FF_TRANSPOSE:
            for j in range(n):
                acc = 0.0
                for i in range(m):
                    acc += sw[i] * sw[i] * J[i, j] * ff[i]
                step[j] += dt * s[j] * acc
        elif has_ff and ff_mode == FF_DAMPED:
            _damped_solve(J, ff, sw, alpha, work, m, n, dt, step, 0.0)
    return e_sq, ff_sq, ew_sq, gain, bound, stall, trace


@compiled
def _least_squares_core(J, e, ff, has_ff, mask, work, step):
    """The least-squares mapping (see :func:`least_squares_step`) on the joints of ``mask``;
    returns (|e|^2, |ff|^2, |e_w|^2, gain, 1, 1, 0)."""
    m, n = J.shape
    p = min(m, n)
    use_rows = m <= n
    dt = work[P_DT]
    gain = work[P_GAIN_ARG] / dt if work[P_GAIN_MODE] != GAIN_FIXED else 1.0
    rows = int(work[P_ROWS])
    sw = work[rows:rows + m]
    k = work[rows + m:rows + 2 * m]
    scratch = int(work[P_SCRATCH])
    v = work[scratch:scratch + m]
    r = work[scratch + m:scratch + m + n]
    sol = work[scratch + m + n:scratch + m + n + p]
    A, V, _ = _matrices(work, m, n)
    e_sq, ew_sq, ff_sq = 0.0, 0.0, 0.0
    error_rows = int(work[P_ERROR_ROWS])
    for i in range(m):
        ew = sw[i] * e[i]
        if i < error_rows:
            e_sq += e[i] * e[i]
            ew_sq += ew * ew
        v[i] = gain * k[i] * ew
        if has_ff:
            v[i] += sw[i] * ff[i]
            ff_sq += ff[i] * ff[i]
    gram(J, sw, mask, use_rows, A)
    # the right-hand side in the Gram matrix's space: v (rows) or J_w^T v (columns)
    if not use_rows:
        for j in range(n):
            acc = 0.0
            for i in range(m):
                acc += sw[i] * J[i, j] * v[i]
            r[j] = mask[j] * acc
    rhs = v if use_rows else r
    damping = work[P_MU]
    if damping > 0.0:
        cholesky_solve(A, damping * damping, rhs, sol)
    else:
        _pseudo_solve(A, V, rhs, sol, work[P_RCOND])
    for j in range(n):
        if use_rows:
            acc = 0.0
            for i in range(m):
                acc += sw[i] * J[i, j] * sol[i]
            step[j] = dt * mask[j] * acc
        else:
            step[j] = dt * mask[j] * sol[j]
    return e_sq, ff_sq, ew_sq, gain, 1.0, 1.0, 0.0


@compiled
def _core(kind, J, e, ff, has_ff, mask, work, step):
    if kind == TRANSPOSE:
        return _transpose_core(J, e, ff, has_ff, mask, work, step)
    return _least_squares_core(J, e, ff, has_ff, mask, work, step)


@compiled
def _step(kind, J, e, ff, q, work, step):
    """The mapping, then the limits (see the module docstring); returns the status."""
    m, n = J.shape
    dt = work[P_DT]
    mask_at = int(work[P_MASK])
    mask = work[mask_at:mask_at + n]
    has_ff = work[P_HAS_FF] != 0.0
    e_sq, ff_sq, ew_sq, gain, bound, stall, trace = _core(kind, J, e, ff, has_ff, mask, work,
                                                          step)
    work[INFO + I_E_SQ] = e_sq
    work[INFO + I_FF_SQ] = ff_sq
    work[INFO + I_EW_SQ] = ew_sq
    work[INFO + I_GAIN] = gain
    work[INFO + I_LOOP] = bound
    work[INFO + I_STALL] = stall
    work[INFO + I_TRACE] = trace
    if not math.isfinite(e_sq + ff_sq):
        return NON_FINITE
    regular = 0.0
    for j in range(n):
        regular += step[j] * step[j]
    work[INFO + I_REGULAR] = math.sqrt(regular) / dt
    status = 0
    if stall < work[P_STALL_RATIO] and e_sq > work[P_STALL_ERROR]:
        status = STALLED
    escaping = work[P_ESCAPING] != 0.0
    extra = int(work[P_EXTRA])
    if escaping:
        for j in range(n):
            step[j] += dt * work[extra + j]
    status |= _clamp_position(kind, J, e, ff, has_ff, q, mask, work, step, escaping)
    # the speed limits: the free joints' step scaled down together, its direction kept; a
    # clamped joint follows its own motion (onto its limit, or back into range), capped alone
    speed, clamped = int(work[P_SPEED]), int(work[P_CLAMPED])
    worst = 0.0
    for j in range(n):
        if work[clamped + j] != 0.0:
            cap = dt / work[speed + j] if work[speed + j] > 0.0 else math.inf
            step[j] = min(max(step[j], -cap), cap)
        else:
            worst = max(worst, abs(step[j]) * work[speed + j])
    worst /= dt
    work[INFO + I_SCALE] = 1.0
    if worst > 1.0:
        for j in range(n):
            if work[clamped + j] == 0.0:
                step[j] /= worst
        work[INFO + I_SCALE] = 1.0 / worst
        status |= SCALED
    return status


@compiled
def _clamp_position(kind, J, e, ff, has_ff, q, mask, work, step, escaping):
    """Fix the joints that ``q + step`` takes out of their range and solve again for the
    others (as :meth:`~sjt_pin.limits.PositionLimit.enforce`); returns ``CLAMPED`` or 0."""
    m, n = J.shape
    dt = work[P_DT]
    box, count = int(work[P_BOX]), int(work[P_BOX_COUNT])
    clamped = int(work[P_CLAMPED])
    outside = False
    for c in range(count):
        new = q[int(work[box + c])] + step[int(work[box + count + c])]
        if new > work[box + 3 * count + c] or new < work[box + 2 * count + c]:
            outside = True
            break
    if not outside:
        for j in range(n):
            work[clamped + j] = 0.0
        return 0
    fixed = work[clamped:clamped + n]  # 1 where fixed: also what the step reports
    fixed_step = work[clamped + n:clamped + 2 * n]
    free = work[clamped + 2 * n:clamped + 3 * n]
    ff2 = work[clamped + 3 * n:clamped + 3 * n + m]
    extra = int(work[P_EXTRA])
    for j in range(n):
        fixed[j] = 0.0
        fixed_step[j] = 0.0
        free[j] = mask[j]
    for _ in range(count):
        if not clamp_pass(q, step, work[box:box + count], work[box + count:box + 2 * count],
                          work[box + 2 * count:box + 3 * count],
                          work[box + 3 * count:box + 4 * count],
                          work[box + 4 * count:box + 5 * count], dt, fixed, fixed_step):
            break
        # the free joints take over the task velocity the fixed ones no longer provide
        for i in range(m):
            acc = ff[i] if has_ff else 0.0
            for j in range(n):
                if fixed[j] != 0.0:
                    acc -= J[i, j] * fixed_step[j] / dt
            ff2[i] = acc
        for j in range(n):
            free[j] = 0.0 if fixed[j] != 0.0 else mask[j]
        _core(kind, J, e, ff2, True, free, work, step)
        for j in range(n):
            if fixed[j] != 0.0:
                step[j] = fixed_step[j]
            elif escaping:
                step[j] += dt * work[extra + j]
    return CLAMPED


@compiled
def transpose_step(J, e, ff, q, work, step):
    """One step of a Jacobian-transpose-type CLIK law (JT eq. 10, SJT eq. 21)::

        step = dt [ S J_w^T (gain K e_w) + feed-forward ],     e_w = sw e

    S = D = diag(alpha_i), alpha_i = 1 / max(|J_w,i|^2, l^2) (eq. 18, with the characteristic
    length l^2 = ``P_LENGTH2`` as a floor) for SJT (``P_SCALED``), S = I for JT; both zero on
    joints whose mask is 0, and alpha zero on columns whose squared norm is not above
    ``P_COL_TOL``. ``gain`` is 1 (fixed K) or, "auto", c / (dt lambda_hat) with
    lambda_hat >= lambda_max(J_w S J_w^T) from :func:`~.linalg.loop_bound` and c =
    ``P_GAIN_ARG``. The feed-forward is S J_w^T ff_w (the paper's eq. 21) or
    D J_w^T (J_w D J_w^T + mu^2 I)^-1 ff_w, a damped solve on the unit-norm columns
    J_w sqrt(D) (unit-free; mu = ``P_MU``). With the damped feedback (``P_FB_MODE``) the
    feedback goes through that solve too,
    ``D J_w^T (J_w D J_w^T + (mu^2 + lm |e_w| sqrt(max alpha)) I)^-1 (ff_w + gain K e_w)`` with
    the Levenberg-Marquardt weight lm = ``P_LM``; its loop eigenvalues are below 1, so "auto" is
    gain = c / dt. With the transpose feedback "auto" divides by lambda_hat + |e_w| max_j
    (|J_j| s_j), the curvature of 1/2 |e|^2 along the joints (about |e| |J_j|) on the loop's
    scale, which an arm far from an unreachable target would otherwise overshoot. Then the
    limits (module docstring).

    Results: |e|^2, |ff|^2, the gain factor, lambda_hat (1 when not computed), the stall ratio
    (K e_w)^T J_w S J_w^T (K e_w) / (|K e_w|^2 tr) in [0, 1] (its small values flag a saddle),
    tr(J_w S J_w^T), |e_w|^2, the speed scale and |regular q_dot|. The error norms and the
    stall ratio count the first ``P_ERROR_ROWS`` rows: the tasks that take targets (a posture
    task's rows come after them).
    """
    return _step(TRANSPOSE, J, e, ff, q, work, step)


@compiled
def least_squares_step(J, e, ff, q, work, step):
    """One step of the pseudoinverse (JP, eq. 8) or damped least-squares CLIK law::

        step = dt M(J_w) (ff_w + gain K e_w),  M = J^+  or  J^T (J J^T + lambda^2 I)^-1

    on the joints whose mask is not 0, then the limits (module docstring). ``P_MU`` is the
    damping lambda (task units; DLS), or 0 for the pseudoinverse, whose singular values below
    ``P_RCOND`` sigma_max count as zero (the inverse of J J^T is taken by Cholesky when that is
    exact, by Jacobi eigenvalues otherwise). The gain factor is ``P_GAIN_ARG / dt`` for "auto"
    (both methods' loop eigenvalues are at most 1) and 1 for a fixed K.
    """
    return _step(LEAST_SQUARES, J, e, ff, q, work, step)


@compiled
def _pseudo_solve(A, V, rhs, sol, rcond):
    """``sol = A^+ rhs`` for the PSD ``A`` (overwritten), singular values of the underlying J
    below ``rcond sigma_max`` treated as zero. By Cholesky when that is exact: when
    lambda_min(A) >= 1 / tr(A^-1) = 1 / |L^-1|_F^2 is above the cutoff (the common,
    well-conditioned case); else by Jacobi eigenvalues."""
    p = A.shape[0]
    top = 0.0
    for i in range(p):
        top = max(top, A[i, i])
    cutoff = max(rcond * rcond, EIGEN_FLOOR) * top
    for i in range(p):
        for j in range(p):
            V[i, j] = A[i, j]
    ok = cholesky_factor(V, 0.0)
    if ok:  # tr(A^-1) = |L^-1|_F^2, one unit column at a time (sol as scratch)
        inverse_trace = 0.0
        for c in range(p):
            for i in range(p):
                acc = 1.0 if i == c else 0.0
                for t in range(c, i):
                    acc -= V[i, t] * sol[t]
                sol[i] = acc / V[i, i] if i >= c else 0.0
                inverse_trace += sol[i] * sol[i]
        ok = inverse_trace * cutoff < 1.0
    if ok:
        cholesky_substitute(V, rhs, sol)
        return
    symmetric_eigen(A, V)
    for i in range(p):
        sol[i] = 0.0
    for c in range(p):
        lam = A[c, c]
        if lam <= cutoff:
            continue
        proj = 0.0
        for i in range(p):
            proj += V[i, c] * rhs[i]
        proj /= lam
        for i in range(p):
            sol[i] += proj * V[i, c]
