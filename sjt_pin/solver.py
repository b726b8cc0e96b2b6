"""Closed-loop inverse kinematics (CLIK): one step pipeline for every method and task.

Every solver implements the paper's CLIK law::

    q_dot = M(J(q)) (x_dot_d + K e),     e = task error at q        (eq. 5, 10, 21)
    q_next = integrate(q, q_dot dt)                                  (eq. 9, 11, 22)

and every ``step()`` — any method, any tasks, with or without feed-forward, posture or
limits — runs the same stages:

1. the :class:`~sjt_pin.stack.TaskStack` evaluates the kinematics of ``q`` once and each task's
   error, Jacobian rows and desired velocity, stacked;
2. the :class:`~sjt_pin.methods.Method`'s compiled kernel applies the gain
   (:mod:`~sjt_pin.gains`) and the mapping M, in one call;
3. a :class:`~sjt_pin.escape.SaddleEscape` adds a smooth escape velocity at a saddle (JT, SJT);
4. the :class:`~sjt_pin.limits.Limit` objects test the step and, when needed, enforce it;
5. ``pinocchio.integrate`` moves ``q`` on its manifold (continuous joints, free flyers);
6. :attr:`Solver.last` builds a :class:`StepInfo` from the step's buffers on first access.

Arguments are validated at the door (``step``, ``solve``, the setters); inside, nothing is
validated twice and the per-step checks are a few float comparisons.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import kernels as K
from .escape import SaddleEscape
from .exceptions import GainWarning
from .gains import Gain, as_gain
from .limits import Limit, PositionLimit, VelocityLimit
from .methods import Method
from .robot import Robot
from .stack import TaskStack, normalise_tasks
from .tasks import PostureTask, Task
from .validation import positive, raise_non_finite_targets

_F64 = np.dtype(np.float64)
_NONE_CLAMPED = np.zeros(0, dtype=np.int64)
#: status bits that need Python: an error to raise, a stall for the escape to look at
_PYTHON = K.NON_FINITE | K.STALLED


@dataclass(frozen=True)
class StepInfo:
    """What one ``step()`` computed, at the configuration it was given.

    Attributes:
        error: task error e (the stacked rows of the tasks that take targets, without posture
            rows; m and rad), before weights and gain.
        error_norm: Euclidean norm of ``error``.
        dq: joint velocity q_dot (nv,) in rad/s or m/s, after the escape and the limits (the
            step integrated is ``dq * dt``).
        gain: K used in this step (1/s): a number, or one per task row for a per-row gain.
        loop_bound: the bound of lambda_max(J M) that "auto" divided by (1 when the method's
            loop eigenvalues are at most 1, or with a fixed gain).
        pose: world pose of the task frame (``pin.SE3``); with several frames a dict
            ``{frame: pose}``.
        alpha: SJT's scaling factors alpha_i (nv,), 0 for joints that do not move the tasks;
            ``None`` for the other methods.
        escaped: a saddle escape velocity was added (JT, SJT).
        clamped: velocity (tangent) indices — columns of J, entries of ``dq`` — of the joints
            held at a position limit; ``clamped_joints`` are their names.
        velocity_scale: factor (<= 1) applied to the whole joint velocity for the speed limits.
    """

    error: np.ndarray
    error_norm: float
    dq: np.ndarray
    gain: float | np.ndarray
    loop_bound: float
    pose: pin.SE3 | dict
    alpha: np.ndarray | None
    escaped: bool
    clamped: np.ndarray
    clamped_joints: tuple[str, ...]
    velocity_scale: float

    def __repr__(self) -> str:
        return (f"StepInfo(error_norm={self.error_norm:.3g}, "
                f"|dq|={float(np.linalg.norm(self.dq)):.3g} rad/s)")


class Solver:
    """A CLIK solver: a :class:`~sjt_pin.methods.Method` and the step pipeline around it.

    The public solvers :class:`~sjt_pin.SJTSolver`, :class:`~sjt_pin.JTSolver`,
    :class:`~sjt_pin.JPSolver` and :class:`~sjt_pin.DLSSolver` document every option; this class
    takes a method object, for methods of your own.

    Args:
        robot: the :class:`~sjt_pin.Robot` to move.
        method: the mapping M(J), a :class:`~sjt_pin.methods.Method`.
        gain: K in 1/s: a number, one number per task row, ``"auto"`` or a
            :class:`~sjt_pin.gains.Gain` (see :mod:`~sjt_pin.gains`).
        dt: control period in s (the integration step), > 0.
        task: a :class:`~sjt_pin.Task` (default: a pose task on the end effector), a list of
            tasks on distinct frames, or a ``{frame: task}`` mapping; with several tasks
            ``step`` takes ``{frame: target}`` mappings.
        posture: a :class:`~sjt_pin.PostureTask` stacked under the tasks (redundant robots).
        position_limits: keep 1-DoF joints within their URDF position limits (default: on when
            the URDF has them).
        velocity_limits: ``True``/``None`` for the URDF's speed limits, ``False`` for none, or
            an (nv,) array in rad/s or m/s (``inf`` for none).
        escape: add a smooth escape at the saddles of singular configurations (JT, SJT).
        check_stability: warn (:class:`~sjt_pin.GainWarning`, once) when a fixed gain exceeds
            the linear stability bound ``2 / (dt lambda_max(J M))`` at the current q.
        limits: further :class:`~sjt_pin.limits.Limit` objects, applied after the built-in ones.
    """

    def __init__(
        self,
        robot: Robot,
        method: Method,
        gain: float | str | Sequence[float] | Gain = "auto",
        dt: float = 1e-3,
        task: Task | Sequence[Task] | Mapping[str, Task] | None = None,
        *,
        posture: PostureTask | None = None,
        position_limits: bool | None = None,
        velocity_limits: bool | np.ndarray | None = None,
        escape: bool = True,
        check_stability: bool = True,
        limits: Sequence[Limit] = (),
    ):
        if not isinstance(robot, Robot):
            raise TypeError(f"robot must be a sjt_pin.Robot, got {type(robot).__name__}")
        if not isinstance(method, Method):
            raise TypeError(f"method must be a sjt_pin Method, got {type(method).__name__}")
        if robot.nv == 0:
            raise ValueError(f"robot {robot.name!r} has no moving joint: there is nothing to "
                             "solve for")
        self.robot = robot
        self.method = method
        self.stack = TaskStack(robot, normalise_tasks(task, posture))
        stack = self.stack
        n = robot.nv
        self._model = robot.model
        self._q_shape = (robot.nq,)
        self._dt = positive(dt, "dt", "s")
        self._kernel = method.kernel
        # limits: the built-in ones run inside the method's kernel (their data in ``work``);
        # further Limit objects after it, in Python
        urdf_speeds = robot.velocity_limits
        moving = stack.chain > 0
        position = PositionLimit(robot, moving, np.where(np.isfinite(urdf_speeds), urdf_speeds,
                                                         SaddleEscape.DEFAULT_SPEED))
        use_position = position.active if position_limits is None else (
            bool(position_limits) and position.active)
        self.position_limit = position if use_position else None
        speeds = np.where(moving, _speed_limits(velocity_limits, urdf_speeds, n), np.inf)
        velocity = VelocityLimit(speeds)
        self.velocity_limit = velocity if velocity.active else None
        self._extra_limits = list(limits)
        for extra in self._extra_limits:
            if not isinstance(extra, Limit):
                raise TypeError(f"limits must hold sjt_pin Limit objects, got {extra!r}")
        self.limits: list[Limit] = [x for x in (self.position_limit, self.velocity_limit)
                                    if x is not None] + self._extra_limits
        self.escape = (SaddleEscape(robot.model, stack.chain, urdf_speeds, self.position_limit)
                       if escape and method.stalls else None)
        # the kernel's work vector: parameters, weights, gains, mask, box, speeds, scratch
        box = self.position_limit
        self._layout = layout = K.Layout(stack.dim, n, 0 if box is None else box.q_index.size)
        self._work = work = layout.allocate()
        self._info = layout.info(work)
        layout.sqrt_weight(work)[:] = stack.sqrt_weight
        self._mask = layout.joint_mask(work)
        self._mask[:] = stack.chain
        if box is not None:
            for part, values in enumerate((box.q_index, box.v_index, box.lower, box.upper,
                                           box.recovery_speeds)):
                layout.box_part(work, part)[:] = values
        self._escape_velocity = layout.extra_velocity(work)
        self._clamped = layout.clamped_joints(work)
        layout.inverse_speeds(work)[:] = np.where(np.isfinite(speeds), 1.0 / speeds, 0.0)
        work[K.P_ERROR_ROWS] = stack.target_dim
        work[K.P_STALL_RATIO] = -1.0 if self.escape is None else SaddleEscape.STALL_RATIO
        work[K.P_STALL_ERROR] = SaddleEscape.ERROR_FLOOR ** 2
        self._step = np.zeros(n)
        self._no_ff = np.zeros(stack.dim)
        self._ff_on = False
        self._escaped = (-1, False)  # (step count, whether that step added the escape)
        self._v_names = robot.velocity_names
        self._check_stability = bool(check_stability)
        self._warned = False
        self._probe: TaskStack | None = None
        self._search = None
        self._gain = as_gain(gain, stack.target_dim)
        self._configure()
        self._count = 0
        self._last: StepInfo | None = None
        #: the last step's rows, error, displacement and status (None before the first)
        self._record: tuple | None = None

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
        self._dt = positive(dt, "dt", "s")
        self._configure()

    @property
    def check_stability(self) -> bool:
        """Warn once when a fixed gain exceeds the stability bound (see the class docstring)."""
        return self._check_stability

    @check_stability.setter
    def check_stability(self, value: bool) -> None:
        self._check_stability = bool(value)
        self._configure()

    def _configure(self) -> None:
        """Write everything that depends on the gain and dt into the kernel's parameters."""
        stack, gain, work = self.stack, self._gain, self._work
        self.method.configure(work, gain, self._dt, stack.n_chain)
        work[K.P_FF_MODE] = self.method.feedforward_mode()
        self._layout.gains(work)[:] = gain.rows(stack.target_dim, stack.posture_dim)
        self._k_dt = gain.largest * self._dt
        bound = self.method.bound(stack.n_chain)
        # the check can only fire when k dt times a bound of lambda_max reaches 2
        self._gain_check = (self._check_stability and not self._warned
                            and gain.mode == K.GAIN_FIXED
                            and (bound is None or self._k_dt * bound >= 2.0))
        self._update_slow()

    def _update_slow(self) -> None:
        """Whether every step must take the slow path (an escape in progress, a pending
        stability check, limits outside the kernel's box)."""
        self._always = (self._gain_check or bool(self._extra_limits)
                        or (self.escape is not None and self.escape.active))

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
        """
        if not (type(q) is np.ndarray and q.shape == self._q_shape and q.dtype == _F64):
            q = self.robot.check_q(q)
        # 1. the task rows at q
        stack = self.stack
        if stack.single:
            task = stack.task
            target = task.target(target)
            velocity = None if target_velocity is None else task.velocity(target_velocity)
            kinematics = stack.kinematics
            kinematics.update(q)
            J, e, ff = task.compute(kinematics, target, velocity)
            targets = (target,)
        else:
            targets, velocities = stack.targets(target, target_velocity)
            J, e, ff = stack.evaluate(q, targets, velocities)
        # 2. gain, mapping, escape velocity and limits, in one compiled call
        if ff is None:
            if self._ff_on:
                self._work[K.P_HAS_FF], self._ff_on = 0.0, False
            ff = self._no_ff
        elif not self._ff_on:
            self._work[K.P_HAS_FF], self._ff_on = 1.0, True
        step = self._step
        status = self._kernel(J, e, ff, q, self._work, step)
        self._count += 1
        # 3. only when needed: errors, the stability check, the escape's state, other limits
        if status & _PYTHON or self._always:
            step = self._slow(status, q, J, e, ff, targets)
        # 4. integrate on the manifold; the record of the step (StepInfo) is built on demand
        self._record, self._last = (J, e, step, status), None
        return pin.integrate(self._model, q, step)

    def _slow(self, status, q, J, e, ff, targets) -> np.ndarray:
        """What the fast path skips: errors, the stability check, the escape's state (its
        velocity for the next step), limits beyond the built-in ones."""
        if status & K.NON_FINITE:
            self._raise_non_finite(q, targets)
        if self._gain_check:
            self._check_gain(J)
        step, dt = self._step, self._dt
        escape = self.escape
        self._escaped = (self._count, escape is not None and escape.active)
        if escape is not None:
            if (status & K.STALLED and not escape.active
                    and escape.observe(self._count, self._info[K.I_E_SQ])):
                escape.test(q, self._weighted_rows(targets))
            velocity = escape.velocity(float(self._info[K.I_REGULAR]), dt)
            if velocity is None:
                self._work[K.P_ESCAPING] = 0.0
                self._escape_velocity[:] = 0.0
            else:  # the kernel adds it, within the limits, from the next step on
                self._work[K.P_ESCAPING] = 1.0
                self._escape_velocity[:] = velocity
        for limit in self._extra_limits:
            if limit.violated(q, step, dt):
                step = limit.enforce(q, step, dt, self._remap(q, J, e, ff))
        self._update_slow()
        return step

    def _remap(self, q, J, e, ff):
        """``remap(free, fixed_velocity)``: the method's step with only the ``free`` joints and
        the task velocity the others (moving at ``fixed_velocity``) leave to them."""

        def remap(free: np.ndarray, fixed_velocity: np.ndarray) -> np.ndarray:
            work, mask = self._work, self._mask
            saved = mask.copy()
            mask *= free
            work[K.P_HAS_FF] = 1.0
            out = np.empty_like(self._step)
            try:
                self._kernel(J, e, ff - J @ fixed_velocity, q, work, out)
            finally:
                mask[:] = saved
                work[K.P_HAS_FF] = 1.0 if self._ff_on else 0.0
            return out

        return remap

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
        return math.sqrt(self._info[K.I_E_SQ]) if self._record is not None else math.nan

    @property
    def error(self) -> np.ndarray:
        """The last step's task error e (the target rows), as a view that the next step
        overwrites (copy it to keep it; :attr:`last` holds copies)."""
        if self._record is None:
            return np.full(0, np.nan)
        return self._record[1] if self.stack.single else self.stack.error

    @property
    def displacement(self) -> np.ndarray:
        """The last step's joint displacement ``q_dot dt`` (nv,), as a view that the next step
        overwrites."""
        return self._step if self._record is None else self._record[2]

    @property
    def last(self) -> StepInfo | None:
        """The :class:`StepInfo` of the last step (``None`` before the first)."""
        if self._last is None and self._record is not None:
            info, stack = self._info, self.stack
            J, _, step, status = self._record
            gain = self._gain
            k = gain.value if gain.mode == K.GAIN_FIXED else float(info[K.I_GAIN])
            Jw = stack.sqrt_weight[:, None] * J * stack.chain
            alpha = self.method.scaling_factors(Jw)
            escaped = self._escaped[1] and self._escaped[0] == self._count
            clamped = (np.flatnonzero(self._clamped) if status & K.CLAMPED else _NONE_CLAMPED)
            scale = float(info[K.I_SCALE]) if status & K.SCALED else 1.0
            self._last = StepInfo(
                error=np.array(self.error, dtype=float), error_norm=math.sqrt(info[K.I_E_SQ]),
                dq=step / self._dt, gain=k, loop_bound=float(info[K.I_LOOP]),
                pose=stack.poses(), alpha=alpha, escaped=escaped,
                clamped=np.array(clamped), velocity_scale=float(scale),
                clamped_joints=tuple(self._v_names[i] for i in clamped))
        return self._last

    # -- safeguards ----------------------------------------------------------------------------
    def _check_gain(self, J: np.ndarray) -> None:
        """Warn once if ``k_max dt lambda_max(J M) >= 2`` at this configuration."""
        bound = self.method.bound(self.stack.n_chain)
        if bound is None:
            bound = float(self._info[K.I_TRACE])
        if self._k_dt * bound < 2.0:
            return
        Jw = self.stack.sqrt_weight[:, None] * J * self.stack.chain
        JM = Jw @ self.method.matrix(Jw)
        lam = float(np.linalg.eigvalsh(0.5 * (JM + JM.T))[-1]) if JM.size else 0.0
        if lam <= 0.0 or self._gain.largest * self._dt * lam < 2.0:
            return
        self._warned, self._gain_check = True, False
        warnings.warn(
            f"{self.method.name.upper()} gain {self._gain.largest:g} 1/s exceeds the stability "
            f"bound 2 / (dt lambda_max(J M)) = {2.0 / (self._dt * lam):.4g} 1/s at the current "
            f"configuration (dt = {self._dt:g} s); the closed loop will oscillate or diverge",
            GainWarning, stacklevel=4)

    def _raise_non_finite(self, q: np.ndarray, targets) -> None:
        self.robot.check_q(q)  # names q if it holds NaN or inf
        if not math.isfinite(self._info[K.I_E_SQ]):
            raise_non_finite_targets(targets)
        raise ValueError("target_velocity contains NaN or inf (the feed-forward is not finite)")

    # -- other entry points ----------------------------------------------------------------------
    def solve(self, target, q0, **options):
        """Solve to ``target`` from ``q0`` (set-point IK): Levenberg-Marquardt on this
        method's columns (SJT's normalised ones for SJT) within the limits, restarted from
        random configurations until it succeeds or its budget (iterations, 5 ms) runs out; see
        :func:`sjt_pin.solve.solve` for the options. Returns an :class:`~sjt_pin.IKResult`."""
        from .solve import solve

        return solve(self, target, q0, **options)

    def search(self):
        """The set-point IK state of this solver (:class:`~sjt_pin.solve.Search`, created on
        first use; its buffers are its own)."""
        if self._search is None:
            from .solve import Search

            self._search = Search(self)
        return self._search

    def __repr__(self) -> str:
        tasks = self.stack.tasks[0] if len(self.stack.tasks) == 1 else self.stack.tasks
        return (f"{type(self).__name__}({self.robot.name!r}, gain={self.gain!r}, "
                f"dt={self._dt:g}, task={tasks!r})")


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
