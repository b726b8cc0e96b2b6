"""Closed-loop inverse kinematics (CLIK): one step pipeline for every method and task.

Every solver implements the paper's CLIK law::

    q_dot = M(J(q)) (x_dot_d + K e),     e = task error at q        (eq. 5, 10, 21)
    q_next = integrate(q, q_dot dt)                                  (eq. 9, 11, 22)

and every ``step()`` — any method, any tasks, with or without feed-forward, posture or
limits — runs the same stages:

1. the :class:`~sjt_pin.stack.TaskStack` evaluates the kinematics of ``q`` once and each task's
   error, Jacobian rows and desired velocity, stacked;
2. the :class:`~sjt_pin.methods.Method`'s compiled kernel applies the gain
   (:mod:`~sjt_pin.gains`) and the mapping M, adds the escape velocity of a saddle in progress
   (:class:`~sjt_pin.escape.SaddleEscape`, JT and SJT), and holds the URDF's position and speed
   limits by Saturation in the Null Space (:mod:`~sjt_pin.constraints`), in one call; with
   acceleration (and jerk) limits the same call runs their whole stage — the feedback's and
   the position limits' braking, SNS on the hard box, the smoothing, and the motion state
   (the previous velocity and acceleration, kept in the kernel's work vector);
3. only when something needs it, Python: an error to raise, the stability check, the escape's
   curvature test at the end of a stall, and the user's limits (:mod:`~sjt_pin.limits`) —
   their bounds and rows checked against the kernel's step, which is corrected in one more
   compiled call only when it breaks them (within the acceleration/jerk stage's boxes when it
   has one), the :class:`~sjt_pin.constraints.ConstraintStage` in Python when that cannot
   weigh them — or every limit of a method without a kernel (the stage in Python is the
   compiled one's reference, :data:`COMPILED_SMOOTH_STAGE`);
4. ``pinocchio.integrate`` moves ``q`` on its manifold (continuous joints, free flyers);
5. :attr:`Solver.last` builds a :class:`~sjt_pin.step_info.StepInfo` from the step's buffers
   on first access.

Arguments are validated at the door (``step``, ``solve``, the setters); inside, nothing is
validated twice and the per-step checks are a few float comparisons.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin

from . import kernels
from .constraints import Bounds, Box, ConstraintStage, Outcome, active_limits, as_rows
from .escape import SaddleEscape
from .exceptions import ConcurrentStepError
from .gains import FixedGain, Gain, as_gain
from .joint_ranges import outside
from .limits import AccelerationLimit, JerkLimit, Limit, Motion, PositionLimit, VelocityLimit
from .limits.position import BRAKING_RESERVE, braking_speed
from .methods import Method
from .options import SolverOptions
from .robot import Robot
from .stability import StabilityCheck
from .stack import TaskStack, normalise_tasks
from .step_info import StepInfo, makes_no_progress
from .tasks import PoseTask
from .tasks.pose import tasks_length
from .validation import period, raise_non_finite_targets

_F64 = np.dtype(np.float64)
#: |squared norm - 1| of a configuration's unit blocks taken as exact (rounding of unit norm)
_UNIT_EXACT = 4e-14
#: a status bit of Python's own (beside the kernels' 1-8): a user's limit that the compiled
#: acceleration/jerk stage's correction cannot weigh (its bound against the hard box, a
#: smoothness limit of the user's), so the whole stage runs in Python on this step
_STAGE = 64
#: status bits that need Python: an error to raise, a stall for the escape to look at, a
#: user's limit for the stage in Python (joints held at the position and speed bounds, a task
#: scaled for them: the kernel's own work)
_PYTHON = kernels.NON_FINITE | kernels.STALLED | _STAGE
_I_SCALE = kernels.I_SCALE  # (read per step by task_scale)
_integrate = pin.integrate

#: whether solvers made from now on run the acceleration/jerk stage compiled in their step
#: kernel (a built-in method); ``False`` makes them run its reference, the stage in Python
#: (:mod:`sjt_pin.constraints`), on every step — for comparisons and tests
#: (``tests/test_smooth_kernel.py``); read when a solver is made
COMPILED_SMOOTH_STAGE = True


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
        _check_parts(robot, method)
        self.robot, self.method = robot, method
        self.stack = stack = TaskStack(robot, normalise_tasks(_task(opts), opts.posture))
        self._model, self._q_shape = robot.model, (robot.nq,)
        #: a q with quaternions or (cos, sin) pairs is checked on its manifold (one compiled
        #: call; Robot.check_q normalises or refuses it when a block is off the unit norm),
        #: unless it is the array the last step returned (pin.integrate keeps it there)
        self._unit_blocks = robot.unit_blocks
        self._units = self._unit_blocks.size > 0
        self._returned: np.ndarray | None = None
        self._first = True  # the first step checks the targets' distance (units)
        self._dt = period(opts.dt)
        #: the method's own step (the stage's re-solves call it)
        self._method_step = method.kernel if method.kernel is not None else method.python_step
        self._kernel = self._method_step
        self._build_stage(opts)
        self.escape = (SaddleEscape(robot.model, stack.chain, robot.velocity_limits,
                                    self.position_limit) if opts.escape and method.stalls
                       else None)
        self._build_work()
        self._step, self._no_ff, self._ff_on = np.zeros(robot.nv), np.zeros(stack.dim), False
        self._escaped = (-1, False)  # (step count, whether that step added the escape)
        self._v_names = robot.velocity_names
        self._stability = StabilityCheck(method, stack.n_chain, opts.check_stability)
        self._probe: TaskStack | None = None
        self._search = None
        self._gain = as_gain(opts.gain, stack.target_dim)
        method.adapt(stack.targeted, tasks_length(robot, stack.tasks))  # per the tasks
        self._configure()
        self._count = 0
        self._stepping = False  # a step runs (ConcurrentStepError for a second thread)
        self._last: StepInfo | None = None
        #: the last step's rows, error, displacement and status (None before the first)
        self._record: tuple | None = None

    def _build_stage(self, opts: SolverOptions) -> None:
        """The constraint stage: the URDF's position and speed limits, acceleration and jerk
        limits when given, and the user's limits; keeps the speed limits it enforces (rad/s,
        m/s; inf for none), which :meth:`_hold_speeds` writes with the user's limits' caps."""
        robot, method, stack = self.robot, self.method, self.stack
        n = robot.nv
        urdf_speeds = robot.velocity_limits
        acceleration_limits, jerk_limits = opts.acceleration_limits, opts.jerk_limits
        position_limits, velocity_limits = opts.position_limits, opts.velocity_limits
        moving = stack.chain > 0
        accel = None if acceleration_limits is None else AccelerationLimit(acceleration_limits, n)
        jerk = None if jerk_limits is None else JerkLimit(
            jerk_limits, n, _speed_limits(velocity_limits, urdf_speeds, n))
        if jerk is not None and accel is None:
            raise ValueError("jerk_limits need acceleration_limits (the braking distance of a "
                             "jerk-limited stop depends on both)")
        position = PositionLimit(robot, moving, np.where(np.isfinite(urdf_speeds), urdf_speeds,
                                                         SaddleEscape.DEFAULT_SPEED),
                                 None if accel is None else accel.limits,
                                 None if jerk is None else jerk.limits)
        use_position = position.active if position_limits is None else (
            bool(position_limits) and position.active)
        self.position_limit = position if use_position else None
        speeds = np.where(moving, _speed_limits(velocity_limits, urdf_speeds, n), np.inf)
        velocity = VelocityLimit(speeds)
        self.velocity_limit = velocity if velocity.active else None
        extra = list(opts.limits)
        for limit in extra:
            if not isinstance(limit, Limit):
                raise TypeError(f"limits must hold sjt_pin Limit objects, got {limit!r}")
        self.acceleration_limit, self.jerk_limit = accel, jerk
        self.stage = ConstraintStage(
            [x for x in (self.position_limit, self.velocity_limit, accel, jerk, *extra)
             if x is not None], moving, robot.velocity_names, stack.target_dim)
        #: the compiled kernel runs the acceleration/jerk stage itself (a built-in method): one
        #: call per step, its motion state kept in the work vector; a user's limits then cost
        #: their own rows (:meth:`_smooth_user_step`)
        self._compiled_smooth = (accel is not None and method.kernel is not None
                                 and COMPILED_SMOOTH_STAGE)
        #: limits the kernel cannot test for the stage: every step goes through it
        self._staged = (bool(extra) and not self._compiled_smooth) or method.kernel is None or (
            accel is not None and not self._compiled_smooth)
        #: the compiled kernel holds the position and speed bounds itself (a built-in method,
        #: and no acceleration limits or the compiled stage for them): the stage then only
        #: checks the user's limits first
        self._kernel_bounds = method.kernel is not None and (accel is None
                                                             or self._compiled_smooth)
        self._user_stage = (ConstraintStage(extra, moving, robot.velocity_names, stack.target_dim)
                            if extra else None)
        #: the commanded velocity and acceleration of the last step (the stage's state)
        self._motion = Motion(np.zeros(robot.nq), np.zeros(n), np.zeros(n), 1.0,
                              None if accel is None else accel.limits,
                              None if jerk is None else jerk.limits)  # (and _hold_speeds)
        # (the compiled stage keeps its own, corrections included)
        self._tracks_motion = not self._compiled_smooth and (
            accel is not None or any(limit.uses_motion for limit in extra))
        self._speeds = speeds  # (the user's limits' speed caps join them: _hold_speeds)

    def _build_work(self) -> None:
        """The kernel's work vector: parameters, weights, gains, mask, box, speeds, scratch."""
        robot, stack = self.robot, self.stack
        n = robot.nv
        # the kernel tests the position and speed box, so that a step within them costs nothing
        # more; beyond them (or with limits it cannot test) the stage takes over
        box = self.position_limit if self._kernel_bounds else None
        self._layout = layout = kernels.Layout(
            stack.dim, n, 0 if box is None else box.q_index.size, smooth=self._compiled_smooth)
        self._work = work = layout.allocate()
        self._info = layout.info(work)
        layout.sqrt_weight(work)[:] = stack.sqrt_weight
        work[kernels.P_IDENTITY_ROWS] = stack.identity_rows  # a posture task's: solved linear in n
        self._mask = layout.joint_mask(work)
        self._mask[:] = stack.chain
        if box is not None:
            for part, values in enumerate((box.q_index, box.v_index, box.lower, box.upper,
                                           box.recovery_speeds)):
                layout.box_part(work, part)[:] = values
        self._escape_velocity = layout.extra_velocity(work)
        self._clamped = layout.clamped_joints(work)
        if self._compiled_smooth:
            self._fill_smooth(layout, work)
            if self._user_stage is not None:
                self._kernel = self._smooth_user_step
        self._raw_work = work.copy()  # the method alone, for the stage's solves
        self._outcome: Outcome | None = None
        self._outcome_count = -1
        #: (step count, the user's rows) of a kernel step checked against them (active_rows)
        self._checked_rows: tuple[int, tuple | None] = (-1, None)
        self._no_rows = (np.zeros((0, n)), np.zeros(0))
        self._no_bounds = (np.full(n, -np.inf), np.full(n, np.inf))
        work[kernels.P_ERROR_ROWS] = stack.target_dim
        work[kernels.P_STALL_RATIO] = -1.0 if self.escape is None else SaddleEscape.STALL_RATIO
        # converged, not stalled: |e_w| below ERROR_FLOOR times the tasks' length (unit-free)
        work[kernels.P_STALL_ERROR] = (SaddleEscape.ERROR_FLOOR
                                       * tasks_length(robot, stack.tasks)) ** 2

    def _fill_smooth(self, layout: kernels.Layout, work: np.ndarray) -> None:
        """The compiled acceleration/jerk stage's limits; the solver's motion state becomes
        views on the kernel's (it updates them on every step)."""
        accel, jerk = self.acceleration_limit, self.jerk_limit
        assert accel is not None  # the compiled stage is for acceleration limits
        n = self.robot.nv
        jerks = np.full(n, np.inf) if jerk is None else jerk.limits
        work[kernels.P_JERK] = 0.0 if jerk is None else 1.0
        for part, values in ((kernels.SM_ACC, accel.limits), (kernels.SM_JERK, jerks),
                             (kernels.SM_JERK_SPEED, np.full(n, np.inf) if jerk is None
                              else jerk.speeds),
                             (kernels.SM_BRAKE_ACC, (1.0 - BRAKING_RESERVE) * accel.limits),
                             (kernels.SM_BRAKE_JERK, (1.0 - BRAKING_RESERVE) * jerks)):
            layout.smooth_part(work, part)[:] = values
        self._motion.dq = layout.smooth_part(work, kernels.SM_DQ)
        self._motion.ddq = layout.smooth_part(work, kernels.SM_DDQ)
        #: the state (velocity, then acceleration: adjacent parts) and its copy from before
        #: the step, which the user's limits and a correction of the step start from
        start = layout.smooth + kernels.SM_DQ * n
        self._state = work[start:start + 2 * n]
        self._before = np.zeros(2 * n)
        #: the user's limits' bounds and rows of this step (before its kernel call)
        self._user_parts: tuple | None = None

    # -- settings ----------------------------------------------------------------------------
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

    def _configure(self) -> None:
        """Write everything that depends on the gain and dt into the kernel's parameters."""
        stack, gain, work = self.stack, self._gain, self._work
        self.method.configure(work, gain, self._dt, stack.n_chain)
        work[kernels.P_FF_MODE] = self.method.feedforward_mode()
        self._layout.gains(work)[:] = gain.rows(stack.target_dim, stack.posture_dim)
        self._stability.arm(gain.mode == kernels.GAIN_FIXED, gain.largest * self._dt)
        self._motion.dt = self._dt
        self._hold_speeds()
        self._update_slow()

    def _hold_speeds(self) -> None:
        """Write the speeds the kernel holds: the solver's own limits and, where the kernel
        holds them (``_kernel_bounds``), the user's limits' speed caps at this period
        (:meth:`~sjt_pin.limits.Limit.speed_caps`; a free-flying base without a speed limit
        under a collision limit's caps), so that a step they cut is saturated in the kernel;
        the limits read them in ``Motion.velocity_limits``."""
        speeds, moving = self._speeds, self.stack.chain > 0
        by = np.full(speeds.size, "velocity", dtype=object)
        user = self._user_stage
        limits = user.limits if self._kernel_bounds and user is not None else ()
        capped = 0
        for limit in limits:
            caps = limit.speed_caps(self._dt)
            if caps is None:
                continue
            capped += 1
            caps = np.asarray(caps, dtype=float)
            if caps.shape != speeds.shape or np.isnan(caps).any() or (caps <= 0).any():
                raise ValueError(f"{limit!r}.speed_caps() must return ({speeds.size},) speeds "
                                 f"> 0 (rad/s or m/s; inf for none), got {caps!r}")
            tighter = moving & (caps < speeds)
            speeds = np.where(tighter, caps, speeds)
            by[tighter] = limit.name
        #: the speeds the kernel holds (rad/s, m/s; inf for none) and the limit each is
        #: (StepInfo.active_limits)
        self._held_speeds, self._speed_by = speeds, by
        #: every user's limit has speed caps the kernel holds: a step within them meets their
        #: bounds, which never go below the caps, so only their rows are asked
        self._rows_only = bool(limits) and capped == len(limits)
        #: the one such limit, whose rows are asked directly (no stacking of blocks)
        self._only = limits[0] if self._rows_only and len(limits) == 1 else None
        if self._kernel_bounds:
            self._layout.inverse_speeds(self._work)[:] = np.where(np.isfinite(speeds),
                                                                  1.0 / speeds, 0.0)
        self._motion.velocity_limits = np.where(moving, speeds, 0.0)

    def _update_slow(self) -> None:
        """Whether every step must take the slow path (an escape in progress, a pending
        stability check, limits outside the kernel's box)."""
        busy = (self._first or self._stability.armed
                or (self.escape is not None and self.escape.active))
        self._always = busy or self._staged
        #: a user's limits the kernel's step is checked against first (_user_rows_hold): a
        #: step that keeps them skips the rest of the slow path when nothing else needs it
        self._lean = (not busy and self._user_stage is not None and self._kernel_bounds
                      and not self._compiled_smooth)

    def reset(self) -> None:
        """Forget the commanded velocity and acceleration (the next step starts from rest)
        and any saddle escape in progress."""
        self._motion.dq[:] = 0.0
        self._motion.ddq[:] = 0.0
        if self.escape is not None:
            self.escape.reset()
        self._work[kernels.P_ESCAPING] = 0.0
        self._work[kernels.P_STALL_RUN], self._work[kernels.P_STALL_WAIT] = -1.0, np.inf
        self._escape_velocity[:] = 0.0

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
            self._refuse_concurrent()
        self._stepping = True  # (the body is here, not in a call: a call per step costs)
        try:
            # the array the last step returned is checked: a loop that feeds it back skips this
            if q is not self._returned and (
                    not (type(q) is np.ndarray and q.shape == self._q_shape and q.dtype == _F64)
                    or (self._units
                        and not kernels.unit_defect(q, self._unit_blocks) <= _UNIT_EXACT)):
                q = self.robot.check_q(q)
            # 1. the task rows at q
            stack = self.stack
            if stack.single:
                task, kinematics = stack.task, stack.kinematics
                target = task.target(target)
                velocity = None if target_velocity is None else task.velocity(target_velocity)
                kinematics.update(q)
                J, e, ff = task.compute(kinematics, target, velocity)
                targets = None  # (made for the slow path only)
            else:
                targets, velocities = stack.targets(target, target_velocity)
                J, e, ff = stack.evaluate(q, targets, velocities)
            # 2. gain, mapping, escape velocity and limits, in one compiled call
            if (ff is not None) != self._ff_on:  # the feed-forward starts or stops
                self._ff_on = ff is not None
                self._work[kernels.P_HAS_FF] = float(self._ff_on)
            if ff is None:
                ff = self._no_ff
            step = self._step
            status = self._kernel(J, e, ff, q, self._work, step)
            self._count += 1
            # 3. only when needed: errors, the stability check, the escape's state, other limits
            if status & _PYTHON or self._always:
                # (a user's limits the kernel's step keeps need nothing else: _lean)
                checked = self._lean and not status & _PYTHON
                if not (checked and self._user_rows_hold(q, J, step)):
                    step = self._slow(status, q, J, e, ff,
                                      [target] if targets is None else targets, checked)
            # 4. integrate on the manifold; the record of the step (StepInfo) is built on demand
            self._record, self._last = (J, e, step, status, q, ff), None
            if self._tracks_motion:  # the velocity and acceleration it commands, in place
                motion = self._motion
                kernels.follow_motion(step, self._dt, motion.dq, motion.ddq)
            self._returned = q_next = _integrate(self._model, q, step)
            return q_next
        finally:
            self._stepping = False

    def _refuse_concurrent(self) -> None:
        raise ConcurrentStepError(
            f"{type(self).__name__} is being stepped by another thread: a solver's buffers "
            "and pin.Data are one thread's; give each thread its own solver "
            "(copy.deepcopy(solver) makes one in the same state)")

    def _slow(self, status, q, J, e, ff, targets, checked: bool = False) -> np.ndarray:
        """What the fast path skips: errors, the stability check, the escape's state (its
        velocity for the next step), limits beyond the built-in ones (``checked``: the user's
        rows were tested against the kernel's step already and broken)."""
        if status & kernels.NON_FINITE:
            self._raise_non_finite(q, targets)
        if self._first:
            self._first = False
            for target in targets:
                position = target.translation if isinstance(target, pin.SE3) else target
                if isinstance(position, np.ndarray) and position.shape == (3,):
                    self.robot.check_reach(position, q)
            self._warn_idle_outside(q)
        if self._stability.armed:
            self._stability.check(self.stack.sqrt_weight[:, None] * J * self.stack.chain,
                                  float(self._info[kernels.I_TRACE]), self._gain.largest, self._dt)
        step, dt = self._step, self._dt
        if self._staged or status & _STAGE:  # with this step's escape velocity, as the
            # kernel's step has it
            step = self._constrain(q, J, e, ff, status, step, checked)
        escape = self.escape
        self._escaped = (self._count, escape is not None and escape.active)
        if escape is not None:
            work = self._work
            if status & kernels.STALLED and not escape.active:
                run = float(work[kernels.P_STALL_RUN])
                if escape.observe(run, float(self._info[kernels.I_EW_SQ])):
                    escape.test(q, self._weighted_rows(targets))
                if run > 1.0:  # a window ended: the kernel counts the next one
                    work[kernels.P_STALL_RUN] = 0.0
                work[kernels.P_STALL_WAIT] = escape.wait
            velocity = None if not escape.active else escape.velocity(
                float(self._info[kernels.I_REGULAR]), dt, float(self._info[kernels.I_EW_SQ]))
            if velocity is None:
                if work[kernels.P_ESCAPING]:  # an escape ended: a stall after it is a new run
                    work[kernels.P_STALL_RUN] = -1.0
                    work[kernels.P_ESCAPING] = 0.0
                    self._escape_velocity[:] = 0.0  # (zero while no escape runs)
            else:  # the kernel adds it, within the limits, from the next step on
                self._work[kernels.P_ESCAPING] = 1.0
                self._escape_velocity[:] = velocity
        self._update_slow()
        return step

    def _warn_idle_outside(self, q: np.ndarray) -> None:
        """Warn (first step) about joints outside their range that no task moves: the step
        brings a joint back only if a task moves it, so these stay where they are (a gripper's
        finger and the mimic joint that follows it, for instance); ``StepInfo.outside_limits``
        names them on every step."""
        robot, model = self.robot, self._model
        names = outside(model, q, robot.lower_limits, robot.upper_limits, robot.mimic_joints)
        idle = [name for name in names
                if not self.stack.chain[model.joints[model.getJointId(name)].idx_v]]
        if idle:
            warnings.warn(f"joints {idle} start outside their URDF position range and no task "
                          "moves them: they stay there (stack a PostureTask within the range "
                          "to bring them back)", UserWarning, stacklevel=4)

    # -- the constraint stage ------------------------------------------------------------------
    def _smooth_user_step(self, J, e, ff, q, work, step) -> int:
        """The step kernel with the compiled acceleration/jerk stage, then the user's limits at
        the cost of their own rows: their bounds and rows, evaluated before the call (on the
        motion state the step starts from), are checked against its result and, only when it
        breaks one, it is projected onto them within the stage's hard box and, as far as the
        rows allow, its smoothness box, the motion state following (``kernels.smooth_rows_step``,
        one compiled call). A user's bound the hard box does not meet, or a smoothness limit of
        the user's, leaves the step to the whole stage in Python (the status bit ``_STAGE``)."""
        motion, before, user = self._motion, self._before, self._user_stage
        assert user is not None  # this kernel is for a user's limits
        motion.q = q
        np.copyto(before, self._state)
        parts = self._user_parts = user.hard_parts(self.stack.kinematics, motion)
        status = self._method_step(J, e, ff, q, work, step)
        if status & kernels.NON_FINITE:
            return status
        if parts is None:
            return status | _STAGE
        lower, upper, rows = parts
        if rows is None and lower is None:
            return status
        A, b = (rows[0], rows[1]) if rows is not None else self._no_rows
        if lower is None:  # (lower and upper come together)
            upper = None
        try:
            done = kernels.smooth_rows_step(J, q, A, b, lower, upper, before, work, step)
        except ValueError:  # rows or bounds that do not fit or hold NaN: name the limit
            user.check(self.stack.kinematics, motion)
            raise
        if done < 0:
            return status | _STAGE
        self._checked_rows = (self._count + 1, rows)  # (the step counts after its kernel)
        return status

    def _constrain(self, q, J, e, ff, status, step, checked: bool = False) -> np.ndarray:
        """Run the constraint stage on the method's step (see :mod:`sjt_pin.constraints`);
        ``checked``: :meth:`_user_rows_hold` refused the kernel's step already."""
        motion = self._motion
        motion.q = q
        if self._compiled_smooth:  # the stage starts from the state before this step
            self._state[:] = self._before
        elif (self._user_stage is not None and self._kernel_bounds and not checked
              and self._user_rows_hold(q, J, step)):
            return step
        solve = self._method_solves(q, J, e, ff)
        everything = np.ones(self.stack.chain.size, dtype=bool)
        dq = step / self._dt
        if self._user_stage is not None and self._kernel_bounds:
            dq = solve(everything, None)  # a user's limit is broken: the method alone, then
            # the whole stage
        if self.acceleration_limit is not None:
            dq, solve.feedback = self._brake_feedback(dq, solve(everything, None, 0.0), J, e)
        return self._enforce(q, J, dq, solve)

    def _user_rows_hold(self, q, J, step) -> bool:
        """Whether the kernel's step, which kept the position and speed bounds, is left as it
        is by the user's limits: checked against their bounds and rows and, when it breaks a
        row, projected onto the rows within every bound, in one compiled call (the kernel's
        saturation stands: the same as the whole stage's while the user's bounds do not cut
        the step). False: the whole stage must run."""
        stack, user, motion = self.stack, self._user_stage, self._motion
        assert user is not None  # (for a user's limits)
        motion.q = q
        only = self._only
        rows: tuple | None
        if only is not None:  # (its bounds cannot cut a step the kernel kept)
            own = only.rows(stack.kinematics, motion)
            if own is None:
                return True
            A, b = as_rows(own)  # (rows_step checks their shapes and values)
            rows = (A, b, only.name)
            lower, upper = self._no_bounds
        elif self._rows_only:  # (their bounds cannot cut a step the kernel kept: _hold_speeds)
            rows = user.general_rows(stack.kinematics, motion, check=False)
            if rows is None:
                return True
            lower, upper = self._no_bounds
        else:
            parts = user.hard_parts(stack.kinematics, motion)
            if parts is None:
                return False
            lower, upper, rows = parts
            if rows is None and lower is None:
                return True
            if lower is None or upper is None:
                lower, upper = self._no_bounds
        A, b = (rows[0], rows[1]) if rows is not None else self._no_rows
        try:
            done = kernels.rows_step(J, q, A, b, lower, upper, self._work, step)
        except ValueError:  # rows or bounds that do not fit or hold NaN: name the limit
            user.check(stack.kinematics, motion)
            raise
        if done < 0:
            return False
        self._checked_rows = (self._count, rows)
        return True

    def _method_solves(self, q, J, e, ff) -> _MethodSolve:
        """The stage's re-solve: the method alone (no box, no smoothing) on this step's rows,
        on the joints it frees, with a task velocity less J times the held joints' velocity."""
        raw, layout = self._raw_work, self._layout
        np.copyto(raw, self._work)
        raw[kernels.P_BOX_COUNT] = 0.0
        raw[kernels.P_SMOOTH] = 0.0  # the method alone
        layout.inverse_speeds(raw)[:] = 0.0
        return _MethodSolve(self, q, J, e, ff if self._ff_on else np.zeros(self.stack.dim))

    def _enforce(self, q, J, dq, solve) -> np.ndarray:
        """The stage's enforcement of every limit on ``dq`` (its outcome kept for
        :attr:`last`), the step it commands, and with the compiled stage the motion state."""
        stack, motion, dt = self.stack, self._motion, self._dt
        outcome = self.stage.enforce(dq, solve, stack.kinematics, motion,
                                     lambda: stack.sqrt_weight[:, None] * J * stack.chain)
        self._outcome, self._outcome_count = outcome, self._count
        self._info[_I_SCALE] = outcome.scale  # (task_scale reads it there)
        step = self._exact_position(q, np.multiply(outcome.dq, dt, out=self._step))
        if self._compiled_smooth:  # the state the stage's step commands
            np.subtract(step / dt, motion.dq, out=motion.ddq)
            motion.ddq /= dt
            motion.dq[:] = step / dt
        return step

    def _exact_position(self, q: np.ndarray, step: np.ndarray) -> np.ndarray:
        """``step`` (in place) with every joint inside its range moved exactly onto a limit it
        reaches, not a rounding error past it."""
        limit = self.position_limit
        if limit is not None:
            x = q[limit.q_index]
            inside = (x >= limit.lower) & (x <= limit.upper)
            v = limit.v_index[inside]
            step[v] = np.clip(step[v], (limit.lower - x)[inside], (limit.upper - x)[inside])
        return step

    def _brake_feedback(self, dq: np.ndarray, dq_ff: np.ndarray, J: np.ndarray, e: np.ndarray
                        ) -> tuple[np.ndarray, float]:
        """With acceleration limits: slow the feedback part of ``dq`` (along its direction) so
        that every joint can still stop where the error says the target is — the remaining
        joint displacement ``delta = (dq - dq_ff) / k``, the method's own — within its
        acceleration and jerk limits: a target that jumps gives a ramp, and an arm arriving at
        a still target comes to rest instead of overshooting. Returns the slowed ``dq`` and its
        factor on ``K e``."""
        feedback = dq - dq_ff
        stack = self.stack
        k = float(np.mean(self._layout.gains(self._work)[:stack.target_dim]))
        if self._gain.mode != kernels.GAIN_FIXED:
            k *= float(self._info[kernels.I_GAIN])
        if not k > 0.0:
            return dq, 1.0
        delta = feedback / k
        # the motion along delta as one coordinate p (0 here, 1 at the target): its
        # acceleration limit is the joints' divided by how far each must go
        size = float(delta @ delta)
        rate = float(feedback @ delta) / size if size > 0.0 else 0.0
        if not rate > 0.0:
            return dq, 1.0
        span = np.abs(delta)
        moving = span > 0.0
        motion = self._motion
        # (the jerk limit is the smoothing's: a jerk-aware braking here lags behind a path)
        assert self.acceleration_limit is not None  # braking is for acceleration limits
        allowed = braking_speed(np.array([1.0]), np.array([float(motion.dq @ delta) / size]),
                                np.zeros(1), self._dt,
                                np.array([np.min(self.acceleration_limit.limits[moving]
                                                 / span[moving])]), None)[0]
        sigma = float(min(1.0, max(allowed, 0.0) / rate))
        if sigma >= 1.0:
            return dq, 1.0
        return dq_ff + sigma * feedback, sigma

    def _weighted_rows(self, targets):
        """``q -> (J_w, e_w)``: the weighted, masked task rows for ``targets``, evaluated on a
        stack of their own (the step's buffers stay as they are)."""
        probe = self._probe_stack()
        sw, mask = self.stack.sqrt_weight, self.stack.chain
        targets = list(targets)

        def rows(q):
            J, e, _ = probe.evaluate(q, targets, None)
            return sw[:, None] * J * mask, sw * e

        return rows

    def _probe_stack(self) -> TaskStack:
        if self._probe is None:
            self._probe = self.stack.copy()
        return self._probe

    # -- what the step did ----------------------------------------------------------------------
    @property
    def error_norm(self) -> float:
        """|e| of the last step (task units; NaN before the first), without building
        :attr:`last`: the cheap test of a control loop."""
        return math.sqrt(self._info[kernels.I_E_SQ]) if self._record is not None else math.nan

    @property
    def error(self) -> np.ndarray:
        """The last step's task error e (the target rows), as a view that the next step
        overwrites (copy it to keep it; :attr:`last` holds copies)."""
        if self._record is None:
            return np.full(0, np.nan)
        return self._record[1] if self.stack.single else self.stack.error

    @property
    def task_scale(self) -> float:
        """The last step's task scale s in [0, 1] (1: the constraint stage kept the whole task;
        see :attr:`StepInfo.task_scale`), without building :attr:`last`."""
        # (the kernel's saturation or acceleration stage writes it; the stage in Python, when
        # it runs, its own over it)
        return float(self._info[_I_SCALE]) if self._record is not None else 1.0

    @property
    def displacement(self) -> np.ndarray:
        """The last step's joint displacement ``q_dot dt`` (nv,; zeros before the first): the
        same array after every step, which the next step overwrites (copy it to keep it)."""
        return self._step  # (every path of a step writes its result there)

    @property
    def last(self) -> StepInfo | None:
        """The :class:`StepInfo` of the last step (``None`` before the first)."""
        if self._last is None and self._record is not None:
            info, stack = self._info, self.stack
            J, e, step, status, q, ff = self._record
            gain = self._gain
            k = gain.argument if isinstance(gain, FixedGain) else float(info[kernels.I_GAIN])
            Jw = stack.sqrt_weight[:, None] * J * stack.chain
            alpha = self.method.scaling_factors(Jw)
            escaped = self._escaped[1] and self._escaped[0] == self._count
            outcome = self._outcome if self._outcome_count == self._count else None
            if outcome is None and self._compiled_smooth and not status & kernels.NON_FINITE:
                outcome = self._smooth_outcome()
            elif outcome is None and status & (kernels.CLAMPED | kernels.SCALED):
                outcome = self._kernel_outcome(q, step)
            if outcome is None:
                outcome = Outcome(step / self._dt)
            if self._checked_rows[0] == self._count and self._checked_rows[1] is not None:
                A, b, owners = self._checked_rows[1]  # (owners: a name for every row)
                tight = A @ (step / self._dt) - b > -1e-9 * (1.0 + np.abs(b))
                outcome.rows = tuple(sorted({owners if isinstance(owners, str) else owners[i]
                                             for i in np.flatnonzero(tight)}))
            names: tuple[str, ...] = tuple(dict.fromkeys(joint for _, joint in outcome.active))
            index = {name: i for i, name in enumerate(self._v_names)}
            clamped = np.array([index[name] for name in names], dtype=np.int64)
            rows, sw = stack.target_dim, stack.sqrt_weight[:stack.target_dim]
            stalled = not escaped and makes_no_progress(
                Jw[:rows], sw * e[:rows], step / self._dt, sw * ff[:rows],
                float(self._work[kernels.P_STALL_ERROR]))
            self._last = StepInfo(
                error=np.array(self.error, dtype=float), error_norm=math.sqrt(info[kernels.I_E_SQ]),
                dq=step / self._dt, gain=k, loop_bound=float(info[kernels.I_LOOP]),
                pose=stack.poses(), alpha=alpha, escaped=escaped,
                clamped=clamped, clamped_joints=names, task_scale=float(outcome.scale),
                active_limits=outcome.active, active_rows=outcome.rows,
                limit_conflicts=outcome.conflict,
                outside_limits=outside(self._model, q, self.robot.lower_limits,
                                       self.robot.upper_limits, self.robot.mimic_joints),
                stalled=stalled)
        return self._last

    def _kernel_outcome(self, q: np.ndarray, step: np.ndarray) -> Outcome:
        """What the kernel's saturation on the position and speed bounds did (see
        :func:`~sjt_pin.constraints.saturate`), in the stage's terms."""
        dq = step / self._dt
        scale = float(self._info[kernels.I_SCALE])  # (a user's rows may have set it: rows_step)
        pairs = []
        position = self.position_limit
        at_position = np.zeros(dq.size, dtype=bool)
        if position is not None:
            x = q[position.q_index] + step[position.v_index]
            edge = (np.abs(x - position.lower) <= 1e-12 * (1 + np.abs(position.lower)))
            edge |= np.abs(x - position.upper) <= 1e-12 * (1 + np.abs(position.upper))
            x0 = q[position.q_index]
            outside = (x0 < position.lower) | (x0 > position.upper)
            at_position[position.v_index[edge | outside]] = True
        held = self._held_speeds
        for j in range(dq.size):
            if at_position[j]:
                pairs.append(("position", self._v_names[j]))
            elif abs(dq[j]) >= held[j] * (1 - 1e-12):
                pairs.append((self._speed_by[j], self._v_names[j]))
        return Outcome(dq, scale, self._clamped != 0.0, tuple(pairs))

    def _smooth_outcome(self) -> Outcome:
        """What the compiled acceleration/jerk stage did (its boxes and the limits that set
        them, left in the work vector), in the stage's terms (see
        :meth:`~sjt_pin.constraints.ConstraintStage.enforce`)."""
        layout, work = self._layout, self._work

        def part(k):
            return layout.smooth_part(work, k)

        hard = Bounds(part(kernels.SM_HARD_LO), part(kernels.SM_HARD_HI),
                      part(kernels.SM_HARD_LO_BY).astype(np.int64),
                      part(kernels.SM_HARD_HI_BY).astype(np.int64))
        soft = Bounds(part(kernels.SM_SOFT_LO), part(kernels.SM_SOFT_HI),
                      part(kernels.SM_SOFT_LO_BY).astype(np.int64),
                      part(kernels.SM_SOFT_HI_BY).astype(np.int64))
        dq = part(kernels.SM_OUT).copy()
        active = active_limits(dq, Box(hard, soft), kernels.LIMIT_NAMES, self._v_names,
                               part(kernels.SM_DESIRED))
        if (self._speed_by != "velocity").any():  # the speed bounds that are a limit's caps
            index = {name: j for j, name in enumerate(self._v_names)}
            active = tuple((self._speed_by[index[joint]] if name == "velocity" else name, joint)
                           for name, joint in active)
        torn = np.flatnonzero(part(kernels.SM_TORN))
        parts = self._user_parts
        if (self._checked_rows[0] == self._count and parts is not None and parts[0] is not None
                and self._user_stage is not None):
            # the user's bounds the correction put joints on (evaluated again, as they were)
            n = dq.size
            before = replace(self._motion, dq=self._before[:n], ddq=self._before[n:])
            user = self._user_stage.box(self.stack.kinematics, before)
            if user is not None:
                names = [limit.name for limit in self._user_stage.limits]
                active += tuple(pair for pair in active_limits(dq, Box(user.hard), names,
                                                                self._v_names)
                                if pair not in active)
        return Outcome(dq, float(self._info[kernels.I_SCALE]), self._clamped != 0.0, active,
                       conflict=tuple(self._v_names[j] for j in torn))

    # -- safeguards ----------------------------------------------------------------------------
    def _raise_non_finite(self, q: np.ndarray, targets) -> None:
        self.robot.check_q(q)  # names q if it holds NaN or inf
        if not math.isfinite(self._info[kernels.I_E_SQ]):
            raise_non_finite_targets(targets)
        raise ValueError("target_velocity contains NaN or inf (the feed-forward is not finite)")

    # -- other entry points ----------------------------------------------------------------------
    def solve(self, target, q0, **options):
        """Solve to ``target`` from ``q0`` (set-point IK): Levenberg-Marquardt on this
        method's columns (SJT's normalised ones for SJT) within the limits, restarted (from the
        configurations of a seeded table whose poses are nearest the target, then from random
        ones) until it succeeds or its budget (2000 iterations) runs out; see
        :func:`sjt_pin.ik.solve` for the options. Returns an :class:`~sjt_pin.IKResult`."""
        from .ik import solve

        return solve(self, target, q0, **options)

    def search(self):
        """The set-point IK state of this solver (:class:`~sjt_pin.ik.Search`, created on
        first use; its buffers are its own)."""
        if self._search is None:
            from .ik import Search

            self._search = Search(self)
        return self._search

    # -- copies ----------------------------------------------------------------------------
    def __reduce__(self):
        """A copy (``pickle``, ``copy.deepcopy``, another process) is the same solver made anew
        — buffers of its own, bound to its own arrays — carrying this one's state: the gain and
        period as set now, the commanded velocity and acceleration, the saddle escape (also
        mid-escape) and the stability warning. Its next steps are this one's, bitwise; it has
        no :attr:`last` step until it makes one."""
        arguments = self.options.replace(gain=self._gain, dt=self._dt,
                                         check_stability=self._stability.enabled)
        state = {"motion": (self._motion.dq.copy(), self._motion.ddq.copy()),
                 "escape": self.escape, "escaping": float(self._work[kernels.P_ESCAPING]),
                 "escape_velocity": self._escape_velocity.copy(), "warned": self._stability.warned,
                 "count": self._count, "stall": (float(self._work[kernels.P_STALL_RUN]),
                                                  float(self._work[kernels.P_STALL_WAIT]))}
        return (_rebuild, (type(self), self.robot, self.method, arguments), state)

    def __setstate__(self, state: dict) -> None:
        self._motion.dq[:], self._motion.ddq[:] = state["motion"]
        self.escape = state["escape"]
        self._work[kernels.P_ESCAPING] = state["escaping"]
        self._escape_velocity[:] = state["escape_velocity"]
        self._stability.warned, self._count = state["warned"], state["count"]
        self._work[kernels.P_STALL_RUN], self._work[kernels.P_STALL_WAIT] = state["stall"]
        self._configure()

    def __repr__(self) -> str:
        tasks = self.stack.tasks[0] if len(self.stack.tasks) == 1 else self.stack.tasks
        return (f"{type(self).__name__}({self.robot.name!r}, gain={self.gain!r}, "
                f"dt={self._dt:g}, task={tasks!r})")


class _MethodSolve:
    """``solve(free, held, scale=None)``: the joint velocity (rad/s, m/s) of a solver's method
    alone on one step's rows, moving only the joints ``free`` (bool per joint) with the
    velocity ``held`` of the others taken out of the task velocity (``None``: none held), and
    the feedback ``K e`` scaled by ``scale`` (default :attr:`feedback`, 1 until the braking of
    acceleration limits sets it): what :meth:`ConstraintStage.enforce` re-solves with."""

    def __init__(self, solver: Solver, q, J, e, ff_in):
        self.solver, self.q, self.J, self.e, self.ff_in = solver, q, J, e, ff_in
        self.feedback = 1.0  # the factor of K e in the task velocity the stage re-solves with
        self.out = np.empty_like(solver._step)

    def __call__(self, free, held, scale=None) -> np.ndarray:
        solver = self.solver
        layout, raw, work = solver._layout, solver._raw_work, solver._work
        scale = self.feedback if scale is None else scale
        v = self.ff_in if held is None else self.ff_in - self.J @ held
        layout.joint_mask(raw)[:] = solver.stack.chain * free
        raw[kernels.P_HAS_FF] = 1.0
        if scale != 1.0:  # a fixed gain of scale times the one this step used
            raw[kernels.P_GAIN_MODE] = kernels.GAIN_FIXED
            gains = layout.gains(raw)
            gains[:] = layout.gains(work) * scale
            if solver._gain.mode != kernels.GAIN_FIXED:
                gains *= float(solver._info[kernels.I_GAIN])
        solver._method_step(self.J, self.e, v, self.q, raw, self.out)
        raw[kernels.P_GAIN_MODE] = work[kernels.P_GAIN_MODE]
        layout.gains(raw)[:] = layout.gains(work)
        return self.out / solver._dt


def _rebuild(cls, robot: Robot, method: Method, options: SolverOptions) -> Solver:
    """A solver of class ``cls`` made anew (the unpickling half of ``Solver.__reduce__``)."""
    solver = Solver.__new__(cls)
    Solver.__init__(solver, robot, method, **options.keywords())
    return solver


def _check_parts(robot, method) -> None:
    """A solver's robot and method, checked at the door."""
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a sjt_pin.Robot, got {type(robot).__name__}")
    if not isinstance(method, Method):
        raise TypeError(f"method must be a sjt_pin Method, got {type(method).__name__}")
    if robot.nv == 0:
        raise ValueError(f"robot {robot.name!r} has no moving joint: there is nothing to "
                         "solve for")


def _task(options: SolverOptions):
    """The task(s) of ``options``: ``task``, or the pose task of length ``pose_length``."""
    if options.pose_length is None:
        return options.task
    if options.task is not None:
        raise ValueError("pose_length sets the length of the pose task made when task is "
                         "None; with a task of your own pass PoseTask(length=...)")
    return PoseTask(length=options.pose_length)


def _speed_limits(velocity_limits, urdf: np.ndarray, nv: int) -> np.ndarray:
    """The speed limits a solver enforces (rad/s, m/s; inf for none)."""
    if velocity_limits is None or velocity_limits is True:
        return urdf.copy()
    if velocity_limits is False:
        return np.full(nv, np.inf)
    if isinstance(velocity_limits, (str, bytes)) or np.iscomplexobj(velocity_limits):
        raise ValueError(f"velocity_limits must be True, False or an array, "
                         f"got {velocity_limits!r}")
    vmax = np.asarray(velocity_limits, dtype=float)
    if vmax.shape != (nv,) or np.any(np.isnan(vmax)) or np.any(vmax <= 0):
        raise ValueError(f"velocity_limits must have shape ({nv},) with entries > 0 "
                         f"(rad/s or m/s; inf for none), got {velocity_limits!r}")
    return vmax
