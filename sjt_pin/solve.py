"""Solve to a pose: set-point regulation with an adaptive step along the solver's direction.

JP and DLS step along their own ``M(J) e`` (Newton and Levenberg-Marquardt steps). JT and SJT
step along CGLS iterates preconditioned by ``sqrt(D)``: the first is the method's own direction
``D J^T e`` scaled by the step that minimises the linearised error ``|e - t J d|``; the paper's
Lyapunov argument makes it a descent direction of ``1/2 |e|^2`` at every configuration
(``e^T J D J^T e >= 0``, eq. 24-25), so no gain needs tuning. Further CGLS iterates (``inner``)
move toward the Gauss-Newton step with products by J and J^T only — no factorisation, nothing
that breaks at a singularity. Every step is capped at ``MAX_STEP`` per joint and halved until the
error decreases (Armijo). Joint position limits are kept as in ``step`` (a joint that would leave
its range is clamped out of the direction); a joint whose range spans a full turn is turned by
2 pi instead when a limit would trap it, since both angles give the same posture.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import mappings
from .kernels import cgls
from .validation import positive


@dataclass
class IKResult:
    """Outcome of :func:`solve`: the configuration, whether ``|e| < tol``, the iterations used
    (over all restarts) and the final error norm (task units)."""

    q: np.ndarray
    success: bool
    iterations: int
    error: float
    restarts: int = 0


MAX_STEP = 0.5  # rad (or m): the largest joint move of one iteration (a trust region)
STALL_WINDOW, STALL_PROGRESS = 10, 0.7  # give up when 10 iterations cut |e|^2 by under 30 %
CGLS_TOL = 1e-2  # inner iterations stop once |S J^T r| has fallen tenfold (squared: 1e-2)


def _step_length(d: np.ndarray) -> float:
    """1 (the direction already holds its step), capped at ``MAX_STEP`` per joint."""
    biggest = float(np.abs(d).max()) if d.size else 0.0
    return 0.0 if biggest == 0.0 else min(1.0, MAX_STEP / biggest)


def _wrappable(limits) -> np.ndarray | None:
    """Limited joints whose range spans a full turn: q and q -+ 2 pi are the same posture."""
    if limits is None:
        return None
    full = limits.upper - limits.lower >= 2.0 * np.pi
    return np.flatnonzero(full) if full.any() else None


def _wrap(q: np.ndarray, move: np.ndarray, limits, wrap: np.ndarray) -> np.ndarray:
    """``q`` with the full-turn joints that ``move`` would push out of range turned by -+2 pi
    when that keeps them in range (an IK solution may sit on either turn; a limit must not
    trap the descent there)."""
    qi, vi = limits.q_index[wrap], limits.v_index[wrap]
    lo, hi = limits.lower[wrap], limits.upper[wrap]
    new = q[qi] + move[vi]
    shift = np.where(new > hi, -2.0 * np.pi, np.where(new < lo, 2.0 * np.pi, 0.0))
    ok = (shift != 0.0) & (q[qi] + shift >= lo) & (q[qi] + shift <= hi) \
        & (new + shift >= lo) & (new + shift <= hi)
    if not ok.any():
        return q
    q = q.copy()
    q[qi[ok]] += shift[ok]
    return q


def _direction(solver, J: np.ndarray, e: np.ndarray, inner: int) -> np.ndarray:
    """The solver's step toward the target for the linearised error ``e``.

    JP and DLS: their own ``M(J) e`` (Newton and Levenberg-Marquardt steps). JT and SJT:
    ``inner`` CGLS iterations preconditioned by ``sqrt(alpha)`` (SJT) or nothing (JT), whose
    first is the method's direction ``D J^T e`` (``J^T e``) with the best step along it.
    """
    method = solver.method
    if not method.stalls:
        return method.matrix(J) @ e
    J = np.ascontiguousarray(J)
    alpha = method.scaling_factors(J)
    scale = np.sqrt(alpha) if alpha is not None else (np.abs(J).sum(axis=0) > 0).astype(float)
    out = np.empty(J.shape[1])
    cgls(J, e, scale, inner, CGLS_TOL, out)
    return out


def _descend(solver, q, oMd, tol, max_iters, inner, armijo=1e-4):
    limits, model = solver.position_limit, solver.robot.model
    wrap = _wrappable(limits)
    stack = solver.stack.copy()
    sw = stack.sqrt_weight
    mask = stack.chain

    def kinematics(q):
        J, e, _ = stack.evaluate(q, oMd, None)
        return sw[:, None] * J * mask, e.copy(), sw * e

    J, e, e_w = kinematics(q)
    f = f_checkpoint = 0.5 * float(e_w @ e_w)
    failures = 0
    it = 0
    for it in range(max_iters):  # noqa: B007 (it is returned)
        norm = float(np.sqrt(e @ e))
        if norm < tol:
            return q, True, it, norm
        if it % STALL_WINDOW == STALL_WINDOW - 1:
            if f > STALL_PROGRESS * f_checkpoint:
                break  # a local minimum (or a crawl): better spent on a restart
            f_checkpoint = f
        d = _direction(solver, J, e_w, inner)
        t = _step_length(d)
        if limits is not None and t > 0.0:
            if limits.violated(q, t * d, 1.0):
                if wrap is not None:
                    q = _wrap(q, t * d, limits, wrap)

                def remap(free, fixed_velocity, J=J, e_w=e_w, t=t):
                    return t * _direction(solver, J * free, e_w - J @ fixed_velocity, inner)

                d = limits.enforce(q, t * d, 1.0, remap) / t
        slope = float(e_w @ (J @ d))  # -(d f / d t) at t = 0: > 0 along a descent direction
        accepted = False
        if slope > 0.0 and t > 0.0:
            for _ in range(30):
                q_try = pin.integrate(model, q, t * d)
                if limits is not None:
                    limits.clip(q, q_try)
                J_try, e_try, e_w_try = kinematics(q_try)
                f_try = 0.5 * float(e_w_try @ e_w_try)
                if f_try <= f - armijo * t * slope:
                    accepted = True
                    break
                t *= 0.5
        if accepted:
            q, J, e, e_w, f, failures = q_try, J_try, e_try, e_w_try, f_try, 0
        else:
            failures += 1
            if failures > 1:
                break
    norm = float(np.sqrt(e @ e))
    return q, norm < tol, it + 1, norm


def solve(solver, target, q0, tol: float = 1e-6, max_iters: int = 500, restarts: int = 0,
          rng: np.random.Generator | None = None, inner: int | None = None,
          timeout: float | None = None) -> IKResult:
    """Drive ``solver``'s tasks to ``target`` from ``q0``; see the module docstring.

    Args:
        target: as for ``step`` (a pose, or ``{frame: target}`` with several tasks).
        q0: start configuration (nq,).
        tol: success when the task error norm is below ``tol`` (m and rad).
        max_iters: iterations per start.
        restarts: extra starts from random configurations within the limits when a start fails.
        rng: generator for the restarts (default: seeded 0, so results repeat).
        inner: JT and SJT only: CGLS iterations per step (default: the number of joints);
            1 is the plain adaptive step along the method's own direction.
        timeout: no new restart once this many seconds have passed (``None``: no limit).
    """
    tol = positive(tol, "tol", "task units")
    if int(max_iters) < 1 or int(restarts) < 0:
        raise ValueError(f"max_iters must be >= 1 and restarts >= 0, got {max_iters}, {restarts}")
    q = solver.robot.check_q(q0, "q0")
    oMd, _ = solver.stack.targets(target, None)
    rng = np.random.default_rng(0) if rng is None else rng
    inner = solver.robot.nv if inner is None else int(inner)
    if inner < 1:
        raise ValueError(f"inner must be >= 1, got {inner}")
    total = 0
    best = None
    deadline = None if timeout is None else time.perf_counter() + positive(timeout, "timeout", "s")
    for attempt in range(int(restarts) + 1):
        if attempt and deadline is not None and time.perf_counter() > deadline:
            return IKResult(best[0], False, total, best[1], attempt - 1)
        start = q if attempt == 0 else solver.robot.random_configuration(rng)
        q_end, success, iterations, error = _descend(solver, start, oMd, tol, int(max_iters),
                                                     inner)
        total += iterations
        if best is None or error < best[1]:
            best = (q_end, error)
        if success:
            return IKResult(q_end, True, total, error, attempt)
    return IKResult(best[0], False, total, best[1], int(restarts))


def solve_many(*args, **kwargs):
    raise NotImplementedError
