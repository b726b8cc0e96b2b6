"""Solve to a pose (set-point IK): Levenberg-Marquardt on SJT's normalised columns, restarted
until it succeeds or its budget runs out: on a single pose task first from the configurations
of a seeded table whose poses are nearest the target, then from random configurations within
the limits (:mod:`sjt_pin.restarts`).

Each iteration evaluates the task rows once, at the trial configuration, accepts or rejects the
trial and computes the next step ``S J^T (J S J^T + lambda I)^-1 e`` — S = D for SJT (the
paper's scaling factors as the preconditioner: as lambda grows the step turns into SJT's
direction ``D J^T e``, a descent direction everywhere, eq. 24-25; as it shrinks, into the
Gauss-Newton step, which converges quadratically) and S = I for the other methods (plain
Levenberg-Marquardt: DLS's damping is for tracking; a search that kept it as a floor would stall
short of the tolerance). ``lambda = mu^2 + nu |e_w|^2`` grows with the error (Sugihara's
damping), with ``nu`` adapted as in Levenberg-Marquardt. Joint limits hold at every iteration: a
joint that would leave its range is fixed onto its limit and the others solved again; a joint
whose range spans a full turn wraps by 2 pi instead; no joint moves more than ``MAX_STEP`` in
one iteration. A start ends when the error is below ``tol`` (success), or when it stops falling
(a local minimum: its best |e_w|^2 has not fallen by 1 % in 6 iterations, or, on the first
starts, has not halved in 4 while a joint is held at a limit or after a rejected step): then a
new start.

The search's parameters, the options of a solve and the state of a start are named fields of
one compiled object (``sjt_pin.kernels.SetPointSearch``, C++ on Eigen), which also holds its
current point and next step. On a single :class:`~sjt_pin.tasks.PoseTask` (the usual case)
every iteration of a start runs in one compiled call (``sjt_pin.kernels.search_pose``): per
iteration one Pinocchio call for the kinematics and the frame's Jacobian, then the error
(log6), the update, the limits and ``integrate`` compiled, about 1 us on a 6-joint arm; without
a ``timeout``, the table's restarts run in one such call too (``search_table``). Other task
stacks, and user limits (the constraint stage's, which hold at every iteration too), make one
Python round trip per iteration: the stack's rows, then one compiled call
(``SetPointSearch.iterate``).

Here: :func:`solve`, its options and its :class:`IKResult`; the search's state and parameters
are :mod:`sjt_pin.ik_search`'s, the compiled loop of a single pose task
:mod:`sjt_pin.ik_pose_loop`'s.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .ik_search import (  # noqa: F401 (the search's parameters re-exported: the old path)
    HELD_ITERS,
    HELD_PROGRESS,
    MAX_STEP,
    MU,
    NEAREST,
    NU_START,
    PROGRESS,
    STALE_ITERS,
    Search,
)
from .joint_ranges import outside
from .validation import integer, positive, raise_non_finite_targets

#: |e| (m and rad, the target rows) below which a pose counts as solved
TOL = 1e-6
#: iterations of one start before it gives up
MAX_ITERS = 100
#: the search's budget: iterations over all starts (the default, so that a result depends on
#: the inputs only), and, only when asked for, seconds of wall-clock time
BUDGET = 2000
TIMEOUT: float | None = None
#: how far (each bound and row over a period of 1: rad, m; 0.2 mm of a collision damper's
#: distance at its default gain) a failed start's end may lie outside the user's limits and
#: still be returned before one that ends within them
ENDS_TOL = 1e-4


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



def solve(solver, target, q0, *, tol: float = TOL, max_iters: int = MAX_ITERS,
          restarts: int | None = None, timeout: float | None = TIMEOUT, budget: int = BUDGET,
          rng: np.random.Generator | int | None = None) -> IKResult:
    """Drive ``solver``'s tasks to ``target`` from ``q0``; see the module docstring.

    Args:
        target: as for ``step`` (a pose, or ``{frame: target}`` with several tasks).
        q0: the first start (nq,), clipped into the position limits first (``IKResult.clipped``
            names the joints moved). On a single pose task the next ``NEAREST`` (8) starts
            are the configurations of a seeded table (:mod:`sjt_pin.restarts`) whose poses are
            nearest ``target``; later starts are random within the limits (a floating base
            and prismatic joints without limits keep ``q0``'s values).
        tol: success when the tasks' error norm is below ``tol`` (m and rad; > 0).
        max_iters: iterations of one start.
        restarts: most restarts after the first start (``None``: as many as the budget allows).
        timeout: no new iteration once this many seconds have passed (default ``None``: no
            time limit, so the result depends only on the inputs and ``rng``, never on the
            machine's speed or load; the clock starts after the search is set up, its restart
            table built).
        budget: iterations over all starts (the default limit: 2000, about 2.5 ms on Panda at
            1.2 us per iteration).
        rng: a ``numpy.random.Generator`` or a seed for the random starts (``None``: seed 0,
            so a call repeats; the table's starts do not depend on it).

    Returns the first start that succeeds, or the best one (lowest error) when none did; with
    limits of the user's (``limits=[...]``: a collision limit), the best of the starts that end
    within them, if any did (a target inside an obstacle: the closest the arm gets to it from
    outside, not the start that ended deepest in it).
    """
    search = solver.search()
    tol, max_iters, budget, restarts = _options(tol, max_iters, budget, restarts)
    if rng is not None and type(rng) is not int and not isinstance(rng, np.random.Generator):
        rng = _generator(rng)  # checked at the door, not when a restart first needs it
    q, clipped = _seed(solver.robot, q0)
    targets = _targets(search, solver.robot, target, q)
    search.aim(targets, tol)
    deadline = _deadline(search, q, targets, timeout)
    starts = _Starts(search, q, rng)
    total, best, attempt = 0, None, 0
    while True:
        table = search.nearest(attempt) if attempt else None
        if table is not None and search.pose is not None and deadline == math.inf:
            assert best is not None  # the first start has run
            last = NEAREST if restarts is None else min(NEAREST, restarts)
            success, used, attempt, best = _table_starts(search, table, attempt, last,
                                                         max_iters, budget - total, best)
        else:
            success, used = search.run(starts.pick(attempt, table),
                                       min(max_iters, budget - total), deadline,
                                       attempt <= NEAREST)
        total += used
        error = search.error()
        if not math.isfinite(error):  # a NaN target, or one so far that |e|^2 overflows
            raise_non_finite_targets(targets)  # as step() says it
        # a start that ends outside the user's limits (a random start inside an obstacle, or
        # pressed into it on its way) comes after every one that ends within them
        outside = (search.user_limits is not None and not success
                   and not search.admissible(search.q, ENDS_TOL))
        if best is None or (outside, error) < (best[1], best[2]):
            best = (search.q.copy(), outside, error)
        if success:
            return IKResult(best[0], True, total, error, attempt, clipped)
        out_of_starts = restarts is not None and attempt >= restarts
        if out_of_starts or total >= budget or time.perf_counter() > deadline:
            return IKResult(best[0], False, total, best[2], attempt, clipped)
        attempt += 1


def _deadline(search: Search, q: np.ndarray, targets: list, timeout) -> float:
    """When the search must stop (``time.perf_counter()`` s; ``inf`` without a timeout): the
    clock starts once what loads on first use has loaded (the rows, the restart table)."""
    if timeout is None:
        return math.inf
    timeout = positive(timeout, "timeout", "s")
    search.stack.evaluate(q, targets, None)
    search.restart_table()
    return time.perf_counter() + timeout


class _Starts:
    """The configuration each start runs from: ``q`` first, then the table's next nearest,
    then random ones from ``rng`` (its generator made only when a restart needs it: it costs
    as much as a start)."""

    def __init__(self, search: Search, q: np.ndarray, rng):
        self.search, self.q, self.rng = search, q, rng
        self.generator: np.random.Generator | None = None

    def pick(self, attempt: int, table) -> np.ndarray:
        if attempt == 0:
            return self.q
        if table is not None:
            return table.next()
        if self.generator is None:
            self.generator = self.search.generator(self.rng)
        return self.search.random(self.q, self.generator)


def _table_starts(search: Search, table, attempt: int, last: int, max_iters: int, left: int,
                  best: tuple) -> tuple[bool, int, int, tuple]:
    """The table's starts ``attempt`` to ``last`` in one compiled call (a single pose task,
    no clock): (success, iterations used, the last start run, the best (q, outside the user's
    limits: never here, error) so far)."""
    success, used, attempt, lowest = search.run_nearest(table, attempt, last, max_iters, left,
                                                        best[2])
    if lowest < best[2]:
        best = (search.best_q.copy(), False, lowest)
    return success, used, attempt, best


def _options(tol, max_iters, budget, restarts) -> tuple[float, int, int, int | None]:
    """The options of :func:`solve` validated (the defaults are valid as they are)."""
    tol = tol if tol is TOL else positive(tol, "tol", "task units")
    max_iters = max_iters if max_iters is MAX_ITERS else integer(max_iters, "max_iters")
    budget = budget if budget is BUDGET else integer(budget, "budget")
    if restarts is not None:
        restarts = integer(restarts, "restarts", 0)
    return tol, max_iters, budget, restarts


def _generator(rng) -> np.random.Generator:
    """``numpy.random.default_rng(rng)``, or a ``TypeError`` naming ``rng``."""
    try:
        return np.random.default_rng(rng)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"rng must be a numpy.random.Generator, a seed (int) or None, got "
                        f"{rng!r} ({exc})") from None


def _seed(robot, q0) -> tuple[np.ndarray, tuple[str, ...]]:
    """``q0`` validated, and clipped into the position limits: (q, the joints clipped)."""
    q = robot.check_q(q0, "q0").copy()
    clipped = outside(robot.model, q, robot.lower_limits, robot.upper_limits)
    if clipped:  # a seed out of range starts at its nearest point within the limits
        np.clip(q, robot.lower_limits, robot.upper_limits, out=q)
    return q, clipped


def _targets(search: Search, robot, target, q: np.ndarray) -> list:
    """``target`` per task, validated; a position far out of reach (in mm by mistake?) warns,
    as ``step()`` does."""
    targets, _ = search.stack.targets(target, None)
    for goal in targets:
        position = goal.translation if isinstance(goal, pin.SE3) else goal
        if isinstance(position, np.ndarray) and position.shape == (3,):
            robot.check_reach(position, q)
    return targets

