"""The state of the set-point search of one solver (:class:`Search`): its own task stack, the
compiled search (``sjt_pin.kernels.SetPointSearch``) and its parameters, the user's limits at
every iteration, and its restarts (the table of nearest configurations, random starts).
:func:`sjt_pin.ik.solve` runs it."""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin

from .ik_pose_loop import PoseLoop
from .kernels import CONVERGED, SetPointSearch, search_table
from .kinematics import Kinematics
from .limits.base import Motion
from .methods.transpose import COLUMN_TOL
from .restarts import NearStarts, Sampler
from .tasks import ContactTask

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
#: the initial nu of the damping lambda = mu^2 + nu |e_w|^2, and its floor mu^2
NU_START, MU = 1.0, 1e-6


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
        core.error_rows = stack.search_dim
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
        self.pose = None if self.user_limits is not None else PoseLoop.of(robot, stack)

    def aim(self, targets: list, tol: float) -> None:
        """Set up one solve: its targets (validated) and tolerance (|e|, task units)."""
        self.targets = targets
        self.core.tol = tol
        for task in self.stack.tasks:  # contacts hold where this solve starts (or their pose=)
            if isinstance(task, ContactTask):
                task.release()
        if self.pose is not None:
            self.pose.aim(self.core, targets[0])

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
