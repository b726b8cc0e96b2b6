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
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .joint_ranges import outside
from .kernels import CONVERGED, SetPointSearch, search_pose, search_table
from .kinematics import Kinematics
from .limits.base import Motion
from .methods.transpose import COLUMN_TOL
from .restarts import NearStarts, Sampler
from .tasks import PoseTask
from .validation import integer, positive, raise_non_finite_targets

#: |e| (m and rad, the target rows) below which a pose counts as solved
TOL = 1e-6
#: iterations of one start before it gives up
MAX_ITERS = 100
#: the search's budget: iterations over all starts (the default, so that a result depends on
#: the inputs only), and, only when asked for, seconds of wall-clock time
BUDGET = 2000
TIMEOUT: float | None = None
#: the largest joint motion of one iteration (rad or m): a trust region
MAX_STEP = 2.0
#: a start has stalled (a local minimum) when its best error has not fallen below ``PROGRESS``
#: times itself (in |e_w|^2 / 2) for ``STALE_ITERS`` iterations (the patient test); on the first
#: start and the table's (``NEAREST``) also when it has not fallen below ``HELD_PROGRESS`` times
#: itself for ``HELD_ITERS`` iterations while a joint is held at one of its limits (heading for
#: a minimum on the boundary) or once a step of the start has been rejected (its damping found:
#: Levenberg-Marquardt then converges fast or not at all) — the quick test. A stalled start
#: costs the iterations of its test: the tail of solve()'s times. Later starts, on a pose hard
#: enough to need them, keep only the patient test, which lets a slow start finish.
STALE_ITERS, PROGRESS = 6, 0.99
HELD_ITERS, HELD_PROGRESS = 4, 0.5
#: restarts taken from the table of configurations nearest the target (single pose task) before
#: random ones
NEAREST = 8
#: how far (each bound and row over a period of 1: rad, m; 0.2 mm of a collision damper's
#: distance at its default gain) a failed start's end may lie outside the user's limits and
#: still be returned before one that ends within them
ENDS_TOL = 1e-4
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
        limit = solver.position_limit
        empty = np.zeros(0, dtype=np.int64)
        self.core = core = SetPointSearch(
            np.ascontiguousarray(stack.sqrt_weight, dtype=float),
            np.ascontiguousarray(stack.chain, dtype=float), robot.nq,
            empty if limit is None else np.asarray(limit.q_index, dtype=np.int64),
            empty if limit is None else np.asarray(limit.v_index, dtype=np.int64),
            np.zeros(0) if limit is None else np.asarray(limit.lower, dtype=float),
            np.zeros(0) if limit is None else np.asarray(limit.upper, dtype=float),
            damping=MU,  # the search's own damping: DLS's tracking damping would stall it
            column_tol=getattr(method, "column_tol", COLUMN_TOL),
            length=getattr(method, "length", 0.0),
            scaled=bool(getattr(method, "scaled", False)),
            identity_rows=stack.identity_rows)
        core.error_rows = stack.target_dim
        core.max_step, core.nu_start = MAX_STEP, NU_START
        core.stale_iters, core.progress = STALE_ITERS, PROGRESS
        core.held_iters, core.held_progress = HELD_ITERS, HELD_PROGRESS
        # the user's limits hold at every iteration too (the URDF's position limits are the
        # search kernel's own): each displacement is a velocity over a period of 1
        self.user_limits = solver.user_limits
        self.kinematics = Kinematics(robot.model)
        self.targets = []  # of the solve set up by aim
        # the current point (J, e, q: read-only views) and the next step from it (writable:
        # the user's limits correct it), the compiled search's own arrays
        self.J, self.e, self.q, self.step = core.J, core.e, core.q, core.step
        self.best_q = np.zeros(robot.nq)  # the best start's q of run_nearest
        self._sampler = Sampler(robot)
        self._near: NearStarts | None = None  # built on the first restart (see near)
        self._near_built = False
        self._seed = None  # (seed, its generator, its first state)
        self.pose = None if self.user_limits is not None else _PoseLoop.of(robot, stack)

    def aim(self, targets: list, tol: float) -> None:
        """Set up one solve: its targets (validated) and tolerance (|e|, task units)."""
        self.targets = targets
        self.core.tol = tol
        if self.pose is not None:
            self.pose.aim(self, targets[0])

    def run(self, q0: np.ndarray, limit: int, deadline: float,
            quick: bool = True) -> tuple[bool, int]:
        """One start from ``q0`` towards the targets of :meth:`aim`, of at most ``limit``
        iterations: (converged, iterations used). ``quick``: with the quick stall test (see
        ``HELD_ITERS``) as well as the patient one."""
        core = self.core
        core.start(quick)
        if self.pose is not None:
            return self.pose.run(q0, limit, deadline)
        stack, model, targets = self.stack, self.robot.model, self.targets
        q, iterations = q0, 0
        clock = time.perf_counter
        while iterations < limit:
            J, e = stack.search_rows(q, targets)
            status = core.iterate(J, e, q)
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

    def admissible(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        """Whether ``q`` is within the user's limits (standing still there is admissible), to
        ``tol`` (each bound and row over a period of 1: rad, m)."""
        motion = self._motion(q)
        return self.user_limits.admits_rest(self.kinematics, motion, tol)

    def limit(self, step: np.ndarray, J: np.ndarray) -> None:
        """Keep the next displacement from the current configuration within the user's limits
        (in place): the smallest change in the metric of the task rows (see
        :func:`~sjt_pin.constraints.project`)."""
        motion = self._motion(self.q)
        rows = self.stack.sqrt_weight[:, None] * self.J * self.stack.chain
        step[:] = self.user_limits.project(step, rows, self.kinematics, motion)

    def error(self) -> float:
        """|e| of the target rows at the current configuration (the kernel's |e|^2 there)."""
        return self.core.error

    def random(self, seed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A random start: ``seed`` with the drawn joints drawn from ``rng`` (see
        :class:`~sjt_pin.restarts.Sampler`)."""
        return self._sampler(seed, rng)

    def restart_table(self) -> NearStarts | None:
        """The table of configurations the first restarts take (built on first use, its
        2,000 poses by Pinocchio one at a time: 4-10 ms on UR5 and Panda; the first ``solve()``
        that restarts pays it), or ``None`` where it does not apply (see :meth:`NearStarts.of
        <sjt_pin.restarts.NearStarts.of>`)."""
        if not self._near_built:
            self._near = NearStarts.of(self.robot, self.stack, self._sampler)
            self._near_built = True
        return self._near

    def nearest(self, attempt: int) -> NearStarts | None:
        """:meth:`restart_table` for restart ``attempt`` (1, 2, ...), ranked for the target of
        :meth:`aim` on restart 1; ``None`` past ``NEAREST`` restarts or without a table."""
        if attempt > NEAREST:
            return None
        table = self.restart_table()
        if table is not None and attempt == 1:
            table.aim(self.targets[0].homogeneous)
        return table

    def run_nearest(self, table: NearStarts, attempt: int, last: int, max_iters: int,
                    count: int, best: float) -> tuple[bool, int, int, float]:
        """Restarts ``attempt`` .. ``last`` from ``table`` (ranked: see :meth:`nearest`) in one
        compiled call on the pose loop, each of at most ``max_iters`` iterations, ``count`` in
        all, until one converges: (converged, iterations used, the last restart made, the
        lowest |e| of a start, ``best`` if none was lower; its q is then in ``best_q``). As
        many starts of :meth:`run`, without a Python round trip between them (no clock: for
        solves without a ``timeout``)."""
        assert self.pose is not None
        status, used, made, lowest = search_table(
            *self.pose.call, count, table.configurations, table.distance, self.best_q,
            last - attempt + 1, max_iters, best)
        return status == CONVERGED, used, attempt + made - 1, lowest

    def generator(self, rng) -> np.random.Generator:
        """``rng`` as a generator of random starts (``None``: seed 0). An int seed's generator
        is this search's own, reset to the seed's first state: the numbers of
        ``numpy.random.default_rng(seed)`` at a seventh of its cost."""
        if isinstance(rng, np.random.Generator):
            return rng
        seed = 0 if rng is None else rng
        if type(seed) is not int:
            return np.random.default_rng(seed)
        if self._seed is None or self._seed[0] != seed:
            generator = np.random.default_rng(seed)
            self._seed = (seed, generator, generator.bit_generator.state)
        else:
            self._seed[1].bit_generator.state = self._seed[2]
        return self._seed[1]


class _PoseLoop:
    """The iterations of one start on a single :class:`~sjt_pin.tasks.PoseTask` in one compiled
    call (``sjt_pin.kernels.search_pose``): per iteration, one Pinocchio call
    (``computeFrameJacobian``, LOCAL_WORLD_ALIGNED: forward kinematics, the frame's Jacobian
    and its placement ``data.oMf``), then the pose error (``log6``), the Levenberg-Marquardt
    update, the limits and ``integrate``, compiled. The rows are the pose task's rotated into
    world axes at the frame: the same search, as its rows' weights are equal within the linear
    and within the angular block. For the robots whose joints all have one coordinate or a
    (cos, sin) pair, and no user limits (see :meth:`of`)."""

    def __init__(self, robot, frame_id: int, joints: np.ndarray):
        model = robot.model
        self.data = data = model.createData()
        self.placement = placement = data.oMf[frame_id]  # views into data, kept alive here
        self.rotation, self.translation = placement.rotation, placement.translation
        # R^T: Pinocchio's view of R is column-major, its transpose the C-contiguous rows the
        # kernel reads
        self.rotation_t = self.rotation.T
        self.trial = np.zeros(model.nq)
        self.arguments = (model, data, self.trial, frame_id, pin.LOCAL_WORLD_ALIGNED)
        self.joints = joints
        self.e = np.zeros(6)
        self.call: tuple = ()

    @classmethod
    def of(cls, robot, stack) -> _PoseLoop | None:
        """The loop for ``stack``, or ``None`` when it takes the general path: not one pose
        task, rows weighted unequally within a block, or a joint other than a revolute,
        prismatic or continuous one (a floating base), or a mimic joint on the frame's chain."""
        task = stack.task
        w = stack.sqrt_weight
        if not (stack.single and type(task) is PoseTask and np.all(w[:3] == w[0])
                and np.all(w[3:] == w[3])):
            return None
        joints = _joint_table(robot.model)
        model = robot.model
        support = model.supports[model.frames[task.frame_id].parentJoint]
        if joints is None or any(model.joints[j].nv == 0 for j in support[1:]):
            return None  # another joint type, or a mimic joint moves the frame
        loop = cls(robot, task.frame_id, joints)
        return loop if loop.tracks(robot, task.frame_id) else None

    def tracks(self, robot, frame_id: int) -> bool:
        """Whether the placement's views follow Pinocchio's data (checked once)."""
        for q in (pin.neutral(robot.model), robot.random_configuration(np.random.default_rng(0))):
            self.trial[:] = q
            pin.computeFrameJacobian(*self.arguments)
            expected = robot.fk(q, frame_id)
            if not (np.allclose(self.rotation, expected.rotation, rtol=0.0, atol=1e-12)
                    and np.allclose(self.translation, expected.translation, rtol=0.0,
                                    atol=1e-12)):
                return False
        return True

    def aim(self, search: Search, target: pin.SE3) -> None:
        """The kernel's arguments for the starts of one solve of ``search`` to ``target``."""
        self.call = (search.core, pin.computeFrameJacobian, self.arguments, self.rotation_t,
                     self.translation, target.homogeneous, self.joints, self.trial, self.e)

    def run(self, q0: np.ndarray, limit: int, deadline: float) -> tuple[bool, int]:
        """One start from ``q0`` (the search's state already reset): (converged, iterations
        used)."""
        self.trial[:] = q0
        chunk = limit if deadline == math.inf else 16  # the clock between chunks
        iterations = 0
        while iterations < limit:
            status, used = search_pose(*self.call, min(chunk, limit - iterations))
            iterations += used
            if status:
                return status == CONVERGED, iterations
            if time.perf_counter() > deadline:
                break
        return False, iterations


def _joint_table(model: pin.Model) -> np.ndarray | None:
    """(3, k) int64: q index, v index and kind (0: one coordinate, q + v; 1: a continuous joint's
    (cos, sin) pair) of every joint with coordinates, or ``None`` if a joint is of another
    kind."""
    rows = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq == 0 and joint.nv == 0:  # a mimic joint: no coordinate of its own
            continue
        if joint.nq == 1 and joint.nv == 1:
            rows.append((joint.idx_q, joint.idx_v, 0))
        elif joint.nq == 2 and joint.nv == 1 and ("RUB" in joint.shortname()
                                                   or "RevoluteUnbounded" in joint.shortname()):
            rows.append((joint.idx_q, joint.idx_v, 1))
        else:
            return None
    return np.array(rows, dtype=np.int64).reshape(-1, 3).T.copy()


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

