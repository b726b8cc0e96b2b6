"""Closed-loop inverse kinematics (CLIK): one step pipeline for every method and task.

Every solver implements the paper's CLIK law::

    q_dot = M(J(q)) (x_dot_d + K e),     e = task error at q        (eq. 5, 10, 21)
    q_next = integrate(q, q_dot dt)                                  (eq. 9, 11, 22)

and every ``step()`` — any method, any tasks, with or without feed-forward, priorities or
limits — runs the same stages:

1. tasks: the :class:`~sjt_pin.stack.TaskStack` evaluates the kinematics of ``q`` once and each
   task's error, Jacobian rows and desired velocity, stacked level by level;
2. limits: a user's limits (:mod:`~sjt_pin.limits`) give their bounds and rows at ``q``
   (:class:`~sjt_pin.constraints.UserLimits`);
3. method and stage, in one compiled call (:class:`sjt_pin.kernels.Controller`): the gain and
   the mapping M (for a method of your own, its ``matrix`` called from there on the first
   level's weighted rows, its result checked and mapped there), the lower priority levels
   in the null space of the higher ones, the saddle escape's velocity, each joint's box from
   the position, speed, acceleration and jerk limits, and the projection that keeps the
   method's step where it is feasible and returns the feasible velocity nearest it in the
   method's metric where it is not (:mod:`~sjt_pin.constraints`);
4. only when something needs it, Python: an error to raise, the stability check, the escape's
   curvature test;
5. ``pinocchio.integrate`` moves ``q`` on its manifold (continuous joints, free flyers);
6. :attr:`Solver.last` builds a :class:`~sjt_pin.step_info.StepInfo` on first access.

Arguments are validated at the door (``step``, ``solve``, the setters), never twice. Which
stages run is decided by the data (the limits given, the levels), not by flags.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from . import kernels, solver_parts, step_checks
from .constraints import UserLimits
from .escape import SaddleEscape
from .gains import FixedGain, Gain, as_gain
from .joint_move import JointMove, move_goal, solver_move
from .methods import Method
from .options import SolverOptions
from .robot import Robot
from .stability import StabilityCheck
from .stack import TaskStack, normalise_tasks
from .step_info import StepInfo, step_info
from .tasks import PostureTask
from .tasks.pose import tasks_length
from .validation import period

_F64 = np.dtype(np.float64)
_NOTHING = object()  # (no array is the last returned one yet)
#: |squared norm - 1| of a configuration's unit blocks taken as exact (rounding of unit norm)
_UNIT_EXACT = 4e-14
#: status bits that need Python: an error to raise, a stall for the escape to look at
_PYTHON = kernels.NON_FINITE | kernels.STALLED
_integrate = pin.integrate


class Solver:
    """A CLIK solver: a :class:`~sjt_pin.methods.Method` and the step pipeline around it.

    The public solvers :class:`~sjt_pin.SJTSolver`, :class:`~sjt_pin.JTSolver`,
    :class:`~sjt_pin.JPSolver` and :class:`~sjt_pin.DLSSolver` document every option; this class
    takes a method object, for methods of your own.

    Args:
        robot: the :class:`~sjt_pin.Robot` to move.
        method: the mapping M(J), a :class:`~sjt_pin.methods.Method`.
        **options: the common options, :class:`~sjt_pin.options.SolverOptions` (gain, dt,
            task, posture, limits, ...).
    """

    def __init__(self, robot: Robot, method: Method, **options: Any):
        #: the options it was made with (a copy is made anew from them, see __reduce__)
        self.options = opts = SolverOptions.of(type(self).__name__, options)
        solver_parts.check_parts(robot, method)
        self.robot, self.method = robot, method
        tasks = normalise_tasks(solver_parts.options_task(opts), opts.posture)
        self.stack = stack = TaskStack(robot, tasks)
        self._model, self._q_shape = robot.model, (robot.nq,)
        #: a q with unit blocks is checked on its manifold, unless the last step returned it
        self._unit_blocks, self._units = robot.unit_blocks, robot.unit_blocks.size > 0
        self._returned: object = _NOTHING  # the array the last step returned (trusted as it is)
        self._first = True  # the first step checks the targets' distance (units)
        self._dt = period(opts.dt)
        self._gain = as_gain(opts.gain, stack.target_dim)
        method.adapt(stack.leading, tasks_length(robot, stack.leading))
        (self.acceleration_limit, self.jerk_limit, self.position_limit, self.velocity_limit,
         self._user, self._motion) = solver_parts.solver_limits(robot, stack, opts, self._dt)
        self.escape = (SaddleEscape(robot.model, stack.chain, robot.velocity_limits,
                                    self.position_limit) if opts.escape and method.stalls
                       else None)
        self._controller, matrix_method = solver_parts.make_controller(
            robot, stack, method, self._dt, self.position_limit, self.acceleration_limit,
            self.jerk_limit, self.escape, self._motion)
        self._matrix = method.matrix if matrix_method else None  # (a method of your own's M(J))
        self._stability = StabilityCheck(method, stack.n_chain, opts.check_stability)
        self._step = np.zeros(robot.nv)
        self._probe: TaskStack | None = None
        self._escaped = (-1, False)  # (a step's count, whether it added the escape)
        self._search, self._count, self._stepping = None, 0, False  # (stepping: a step runs)
        self._last: StepInfo | None = None
        self._record: tuple | None = None  # the last step's rows, e, q, ff and row owners
        self._configure()

    # -- construction --------------------------------------------------------------------------
    def _configure(self) -> None:
        """Write what depends on the gain and dt into the controller: the rows' gains, the
        period, the speed limits (with the user's limits' caps at this period)."""
        stack, gain, c = self.stack, self._gain, self._controller
        c.set_gains(solver_parts.row_gains(stack, gain), gain.mode != kernels.GAIN_FIXED,
                    gain.factor)
        c.set_dt(self._dt)
        self._motion.dt = self._dt
        # contacts ask back the last velocity's drift (ContactTask's docstring says when)
        self._drift = ((self._motion.dq, self._dt) if self.acceleration_limit is not None
                       and self.jerk_limit is None else None)
        self._stability.arm(gain.mode == kernels.GAIN_FIXED, gain.largest * self._dt)
        moving = stack.chain > 0
        speeds, self._speed_by = solver_parts.capped_speeds(self._user, self._dt, moving,
                                                            self.velocity_limit)
        c.set_speed(np.where(moving, speeds, 0.0))
        self._motion.velocity_limits = np.where(moving, speeds, 0.0)
        self._busy = self._first or self._stability.armed or (
            self.escape is not None and self.escape.busy)

    # -- settings ------------------------------------------------------------------------------
    @property
    def gain(self) -> float | np.ndarray | str | Gain:
        """K (1/s): a number, one per task row, ``"auto"`` or a Gain object."""
        return self._gain.argument

    @gain.setter
    def gain(self, gain) -> None:
        self._gain = as_gain(gain, self.stack.target_dim)
        self._configure()

    @property
    def dt(self) -> float:
        """Control period in s (the integration step)."""
        return self._dt

    @dt.setter
    def dt(self, dt: float) -> None:
        self._dt = period(dt)
        self._configure()

    @property
    def check_stability(self) -> bool:
        """Warn once when a fixed gain exceeds the stability bound (see the class docstring)."""
        return self._stability.enabled

    @check_stability.setter
    def check_stability(self, value: bool) -> None:
        self._stability.enabled = bool(value)
        self._configure()

    def reset(self) -> None:
        """Forget the commanded velocity and acceleration (the next step starts from rest),
        any saddle escape in progress and the projection's warm start."""
        self._controller.reset()
        if self.escape is not None:
            self.escape.reset()

    # -- one control period --------------------------------------------------------------------
    def step(self, q, target, target_velocity=None) -> np.ndarray:
        """One CLIK step: the configuration after ``dt`` (a new array; ``q`` is not modified).

        Args:
            q: current configuration (nq,).
            target: desired pose x_d(t): ``pin.SE3`` or 4x4 matrix (position tasks also take a
                3-vector in m); with several tasks a ``{frame: target}`` mapping.
            target_velocity: desired velocity x_dot_d(t) as ``pin.Motion`` or 6-vector
                [linear (m/s), angular (rad/s)], world axes at the desired origin (``None``:
                no feed-forward); with several tasks a ``{frame: velocity}`` mapping (missing
                frames: 0).

        A second thread that steps this solver while a step runs gets
        :class:`~sjt_pin.exceptions.ConcurrentStepError`: a solver's buffers are one thread's.
        """
        if self._stepping:
            step_checks.refuse_concurrent(type(self).__name__)
        self._stepping = True  # (the body is here, not in a call: a call per step costs)
        try:
            if q is not self._returned and (
                    not (type(q) is np.ndarray and q.shape == self._q_shape and q.dtype == _F64
                         and q.flags.c_contiguous)
                    or (self._units
                        and not kernels.unit_defect(q, self._unit_blocks) <= _UNIT_EXACT)):
                q = self.robot.check_q(q)
            # 1. the task rows at q
            stack = self.stack
            targets = None  # (made for the slow path only with a single task)
            if stack.single:
                task, kinematics = stack.task, stack.kinematics
                target = task.target(target)
                velocity = None if target_velocity is None else task.velocity(target_velocity)
                kinematics.update(q)
                J, e, ff = task.compute(kinematics, target, velocity)
            else:
                targets, velocities = stack.targets(target, target_velocity)
                J, e, ff = stack.evaluate(q, targets, velocities, self._drift)
            if not stack.trusted:
                J, e, ff = stack.contiguous(J, e, ff)
            # 2. the user's limits at q
            lower = upper = A = b = owners = room = needs = dampers = None
            if self._user is not None:
                self._motion.q = q
                lower, upper, A, b, owners = self._user.evaluate(stack.kinematics, self._motion)
                room, needs, dampers = self._user.room, self._user.needs, self._user.dampers
            # 3. method and stage, compiled (a method of your own: its matrix called there)
            try:
                status = self._controller.run(J, e, ff, q, self._step, self._matrix, lower,
                                              upper, A, b, room, needs, dampers)
            except ValueError:
                if self._user is not None:  # (a limit's rows the stage refused: name it)
                    self._user.raise_non_finite_rows()
                raise
            self._count += 1
            if status & _PYTHON or self._busy:
                self._slow(status, q, J, e, [target] if targets is None else targets)
            # 4. integrate on the manifold; the record of the step (StepInfo) is built on demand
            self._record, self._last = (J, e, q, ff, owners), None
            self._returned = q_next = _integrate(self._model, q, self._step)
            return q_next
        finally:
            self._stepping = False

    def _slow(self, status, q, J, e, targets) -> None:
        """What the fast path skips: errors, first-step checks, stability, the escape's state."""
        c = self._controller
        if status & kernels.NON_FINITE:
            step_checks.raise_non_finite(self.robot, c.e_sq, q, targets)
        if self._first:
            self._first = False
            for target in targets:
                position = target.translation if isinstance(target, pin.SE3) else target
                if isinstance(position, np.ndarray) and position.shape == (3,):
                    self.robot.check_reach(position, q)
            step_checks.warn_idle_outside(self.robot, self.stack.chain, q)
        if self._stability.armed:
            stack = self.stack
            self._stability.check(stack.sqrt_weight[:, None] * stack.step_rows(J, e, c.exact_step)
                                  * stack.chain, c.trace, self._gain.largest, self._dt)
        escape = self.escape
        self._escaped = (self._count, escape is not None and escape.active)
        if escape is not None:
            escape.follow(c, bool(status & kernels.STALLED), q, self._dt, targets,
                          self._weighted_rows)
        self._busy = self._stability.armed or (escape is not None and escape.busy)

    def _weighted_rows(self, targets):
        """The escape's test rows for ``targets`` (:func:`~sjt_pin.step_checks.weighted_rows`),
        on a stack of their own, made on first use."""
        if self._probe is None:
            self._probe = self.stack.copy()
        return step_checks.weighted_rows(self._probe, self.stack, targets, self._controller.exact)

    # -- what the step did ----------------------------------------------------------------------
    @property
    def error_norm(self) -> float:
        """|e| of the last step (task units; NaN before the first), without building
        :attr:`last`: the cheap test of a control loop."""
        return math.sqrt(self._controller.e_sq) if self._record is not None else math.nan

    @property
    def error(self) -> np.ndarray:
        """The last step's task error e (the target rows), as a view that the next step
        overwrites (copy it to keep it; :attr:`last` holds copies)."""
        return np.full(0, np.nan) if self._record is None else self.stack.task_error(
            self._record[1])

    @property
    def task_scale(self) -> float:
        """The share in [0, 1] of the method's task motion that the last step kept (1: the
        whole task; see :attr:`StepInfo.task_scale`), without building :attr:`last`."""
        return self._controller.task_scale if self._record is not None else 1.0

    @property
    def displacement(self) -> np.ndarray:
        """The last step's joint displacement ``q_dot dt`` (nv,; zeros before the first): the
        same array after every step, which the next step overwrites (copy it to keep it)."""
        return self._step

    @property
    def last(self) -> StepInfo | None:
        """The :class:`StepInfo` of the last step (``None`` before the first)."""
        if self._last is None and self._record is not None:
            J, e, q, ff, owners = self._record
            fixed = self._gain.argument if isinstance(self._gain, FixedGain) else None
            self._last = step_info(
                self._controller, self.stack, self.robot, J, e, q, ff, self._step, owners,
                self._user, self._speed_by, fixed,
                alpha=self.method.scaling_factors is not Method.scaling_factors,
                escaped=self._escaped[1] and self._escaped[0] == self._count)
        return self._last

    # -- other entry points ----------------------------------------------------------------------
    def solve(self, target, q0, **options):
        """Solve to ``target`` from ``q0`` (set-point IK): Levenberg-Marquardt on this
        method's columns (SJT's normalised ones for SJT) within the limits, restarted (from the
        configurations of a seeded table whose poses are nearest the target, then from random
        ones) until it succeeds or its budget (2000 iterations) runs out; see
        :func:`sjt_pin.ik.solve` for the options. Returns an :class:`~sjt_pin.IKResult`."""
        from .ik import solve

        return solve(self, target, q0, **options)

    def move_to(self, q, target, *, share: float = 0.5, **options) -> JointMove:
        """The motion from ``q`` to a configuration that reaches ``target``, for targets a
        step loop alone may not reach (a local minimum against the joint limits): ``solve()``
        from ``q`` (with ``options``) finds the goal configuration, and the returned
        :class:`~sjt_pin.joint_move.JointMove` follows the minimum-jerk joint-space path there,
        timed within ``share`` of this solver's speed, acceleration and jerk limits.

        Step it like a solver, ``q = move.step(q)``, until ``move.done``: each step is a step of a
        twin of this solver (the same method, options and limits: every limit holds) tracking
        the frame's pose along the path, with a posture task on the path stacked with the pose
        task (in a null space alone it would let an arm change branch at a singularity, or
        drift); this solver's motion state follows, so it carries on from the move without a
        jump. Raises ``ValueError`` when ``solve()`` finds no configuration within its
        tolerance, or when the task is not one frame's (a multi-task solver moves by its own
        targets)."""
        q, result = move_goal(self, q, target, options)
        posture = PostureTask(q, weight=JointMove.POSTURE_WEIGHT, priority=0)
        twin = _rebuild(type(self), self.robot, self.method,
                        self.options.replace(posture=posture, gain=self._gain, dt=self._dt,
                                             check_stability=False))
        twin.continue_from(self)
        return solver_move(self, twin, q, result.q, share)

    def continue_from(self, other: Solver) -> None:
        """Carry on from ``other``'s motion state (its last commanded joint velocity and
        acceleration), as when one controller hands the arm to another, within this one's limits."""
        if other.robot.nv != self.robot.nv:
            raise ValueError("continue_from needs a solver of a robot with the same joints")
        mine, theirs = self._controller, other._controller
        mine.dq[:], mine.ddq[:] = theirs.dq, theirs.ddq
        mine.curvature_memory = (False, np.zeros(0))  # (their rows are not these)

    def search(self):
        """This solver's set-point IK state (:class:`~sjt_pin.ik.Search`, its own, made on use)."""
        if self._search is None:
            from .ik import Search

            self._search = Search(self)
        return self._search

    @property
    def user_limits(self) -> UserLimits | None:
        """The limits beyond the built-in ones (what ``solve()`` keeps beside the URDF), or None."""
        return self._user

    # -- copies --------------------------------------------------------------------------------
    def __reduce__(self):
        """A copy (``pickle``, ``copy.deepcopy``, another process) is the same solver made anew,
        carrying this one's state: gain and period as set now, the commanded velocity and
        acceleration, the saddle escape, the rows a pose error takes, the stability warning, the
        contacts' held poses and the projection's warm start. Its next steps are this one's,
        bitwise; it has no :attr:`last` until it steps."""
        arguments = self.options.replace(gain=self._gain, dt=self._dt,
                                         check_stability=self._stability.enabled)
        c = self._controller
        state = {"motion": (c.dq.copy(), c.ddq.copy()), "escape": self.escape,
                 "escaping": c.escaping, "escape_velocity": c.escape_velocity.copy(),
                 "resting": (c.resting, c.rest_rank, c.rest_keep.copy()),
                 "start": (c.start_error, c.start_run, c.least_e_sq, c.least_age, c.pushed,
                           c.damped_error, c.goal_damping, c.damping_raises),
                 "warned": self._stability.warned, "count": self._count, "first": self._first,
                 "stall": (c.stall_run, c.stall_wait, c.exact, c.still, c.expected.copy()),
                 "warm": c.warm_state, "curvature": c.curvature_memory,
                 "held": [getattr(t, "held", None) for t in self.stack.tasks]}
        return (_rebuild, (type(self), self.robot, self.method, arguments), state)

    def __setstate__(self, state: dict) -> None:
        c = self._controller
        c.dq[:], c.ddq[:] = state["motion"]
        self.escape, c.escaping = state["escape"], state["escaping"]
        c.resting, c.rest_rank, c.rest_keep[:] = state["resting"]
        (c.start_error, c.start_run, c.least_e_sq, c.least_age, c.pushed, c.damped_error,
         c.goal_damping, c.damping_raises) = state["start"]
        c.escape_velocity[:] = state["escape_velocity"]
        self._stability.warned, self._count, self._first = (state["warned"], state["count"],
                                                            state["first"])
        c.stall_run, c.stall_wait, c.exact, c.still, c.expected[:] = state["stall"]
        c.warm_state, c.curvature_memory = state["warm"], state["curvature"]
        for task, held in zip(self.stack.tasks, state["held"], strict=True):
            if held is not None:  # (a contact's)
                task.held = held  # type: ignore[attr-defined]
        self._configure()

    def __repr__(self) -> str:
        tasks = self.stack.tasks[0] if len(self.stack.tasks) == 1 else self.stack.tasks
        return (f"{type(self).__name__}({self.robot.name!r}, gain={self.gain!r}, "
                f"dt={self._dt:g}, task={tasks!r})")


def _rebuild(cls, robot: Robot, method: Method, options: SolverOptions) -> Solver:
    """A solver of class ``cls`` made anew (the unpickling half of ``Solver.__reduce__``)."""
    solver = Solver.__new__(cls)
    Solver.__init__(solver, robot, method, **options.keywords())
    return solver
