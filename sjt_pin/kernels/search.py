"""One iteration of set-point IK (``solve``): accept or reject the last trial, then the next
Levenberg-Marquardt step on SJT's normalised columns, within the joint limits.

The step is ``delta = S J_w^T (J_w S J_w^T + lambda I)^-1 e_w`` with S = D (SJT) or I, and
``lambda = mu^2 + nu |e_w|^2``: Sugihara's error-scaled damping, with nu adapted as in
Levenberg-Marquardt (divided after a successful step, multiplied after a failed one). As
lambda grows the step turns into SJT's own direction ``D J^T e`` (a descent direction of
``1/2 |e|^2`` everywhere, eq. 24-25); as it shrinks, into the Gauss-Newton step on the
normalised columns, which converges quadratically near a solution.
"""

from __future__ import annotations

import math

from .compile import compiled
from .layout import P_COL_TOL, P_LENGTH2, P_MASK, P_ROWS, P_SCALED, P_SCRATCH
from .methods import _damped_solve

#: slots of the search state vector
S_F, S_NU, S_ITER, S_BEST, S_STALE, S_TOL_SQ, S_MAX_STEP, S_ERROR_ROWS = range(8)
STATE_SIZE = 8
#: what an iteration reports
CONTINUE, CONVERGED, STALLED = 0, 1, 2
NU_DOWN, NU_UP, NU_MIN, NU_MAX = 3.0, 4.0, 1e-6, 1e8
#: give up a start when 1/2 |e_w|^2 fell by less than 1 % over this many iterations
STALE_LIMIT = 12


@compiled
def search_iteration(J, e, q, J_cur, e_cur, q_cur, limits, work, state, step):
    """Judge the trial ``(J, e)`` at ``q`` against the current ``(J_cur, e_cur)`` at ``q_cur``
    (the first call accepts it), then write the next trial's displacement into ``step``.

    ``limits`` (4, c): q indices, v indices, lower and upper limits of the limited joints (a
    joint whose range spans 2 pi or more may wrap by a turn instead of stopping at a limit:
    both angles give the same posture). Returns ``CONTINUE``, ``CONVERGED`` (the target rows'
    |e|^2 below the squared tolerance) or ``STALLED`` (no progress: a local minimum).
    """
    m, n = J.shape
    rows = int(work[P_ROWS])
    sw = work[rows:rows + m]
    error_rows = int(state[S_ERROR_ROWS])
    f, e_sq = 0.0, 0.0
    for i in range(m):
        f += 0.5 * (sw[i] * e[i]) ** 2
        if i < error_rows:
            e_sq += e[i] * e[i]
    first = state[S_ITER] == 0.0
    state[S_ITER] += 1.0
    if first or f < state[S_F]:  # accept the trial
        for i in range(m):
            e_cur[i] = e[i]
            for j in range(n):
                J_cur[i, j] = J[i, j]
        for i in range(q.shape[0]):
            q_cur[i] = q[i]
        state[S_F] = f
        state[S_NU] = max(state[S_NU] / NU_DOWN, NU_MIN) if not first else state[S_NU]
        if e_sq <= state[S_TOL_SQ]:
            return CONVERGED
    else:
        state[S_NU] *= NU_UP
    if f < 0.99 * state[S_BEST] or first:
        state[S_BEST] = min(f, state[S_F])
        state[S_STALE] = 0.0
    else:
        state[S_STALE] += 1.0
    if state[S_STALE] >= STALE_LIMIT or state[S_NU] > NU_MAX or not math.isfinite(f):
        return STALLED
    _limited_step(J_cur, e_cur, q_cur, limits, work, state, step)
    return CONTINUE


@compiled
def _limited_step(J, e, q, limits, work, state, step):
    """The damped step from ``(J, e)`` at ``q``, scaled so that no joint moves more than the
    maximum step (rad or m), within the position limits: a joint that would leave its range
    wraps by a turn (when its range spans one) or is fixed onto its limit, and the free joints
    are solved again for the error the fixed ones leave."""
    m, n = J.shape
    rows, mask_at = int(work[P_ROWS]), int(work[P_MASK])
    sw = work[rows:rows + m]
    mask = work[mask_at:mask_at + n]
    scratch = int(work[P_SCRATCH])
    alpha = work[scratch + m:scratch + m + n]
    free = work[scratch + m + n:scratch + m + 2 * n]
    fixed = work[scratch + m + 2 * n:scratch + m + 3 * n]
    v = work[scratch + 3 * m + 6 * n:scratch + 4 * m + 6 * n]
    ew_sq = 0.0
    for i in range(m):
        ew_sq += (sw[i] * e[i]) ** 2
    damping = state[S_NU] * ew_sq
    tol, length2 = work[P_COL_TOL], work[P_LENGTH2]
    scaled = work[P_SCALED] != 0.0
    for j in range(n):
        free[j] = mask[j]
        fixed[j] = 0.0
    for _ in range(limits.shape[1] + 1):
        for i in range(m):  # the error left to the free joints
            acc = e[i]
            for j in range(n):
                if free[j] == 0.0 and mask[j] != 0.0:
                    acc -= J[i, j] * fixed[j]
            v[i] = acc
        for j in range(n):
            norm = 0.0
            if free[j] != 0.0:
                for i in range(m):
                    norm += (sw[i] * J[i, j]) ** 2
            if norm <= tol:
                alpha[j] = 0.0
            elif scaled:
                alpha[j] = 1.0 / max(norm, length2)
            else:
                alpha[j] = 1.0
            step[j] = 0.0
        _damped_solve(J, v, sw, alpha, work, m, n, 1.0, step, damping)
        biggest = 0.0
        for j in range(n):
            if free[j] == 0.0 and mask[j] != 0.0:
                step[j] = fixed[j]
            biggest = max(biggest, abs(step[j]))
        if biggest > state[S_MAX_STEP]:  # the trust region, before any wrap by a turn
            scale = state[S_MAX_STEP] / biggest
            for j in range(n):
                step[j] *= scale
        if not _clamp(q, step, limits, free, fixed):
            break


@compiled
def _clamp(q, step, limits, free, fixed):
    """Wrap or fix the free joints that ``q + step`` takes out of their range; True if one was
    fixed (the free ones must then be solved again)."""
    changed = False
    for k in range(limits.shape[1]):
        qi, vi = int(limits[0, k]), int(limits[1, k])
        if free[vi] == 0.0:
            continue
        lo, hi = limits[2, k], limits[3, k]
        new = q[qi] + step[vi]
        if lo <= new <= hi:
            continue
        if hi - lo >= 2.0 * math.pi:  # the same posture a turn away
            turn = -2.0 * math.pi if new > hi else 2.0 * math.pi
            if lo <= new + turn <= hi:
                step[vi] += turn
                continue
        free[vi] = 0.0
        fixed[vi] = min(max(new, lo), hi) - q[qi]  # onto the limit
        changed = True
    return changed
