"""Solve to a pose (set-point IK): Levenberg-Marquardt on SJT's normalised columns, restarted
from random configurations within the limits until it succeeds or its budget runs out.

Each iteration evaluates the task rows once, at the trial configuration, and makes one compiled
call (``sjt_pin.kernels.search_iteration``) that accepts or rejects the trial and
computes the next step ``S J^T (J S J^T + lambda I)^-1 e`` — S = D for SJT (the paper's scaling
factors as the preconditioner: as lambda grows the step turns into SJT's direction ``D J^T e``,
a descent direction everywhere, eq. 24-25; as it shrinks, into the Gauss-Newton step, which
converges quadratically) and S = I for the other methods (plain Levenberg-Marquardt: DLS's
damping is for tracking; a search that kept it as a floor would stall short of the
tolerance). ``lambda = mu^2 + nu |e_w|^2`` grows with the error (Sugihara's damping), with
``nu`` adapted as in Levenberg-Marquardt. Joint limits hold at every iteration: a joint that
would leave its range is fixed onto its limit and the others solved again; a joint whose range
spans a full turn wraps by 2 pi instead. A start ends when the error is below ``tol``
(success), or when it stops falling (a local minimum): then a new start.
"""

from __future__ import annotations

import math
import os
import pickle
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import kernels as K
from .joint_ranges import outside
from .kernels import (
    CONVERGED,
    S_BEST,
    S_ERROR_ROWS,
    S_MAX_STEP,
    S_NU,
    S_TOL_SQ,
    STATE_SIZE,
    search_iteration,
)
from .kinematics import Kinematics
from .limits.base import Motion
from .mappings import COLUMN_TOL
from .validation import positive, raise_non_finite_targets

#: |e| (m and rad, the target rows) below which a pose counts as solved
TOL = 1e-6
#: iterations of one start before it gives up
MAX_ITERS = 100
#: the search's budget: iterations over all starts, and seconds of wall-clock time
BUDGET = 2000
TIMEOUT = 5e-3
#: the largest joint motion of one iteration (rad or m): a trust region
MAX_STEP = 0.5
#: the initial nu of the damping lambda = mu^2 + nu |e_w|^2, and its floor mu^2
NU_START, MU = 1.0, 1e-6


@dataclass
class IKResult:
    """Outcome of :func:`solve`: the configuration, whether ``|e| < tol``, the iterations used
    (over all starts), the final error norm (task units), the restarts made, and ``clipped``:
    the joints whose seed ``q0`` lay outside their position limits and was clipped into them
    before the search (``()`` for a seed within the limits). ``q`` is always within the
    limits."""

    q: np.ndarray
    success: bool
    iterations: int
    error: float
    restarts: int = 0
    clipped: tuple[str, ...] = ()


class Search:
    """The set-point IK of one solver: a task stack of its own (a search never touches the
    buffers of the solver's steps), its work vectors and its restart sampler."""

    def __init__(self, solver):
        self.robot = robot = solver.robot
        self.stack = stack = solver.stack.copy()
        method = solver.method
        m, n = stack.dim, robot.nv
        self.layout = layout = K.Layout(m, n, 0)
        self.work = work = layout.allocate()
        layout.sqrt_weight(work)[:] = stack.sqrt_weight
        work[K.P_IDENTITY_ROWS] = stack.identity_rows
        layout.joint_mask(work)[:] = stack.chain
        work[K.P_MU] = MU  # the search's own damping: DLS's tracking damping would stall it
        work[K.P_COL_TOL] = getattr(method, "column_tol", COLUMN_TOL)
        work[K.P_LENGTH2] = getattr(method, "length", 0.0) ** 2
        work[K.P_SCALED] = 1.0 if getattr(method, "scaled", False) else 0.0
        limit = solver.position_limit
        self.limits = (np.zeros((4, 0)) if limit is None else
                       np.vstack([limit.q_index, limit.v_index, limit.lower, limit.upper])
                       .astype(float))
        # the user's limits hold at every iteration too (the URDF's position limits are the
        # search kernel's own): each displacement is a velocity over a period of 1
        self.user_limits = solver.stage.user_limits()
        self.kinematics = Kinematics(robot.model)
        self.state = np.zeros(STATE_SIZE)
        self.J = np.zeros((m, n))
        self.e = np.zeros(m)
        self.q = np.zeros(robot.nq)
        self.step = np.zeros(n)
        self._sampler = _Sampler(robot)

    def start(self, q: np.ndarray, target_rows: int, tol: float) -> None:
        state = self.state
        state[:] = 0.0
        state[S_NU], state[S_BEST] = NU_START, math.inf
        state[S_TOL_SQ], state[S_MAX_STEP] = tol * tol, MAX_STEP
        state[S_ERROR_ROWS] = target_rows

    def run(self, q0: np.ndarray, targets: list, tol: float, max_iters: int, budget: int,
            deadline: float) -> tuple[bool, int]:
        """One start from ``q0``: (converged, iterations used)."""
        stack, model = self.stack, self.robot.model
        self.start(q0, stack.target_dim, tol)
        q, iterations = q0, 0
        limit = min(max_iters, budget)
        clock = time.perf_counter
        while iterations < limit:
            J, e, _ = stack.evaluate(q, targets, None)
            status = search_iteration(J, e, q, self.J, self.e, self.q, self.limits, self.work,
                                      self.state, self.step)
            iterations += 1
            if status == CONVERGED and self.user_limits is not None:
                if not self.admissible(self.q):
                    return False, iterations  # converged outside a limit: another start
            if status:
                return status == CONVERGED, iterations
            if iterations % 16 == 0 and clock() > deadline:
                break
            if self.user_limits is not None:
                self.limit(self.step, J)
            q = pin.integrate(model, self.q, self.step)
        return False, iterations

    def _motion(self, q: np.ndarray) -> Motion:
        self.kinematics.update(q)
        nv = self.robot.nv
        return Motion(q, np.zeros(nv), np.zeros(nv), 1.0)

    def admissible(self, q: np.ndarray) -> bool:
        """Whether ``q`` is within the user's limits (standing still there is admissible)."""
        motion = self._motion(q)
        return self.user_limits.admits_rest(self.kinematics, motion)

    def limit(self, step: np.ndarray, J: np.ndarray) -> None:
        """Keep the next displacement from the current configuration within the user's limits
        (in place): the smallest change in the metric of the task rows (see
        :func:`~sjt_pin.constraints.project`)."""
        motion = self._motion(self.q)
        rows = self.stack.sqrt_weight[:, None] * self.J * self.stack.chain
        step[:] = self.user_limits.project(step, rows, self.kinematics, motion)

    def error(self) -> float:
        """|e| of the target rows at the current configuration."""
        rows = self.stack.target_dim
        with np.errstate(over="ignore"):
            return float(np.sqrt(self.e[:rows] @ self.e[:rows]))

    def random(self, seed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return self._sampler(seed, rng)


class _Sampler:
    """Random starts: limited joints uniform within their limits, unlimited revolute and
    continuous joints a random angle (about the seed's), the rest (a floating base, prismatic
    joints without limits) as in the seed."""

    def __init__(self, robot):
        model = robot.model
        lower, upper = robot.lower_limits, robot.upper_limits
        self.limited, self.turning, self.circle = [], [], []
        for j in range(1, model.njoints):
            joint = model.joints[j]
            kind = joint.shortname()
            if joint.nq == 1 and joint.nv == 1:
                i = joint.idx_q
                if np.isfinite(lower[i]) and np.isfinite(upper[i]):
                    self.limited.append(i)
                elif "Revolute" in kind:
                    self.turning.append(i)
            elif joint.nq == 2 and joint.nv == 1:  # continuous: (cos, sin)
                self.circle.append(joint.idx_q)
        self.limited = np.array(self.limited, dtype=np.int64)
        self.lower, self.upper = lower[self.limited], upper[self.limited]
        self.turning = np.array(self.turning, dtype=np.int64)
        self.circle = np.array(self.circle, dtype=np.int64)

    def __call__(self, seed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        q = seed.copy()
        q[self.limited] = rng.uniform(self.lower, self.upper)
        q[self.turning] += rng.uniform(-np.pi, np.pi, self.turning.size)
        angles = rng.uniform(-np.pi, np.pi, self.circle.size)
        q[self.circle], q[self.circle + 1] = np.cos(angles), np.sin(angles)
        return q


def solve(solver, target, q0, *, tol: float = TOL, max_iters: int = MAX_ITERS,
          restarts: int | None = None, timeout: float | None = TIMEOUT, budget: int = BUDGET,
          rng: np.random.Generator | int | None = None) -> IKResult:
    """Drive ``solver``'s tasks to ``target`` from ``q0``; see the module docstring.

    Args:
        target: as for ``step`` (a pose, or ``{frame: target}`` with several tasks).
        q0: the first start (nq,), clipped into the position limits first (``IKResult.clipped``
            names the joints moved); later starts are random within the limits (a floating
            base and prismatic joints without limits keep ``q0``'s values).
        tol: success when the tasks' error norm is below ``tol`` (m and rad; > 0).
        max_iters: iterations of one start.
        restarts: most restarts after the first start (``None``: as many as the budget allows).
        timeout: no new iteration once this many seconds have passed (``None``: no limit; the
            result then depends only on the inputs and ``rng``).
        budget: iterations over all starts.
        rng: a ``numpy.random.Generator`` or a seed for the random starts (``None``: seed 0,
            so a call repeats).

    Returns the first start that succeeds, or the best one (lowest error) when none did.
    """
    search = solver.search()
    tol = positive(tol, "tol", "task units")
    max_iters, budget = _integer(max_iters, "max_iters"), _integer(budget, "budget")
    if restarts is not None:
        restarts = _integer(restarts, "restarts", 0)
    robot = solver.robot
    q = robot.check_q(q0, "q0").copy()
    clipped = outside(robot.model, q, robot.lower_limits, robot.upper_limits)
    if clipped:  # a seed out of range starts at its nearest point within the limits
        np.clip(q, robot.lower_limits, robot.upper_limits, out=q)
    targets, _ = search.stack.targets(target, None)
    for goal in targets:  # a target in mm by mistake: warn, as step() does
        position = goal.translation if isinstance(goal, pin.SE3) else goal
        if isinstance(position, np.ndarray) and position.shape == (3,):
            solver.robot.check_reach(position, q)
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(0 if rng is None else rng)
    deadline = math.inf if timeout is None else time.perf_counter() + positive(timeout, "timeout",
                                                                                 "s")
    total, best, attempt = 0, None, 0
    while True:
        start = q if attempt == 0 else search.random(q, rng)
        success, used = search.run(start, targets, tol, max_iters, budget - total, deadline)
        total += used
        error = search.error()
        if not math.isfinite(error):  # a NaN target, or one so far that |e|^2 overflows
            raise_non_finite_targets(targets)  # as step() says it
        if best is None or error < best[1]:
            best = (search.q.copy(), error)
        if success:
            return IKResult(search.q.copy(), True, total, error, attempt, clipped)
        out_of_starts = restarts is not None and attempt >= restarts
        if out_of_starts or total >= budget or time.perf_counter() > deadline:
            return IKResult(best[0], False, total, best[1], attempt, clipped)
        attempt += 1


def _integer(value, name: str, minimum: int = 1) -> int:
    """``value`` as an int >= ``minimum``, or an error naming ``name``."""
    whole = (isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
             or isinstance(value, (float, np.floating)) and float(value).is_integer())
    if not whole:
        raise TypeError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


# -- many targets ----------------------------------------------------------------------------------
#: a worker process's problem: the solver, the targets, their seeds, the numbering and options
_WORKER: dict = {}


def _init_worker(solver, targets, seeds, first, seed, options) -> None:
    _WORKER.update(solver=solver, targets=targets, seeds=seeds, first=first, seed=seed,
                   options=options)


def _solve_range(bounds: tuple[int, int]) -> tuple:
    """Targets ``start:stop`` of the worker's problem, as arrays (cheap to send back)."""
    w, (start, stop) = _WORKER, bounds
    return _solve_part(w["solver"], w["targets"][start:stop], w["seeds"][start:stop],
                       w["first"] + start, w["seed"], w["options"])


def _solve_part(solver, targets, seeds, first: int, seed: int, options: dict) -> tuple:
    """Targets numbered ``first, first + 1, ...``: (q (n, nq), success, iterations, error,
    restarts, clipped)."""
    results = [solver.solve(target, q0, rng=np.random.default_rng([seed, first + k]), **options)
               for k, (target, q0) in enumerate(zip(targets, seeds, strict=True))]
    return (np.array([r.q for r in results]), [r.success for r in results],
            [r.iterations for r in results], [r.error for r in results],
            [r.restarts for r in results], [r.clipped for r in results])


def _results(part: tuple) -> list[IKResult]:
    return [IKResult(*fields) for fields in zip(*part, strict=True)]


def _solve_with(payload: bytes, targets, seeds, first: int, seed: int, options: dict) -> tuple:
    """A chunk on a solver of its own (unpickled from ``payload``): executors have no
    initializer, and threads must not share one solver's buffers."""
    return _solve_part(pickle.loads(payload), targets, seeds, first, seed, options)


def solve_many(solver, targets: Sequence, q0, *, processes: int | None = None,
               executor=None, progress: bool = True, chunk: int = 64, seed: int = 0,
               first: int = 0, **options) -> list[IKResult]:
    """:meth:`~sjt_pin.Solver.solve` for every target, in parallel; results in order.

    Target ``k`` is solved with ``rng = numpy.random.default_rng([seed, first + k])``, so the
    results do not depend on how the targets are spread over processes, nor on how a large
    batch is cut into calls (pass each part's position in the whole as ``first``). With the
    default ``timeout`` a slower machine may restart less often; pass ``timeout=None`` for
    results that depend on the inputs only.

    Each worker process receives the solver and all targets once (at its start) and then only
    index ranges of ``chunk`` targets; it sends back arrays.

    Args:
        targets: the targets, as ``step`` takes them.
        q0: one start for every target (nq,), or one per target (N, nq).
        processes: worker processes (default: one per core); 1 solves in this thread.
        executor: a ``concurrent.futures.Executor`` to run on instead (e.g. Dask's
            ``client.get_executor()``); each task it receives carries the pickled solver and
            its ``chunk`` targets.
        progress: a progress bar (tqdm) on standard error.
        chunk: targets per task (>= 1).
        seed: the seed of the random restarts (an integer >= 0; see above).
        first: the number of the first target (see above; >= 0).
        options: passed to ``solve`` (``tol``, ``max_iters``, ``timeout``, ...).
    """
    targets = list(targets)
    chunk = _integer(chunk, "chunk")
    seed, first = _integer(seed, "seed", 0), _integer(first, "first", 0)
    if processes is not None:
        processes = _integer(processes, "processes")
    nq = solver.robot.nq
    if np.iscomplexobj(q0):
        raise ValueError("q0 must be real, got complex values")
    seeds = np.asarray(q0, dtype=float)
    if seeds.ndim == 1:
        seeds = np.broadcast_to(solver.robot.check_q(seeds, "q0"), (len(targets), nq))
    elif seeds.shape != (len(targets), nq):
        raise ValueError(f"q0 must have shape ({nq},) or ({len(targets)}, {nq}), "
                         f"got {seeds.shape}")
    elif not np.all(np.isfinite(seeds)):
        raise ValueError("q0 contains NaN or inf")
    ranges = [(i, min(i + chunk, len(targets))) for i in range(0, len(targets), chunk)]
    bar = _progress(len(targets), progress)
    results: list[IKResult] = []

    def collect(parts):
        for part in parts:
            results.extend(_results(part))
            bar.update(len(part[1]))
        return results

    try:
        if executor is None and (processes == 1 or len(ranges) <= 1):
            return collect(_solve_part(solver, targets[a:b], seeds[a:b], first + a, seed,
                                       options) for a, b in ranges)
        if executor is None:
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(processes or os.cpu_count() or 1, initializer=_init_worker,
                                     initargs=(solver, targets, seeds, first, seed,
                                               options)) as pool:
                return collect(pool.map(_solve_range, ranges))
        payload = pickle.dumps(solver)
        futures = [executor.submit(_solve_with, payload, targets[a:b], seeds[a:b], first + a,
                                   seed, options) for a, b in ranges]
        return collect(future.result() for future in futures)
    finally:
        bar.close()


def _progress(total: int, show: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="solve_many", unit="pose", disable=not show or None)
