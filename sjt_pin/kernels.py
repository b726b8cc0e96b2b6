"""Compiled inner loops of the SJT step (numba): one call instead of a dozen numpy calls.

On arrays of 6 x n numbers every numpy call costs about 0.3 us whatever it computes, so the step
spends more in call overhead than in arithmetic; each function here does its whole loop in one
compiled call (compiled on first use and cached on disk). ``tests/test_kernels.py`` checks them
against the numpy formulas of :mod:`.mappings`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def sjt_step(J: np.ndarray, e: np.ndarray, numerator: np.ndarray, off_chain: np.ndarray,
             out: np.ndarray, tol: float = 0.0) -> float:
    """``out = numerator / (|J_i|^2 + off_chain) * J_i^T e`` per column; returns ``e^T e``.

    With ``numerator = k dt chain`` this is ``k dt D J^T e`` (eq. 21-22): alpha_i = 1 / |J_i|^2
    (eq. 18) on the joints of the chain, 0 off it (their column is zero and ``off_chain`` 1),
    and 0 for a column whose squared norm is not above ``tol``.
    """
    m, n = J.shape
    ee = 0.0
    for i in range(m):
        ee += e[i] * e[i]
    for j in range(n):
        norm = off_chain[j]
        g = 0.0
        for i in range(m):
            x = J[i, j]
            norm += x * x
            g += x * e[i]
        out[j] = numerator[j] / norm * g if norm > tol else 0.0
    return ee


@njit(cache=True, nogil=True)
def outside_box(q_next: np.ndarray, step: np.ndarray, mid: np.ndarray, inv_half: np.ndarray,
                inv_speed: np.ndarray) -> bool:
    """Whether some ``|q_next_i - mid_i| inv_half_i`` or ``|step_i| inv_speed_i`` reaches 1.

    The position part uses a hair under 1, so a joint resting on its limit takes the exact path.
    """
    for i in range(q_next.shape[0]):
        if abs(q_next[i] - mid[i]) * inv_half[i] > 1.0 - 1e-12:
            return True
        if abs(step[i]) * inv_speed[i] > 1.0:
            return True
    return False


@njit(cache=True, nogil=True)
def _scaled_gradient(J: np.ndarray, r: np.ndarray, scale: np.ndarray, out: np.ndarray) -> float:
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


@njit(cache=True, nogil=True)
def cgls(J: np.ndarray, e: np.ndarray, scale: np.ndarray, iterations: int,
         tol: float) -> np.ndarray:
    """Preconditioned CGLS for ``min |J d - e|`` with ``d = S y``, S = diag(``scale``).

    Stops after ``iterations`` or once ``|S J^T r|^2`` has fallen below ``tol`` times its start.
    Only products with J and J^T: nothing to factorise, nothing that breaks at a singularity.
    """
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
        step = gamma / curvature
        for j in range(n):
            y[j] += step * p[j]
        for i in range(m):
            r[i] -= step * Jp[i]
        gamma_new = _scaled_gradient(J, r, scale, s)
        beta = gamma_new / gamma
        for j in range(n):
            p[j] = s[j] + beta * p[j]
        gamma = gamma_new
    for j in range(n):
        y[j] *= scale[j]
    return y


@njit(cache=True, nogil=True)
def sqrt_scaling(J: np.ndarray, chain: np.ndarray, tol: float) -> np.ndarray:
    """``sqrt(alpha_i) = chain_i / |J_i|`` (0 where ``|J_i|^2`` is not above ``tol``): the
    preconditioner of :func:`cgls` for SJT."""
    m, n = J.shape
    out = np.zeros(n)
    for j in range(n):
        norm = 0.0
        for i in range(m):
            norm += J[i, j] * J[i, j]
        if norm > tol:
            out[j] = chain[j] / np.sqrt(norm)
    return out


@njit(cache=True, nogil=True)
def clamp_pass(q: np.ndarray, dq: np.ndarray, q_index: np.ndarray, v_index: np.ndarray,
               lower: np.ndarray, upper: np.ndarray, dt: float, fixed: np.ndarray,
               fixed_dq: np.ndarray) -> int:
    """Fix the joints that ``q + dq dt`` takes out of ``[lower, upper]``; returns how many.

    A fixed joint inside its range moves exactly onto the limit; one already outside (a start
    out of range) keeps a motion back toward the range and stops any other. ``fixed`` and
    ``fixed_dq`` (tangent-indexed) are updated in place.
    """
    count = 0
    for k in range(q_index.shape[0]):
        v = v_index[k]
        if fixed[v]:
            continue
        qk, dqk, lo, hi = q[q_index[k]], dq[v], lower[k], upper[k]
        new = qk + dqk * dt
        if lo <= new <= hi:
            continue
        fixed[v] = True
        count += 1
        if lo <= qk <= hi:
            fixed_dq[v] = (min(max(new, lo), hi) - qk) / dt
        elif (qk > hi and dqk < 0.0) or (qk < lo and dqk > 0.0):
            fixed_dq[v] = dqk
        else:
            fixed_dq[v] = 0.0
    return count
