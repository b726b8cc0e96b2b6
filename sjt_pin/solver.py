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
   the mapping M (for a method of your own, its matrix, mapped here), the lower priority levels
   in the null space of the higher ones, the saddle escape's velocity, each joint's box from
   the position, speed, acceleration and jerk limits, and the projection that keeps the
   method's step where it is feasible and returns the feasible velocity nearest it in the
   method's metric where it is not (:mod:`~sjt_pin.constraints`);
4. only when something needs it, Python: an error to raise, the stability check, the escape's
   curvature test;
5. ``pinocchio.integrate`` moves ``q`` on its manifold (continuous joints, free flyers);
6. :attr:`Solver.last` builds a :class:`~sjt_pin.step_info.StepInfo` on first access.

Arguments are validated at the door (``step``, ``solve``, the setters); inside, nothing is
validated twice. Which stages run is decided by the data (the limits given, the levels), not
by flags.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from . import kernels
from .constraints import UserLimits
from .escape import SaddleEscape
from .exceptions import ConcurrentStepError
from .gains import FixedGain, Gain, as_gain
from .joint_ranges import outside
from .limits import AccelerationLimit, JerkLimit, Motion, PositionLimit, VelocityLimit
from .methods import Method
from .options import SolverOptions
from .robot import Robot
from .stability import StabilityCheck
from .stack import TaskStack, normalise_tasks
from .step_info import StepInfo, step_info
from .tasks import PoseTask, PostureTask
from .tasks.pose import tasks_length
from .validation import period, raise_non_finite_targets

if TYPE_CHECKING:
    from .joint_move import JointMove

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
        _check_parts(robot, method)
        self.robot, self.method = robot, method
        self.stack = stack = TaskStack(robot, normalise_tasks(_task(opts), opts.posture))
        self._model, self._q_shape = robot.model, (robot.nq,)
        #: a q with quaternions or (cos, sin) pairs is checked on its manifold, unless it is
        #: the array the last step returned (pin.integrate keeps it there)
        self._unit_blocks = robot.unit_blocks
        self._units = self._unit_blocks.size > 0
        # the array the last step returned (trusted as it is); none before the first step
        self._returned: object = _NOTHING
        self._first = True  # the first step checks the targets' distance (units)
        self._dt = period(opts.dt)
        self._gain = as_gain(opts.gain, stack.target_dim)
        method.adapt(stack.targeted, tasks_length(robot, stack.tasks))
        self._build_limits(opts)
        self.escape = (SaddleEscape(robot.model, stack.chain, robot.velocity_limits,
                                    self.position_limit) if opts.escape and method.stalls
                       else None)
        self._controller = self._make_controller()
        self._stability = StabilityCheck(method, stack.n_chain, opts.check_stability)
        self._step = np.zeros(robot.nv)
        self._escaped = (-1, False)  # (step count, whether that step added the escape)
        self._probe: TaskStack | None = None
        self._search = None
        self._count = 0
        self._stepping = False  # a step runs (ConcurrentStepError for a second thread)
        self._last: StepInfo | None = None
        #: the last step's rows, error, configuration, feed-forward and row owners
        self._record: tuple | None = None
        self._configure()

    # -- construction --------------------------------------------------------------------------
    def _build_limits(self, opts: SolverOptions) -> None:
        """The built-in limits (position, speed, acceleration, jerk) and the user's."""
        robot, stack, n = self.robot, self.stack, self.robot.nv
        moving = stack.chain > 0
        urdf = robot.velocity_limits
        self.acceleration_limit = (None if opts.acceleration_limits is None
                                   else AccelerationLimit(opts.acceleration_limits, n))
        self.jerk_limit = None if opts.jerk_limits is None else JerkLimit(opts.jerk_limits, n)
        if self.jerk_limit is not None and self.acceleration_limit is None:
            raise ValueError("jerk_limits need acceleration_limits (the braking distance of a "
                             "jerk-limited stop depends on both)")
        position = PositionLimit(robot, moving, np.where(np.isfinite(urdf), urdf,
                                                         SaddleEscape.DEFAULT_SPEED))
        use = position.active if opts.position_limits is None else (
            bool(opts.position_limits) and position.active)
        self.position_limit = position if use else None
        speeds = _speed_limits(opts.velocity_limits, urdf, n)
        self.velocity_limit = VelocityLimit(speeds) if np.isfinite(speeds).any() else None
        self._user = UserLimits(opts.limits, n) if opts.limits else None
        self._motion = Motion(robot.q0.copy(), np.zeros(n), np.zeros(n), self._dt,
                              None if self.acceleration_limit is None
                              else self.acceleration_limit.limits,
                              None if self.jerk_limit is None else self.jerk_limit.limits)

    def _make_controller(self):
        robot, stack, method = self.robot, self.stack, self.method
        params = method.parameters()
        self._matrix_method = params is None  # a method of your own: mapped here
        if params is None:
            params = kernels.MethodParameters()  # the stage's metric of JT
            params.scaled, params.damped_feedback, params.damped_feedforward = False, False, True
        position = self.position_limit
        empty = np.zeros(0)
        accel, jerk = self.acceleration_limit, self.jerk_limit
        controller = kernels.Controller(
            params, stack.dim, robot.nv, robot.nq, self._dt, stack.sqrt_weight,
            np.ones(stack.dim), stack.chain, stack.target_dim, stack.levels,
            np.full(robot.nv, np.inf),
            empty.astype(np.int64) if position is None else position.q_index,
            empty.astype(np.int64) if position is None else position.v_index,
            empty if position is None else position.lower,
            empty if position is None else position.upper,
            empty if position is None else position.recovery_speeds,
            None if accel is None else accel.limits, None if jerk is None else jerk.limits,
            -1.0 if self.escape is None else SaddleEscape.STALL_RATIO,
            # converged, not stalled: |e_w| below ERROR_FLOOR times the tasks' length
            (SaddleEscape.ERROR_FLOOR * tasks_length(robot, stack.tasks)) ** 2)
        #: the motion state a user's limits read is the controller's own
        self._motion.dq, self._motion.ddq = controller.dq, controller.ddq
        return controller

    def _configure(self) -> None:
        """Write what depends on the gain and dt into the controller: the rows' gains, the
        period, the speed limits (with the user's limits' caps at this period)."""
        stack, gain, c = self.stack, self._gain, self._controller
        rows = gain.rows(stack.target_dim, stack.posture_dim)
        gains = np.empty(stack.dim)
        other = np.ones(stack.dim, dtype=bool)
        other[stack.error_rows] = False
        gains[stack.error_rows] = rows[:stack.target_dim]
        gains[other] = rows[stack.target_dim:]
        c.set_gains(gains, gain.mode != kernels.GAIN_FIXED, gain.factor)
        c.set_dt(self._dt)
        self._motion.dt = self._dt
        self._stability.arm(gain.mode == kernels.GAIN_FIXED, gain.largest * self._dt)
        moving = stack.chain > 0
        speeds = np.where(moving, np.inf if self.velocity_limit is None
                          else self.velocity_limit.limits, 0.0)
        by = np.full(speeds.size, "velocity", dtype=object)
        if self._user is not None:
            self._user.capped = set()
            for k, limit in enumerate(self._user.limits):
                caps = limit.speed_caps(self._dt)
                if caps is None:
                    continue
                caps = np.asarray(caps, dtype=float)
                if caps.shape != speeds.shape or np.isnan(caps).any() or (caps <= 0).any():
                    raise ValueError(f"{limit!r}.speed_caps() must return ({speeds.size},) "
                                     f"speeds > 0 (rad/s or m/s; inf for none), got {caps!r}")
                self._user.capped.add(k)  # (its bounds never go below its caps)
                tighter = moving & (caps < speeds)
                speeds = np.where(tighter, caps, speeds)
                by[tighter] = limit.name
        self._speed_by = by
        c.set_speed(np.where(moving, speeds, 0.0))
        self._motion.velocity_limits = np.where(moving, speeds, 0.0)
        self._busy = self._first or self._stability.armed or (
            self.escape is not None and self.escape.active)

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
        """Forget the commanded velocity and acceleration (the next step starts from rest)
        and any saddle escape in progress."""
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
            self._refuse_concurrent()
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
                J, e, ff = stack.evaluate(q, targets, velocities)
            if not stack.trusted:
                J, e, ff = stack.contiguous(J, e, ff)
            # 2. the user's limits at q
            lower = upper = A = b = owners = None
            if self._user is not None:
                self._motion.q = q
                lower, upper, A, b, owners = self._user.evaluate(stack.kinematics, self._motion)
            # 3. method and stage, compiled
            fb = ff_given = None
            if self._matrix_method:
                fb, ff_given = self._matrix_step(J, e, ff)
            status = self._controller.run(J, e, ff, q, self._step, fb, ff_given, lower, upper,
                                          A, b)
            self._count += 1
            if status & _PYTHON or self._busy:
                self._slow(status, q, J, [target] if targets is None else targets)
            # 4. integrate on the manifold; the record of the step (StepInfo) is built on demand
            self._record, self._last = (J, e, q, ff, owners, status), None
            self._returned = q_next = _integrate(self._model, q, self._step)
            return q_next
        finally:
            self._stepping = False

    def _refuse_concurrent(self) -> None:
        raise ConcurrentStepError(
            f"{type(self).__name__} is being stepped by another thread: a solver's buffers "
            "and pin.Data are one thread's; give each thread its own solver "
            "(copy.deepcopy(solver) makes one in the same state)")

    def _matrix_step(self, J, e, ff):
        """A method of your own: its matrix M on the first level's weighted rows, the gain
        (``"auto"``: ``c / (dt lambda_max(J M))``), and the feedback and feed-forward velocities
        it asks for (the compiled stage takes them from there)."""
        stack = self.stack
        begin, end, _, targets = stack.levels[0]
        sw = stack.sqrt_weight[begin:end]
        Jw = sw[:, None] * J[begin:end] * stack.chain
        M = np.asarray(self.method.matrix(Jw), dtype=float)
        gain = self._gain
        k = gain.rows(stack.target_dim, stack.posture_dim)[:end - begin]
        if gain.mode == kernels.GAIN_FIXED:
            scale = 1.0
        else:
            loop = float(np.max(np.linalg.eigvals(Jw @ M).real, initial=0.0))
            scale = gain.factor / (self._dt * loop) if loop > 0.0 else 0.0
        fb = M @ (scale * k * sw * e[begin:end])
        self._controller.given_gain = scale * float(np.mean(k[:max(targets, 1)]))
        ff_given = None if ff is None else M @ (sw * ff[begin:end])
        return fb, ff_given

    def _slow(self, status, q, J, targets) -> None:
        """What the fast path skips: errors, the first step's checks, the stability check, the
        escape's state (its velocity for the next step)."""
        c = self._controller
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
            stack = self.stack
            self._stability.check(stack.sqrt_weight[:, None] * J * stack.chain, c.trace,
                                  self._gain.largest, self._dt)
        escape = self.escape
        self._escaped = (self._count, escape is not None and escape.active)
        if escape is not None:
            if status & kernels.STALLED and not escape.active:
                run = c.stall_run
                if escape.observe(run, c.ew_sq):
                    escape.test(q, self._weighted_rows(targets))
                if run > 1.0:  # a window ended: the kernel counts the next one
                    c.stall_run = 0.0
                c.stall_wait = escape.wait
            velocity = None if not escape.active else escape.velocity(c.regular, self._dt,
                                                                      c.ew_sq)
            if velocity is None:
                if c.escaping:  # an escape ended: a stall after it is a new run
                    c.stall_run = -1.0
                    c.escaping = False
                    c.escape_velocity[:] = 0.0
            else:  # the kernel adds it, within the limits, from the next step on
                c.escaping = True
                c.escape_velocity[:] = velocity
        self._busy = self._stability.armed or (escape is not None and escape.active)

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

    def _weighted_rows(self, targets):
        """``q -> (J_w, e_w)``: the weighted, masked task rows for ``targets``, evaluated on a
        stack of their own (the step's buffers stay as they are)."""
        if self._probe is None:
            self._probe = self.stack.copy()
        probe, sw, mask = self._probe, self.stack.sqrt_weight, self.stack.chain
        targets = list(targets)

        def rows(q):
            J, e, _ = probe.evaluate(q, targets, None)
            return sw[:, None] * J * mask, sw * e

        return rows

    def _raise_non_finite(self, q: np.ndarray, targets) -> None:
        self.robot.check_q(q)  # names q if it holds NaN or inf
        if not math.isfinite(self._controller.e_sq):
            raise_non_finite_targets(targets)
        raise ValueError("target_velocity contains NaN or inf (the feed-forward is not finite)")

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
        if self._record is None:
            return np.full(0, np.nan)
        return self.stack.task_error(self._record[1])

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
            J, e, q, ff, owners, status = self._record
            gain = self._gain
            self._last = step_info(
                self._controller, self.stack, self.robot, J, e, q, ff, self._step, owners,
                self._user,
                self._speed_by, gain.argument if isinstance(gain, FixedGain) else None,
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

        Step it like a solver, ``q = move.step(q)``, until ``move.done``: each step is a step
        of a twin of this solver (the same method, options and limits, so every limit holds on
        every step) tracking the frame's pose along the path, with a posture task pulling the
        joints along it (a redundant arm would drift in its null space); this solver's motion
        state follows, so it carries on from the move without a jump. Raises ``ValueError``
        when ``solve()`` finds no configuration within its tolerance, or when the solver's
        task is not one frame's (a multi-task solver moves by its own targets)."""
        from .joint_move import JointMove

        stack = self.stack
        if not stack.single or stack.task.frame_id < 0:
            raise ValueError("move_to needs a solver with one frame task (PoseTask, "
                             "PositionTask, OrientationTask)")
        q = self.robot.check_q(q)
        result = self.solve(target, q, **options)
        if not result.success:
            raise ValueError(f"move_to: solve() found no configuration that reaches the target "
                             f"(best error {result.error:.3g} after {result.restarts} restarts)")
        posture = PostureTask(q, weight=JointMove.POSTURE_WEIGHT)
        twin = _rebuild(type(self), self.robot, self.method,
                        self.options.replace(posture=posture, gain=self._gain, dt=self._dt,
                                             check_stability=False))
        twin.continue_from(self)
        speed = None if self.velocity_limit is None else self.velocity_limit.limits
        return JointMove(self, twin, stack.task.frame_id, q, result.q, speed,
                         None if self.acceleration_limit is None
                         else self.acceleration_limit.limits,
                         None if self.jerk_limit is None else self.jerk_limit.limits, share)

    def continue_from(self, other: Solver) -> None:
        """Carry on from ``other``'s motion state (the joint velocity and acceleration it
        commanded last), as when one controller hands the arm to another: this solver's next
        step starts from there, within its acceleration and jerk limits."""
        if other.robot.nv != self.robot.nv:
            raise ValueError("continue_from needs a solver of a robot with the same joints")
        mine, theirs = self._controller, other._controller
        mine.dq[:], mine.ddq[:] = theirs.dq, theirs.ddq

    def search(self):
        """The set-point IK state of this solver (:class:`~sjt_pin.ik.Search`, created on
        first use; its buffers are its own)."""
        if self._search is None:
            from .ik import Search

            self._search = Search(self)
        return self._search

    @property
    def user_limits(self) -> UserLimits | None:
        """The limits beyond the built-in ones (what ``solve()`` honours besides the URDF), or
        ``None``."""
        return self._user

    # -- copies --------------------------------------------------------------------------------
    def __reduce__(self):
        """A copy (``pickle``, ``copy.deepcopy``, another process) is the same solver made anew
        — buffers of its own, bound to its own arrays — carrying this one's state: the gain and
        period as set now, the commanded velocity and acceleration, the saddle escape (also
        mid-escape) and the stability warning. Its next steps are this one's, bitwise; it has
        no :attr:`last` step until it makes one."""
        arguments = self.options.replace(gain=self._gain, dt=self._dt,
                                         check_stability=self._stability.enabled)
        c = self._controller
        state = {"motion": (c.dq.copy(), c.ddq.copy()), "escape": self.escape,
                 "escaping": c.escaping, "escape_velocity": c.escape_velocity.copy(),
                 "warned": self._stability.warned, "count": self._count, "first": self._first,
                 "stall": (c.stall_run, c.stall_wait)}
        return (_rebuild, (type(self), self.robot, self.method, arguments), state)

    def __setstate__(self, state: dict) -> None:
        c = self._controller
        c.dq[:], c.ddq[:] = state["motion"]
        self.escape = state["escape"]
        c.escaping = state["escaping"]
        c.escape_velocity[:] = state["escape_velocity"]
        self._stability.warned, self._count = state["warned"], state["count"]
        self._first = state["first"]
        c.stall_run, c.stall_wait = state["stall"]
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
