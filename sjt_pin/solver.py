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
from .validation import positive

_F64 = np.dtype(np.float64)


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
        self._work = np.zeros(K.work_size(stack.dim, n))
        self._info = self._work[K.INFO:K.INFO + K.INFO_SIZE]
        self._step = np.zeros(n)
        self._rows = np.zeros((2, stack.dim))
        self._rows[0] = stack.sqrt_weight
        self._mask = stack.chain.copy()
        self._no_ff = np.zeros(stack.dim)
        self._ff_on = False
        self._kernel = method.kernel
        self._dt = positive(dt, "dt", "s")
        # limits, the escape and the names of the velocity indices
        urdf_speeds = robot.velocity_limits
        speeds = _speed_limits(velocity_limits, urdf_speeds, n)
        moving = stack.chain > 0
        position = PositionLimit(robot, moving, np.where(np.isfinite(urdf_speeds), urdf_speeds,
                                                         SaddleEscape.DEFAULT_SPEED))
        use_position = position.active if position_limits is None else (
            bool(position_limits) and position.active)
        self.position_limit = position if use_position else None
        velocity = VelocityLimit(np.where(moving, speeds, np.inf))
        self.velocity_limit = velocity if velocity.active else None
        self.limits: list[Limit] = [x for x in (self.position_limit, self.velocity_limit)
                                    if x is not None]
        for extra in limits:
            if not isinstance(extra, Limit):
                raise TypeError(f"limits must hold sjt_pin Limit objects, got {extra!r}")
            self.limits.append(extra)
        self.escape = (SaddleEscape(robot.model, stack.chain, urdf_speeds, self.position_limit)
                       if escape and method.stalls else None)
        self._v_names = robot.velocity_names
        self._check_stability = bool(check_stability)
        self._warned = False
        self._probe: TaskStack | None = None
        self._gain = as_gain(gain, stack.target_dim)
        self._configure()
        self._last: StepInfo | None = None
        self._stepped = False
        self._e = self._dq_step = np.full(0, np.nan)

    # -- settings ----------------------------------------------------------------------------
    @property
    def gain(self) -> float | np.ndarray | str | Gain:
        """K (1/s): a number, one per task row, ``"auto"`` or a Gain object."""
        value = self._gain
        if hasattr(value, "value"):
            return value.value
        text = repr(value)
        return text.strip("'") if text.startswith("'") else value

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
        stack, gain = self.stack, self._gain
        self.method.configure(self._work, gain, self._dt, stack.n_chain)
        self._work[K.P_ERROR_ROWS] = stack.target_dim
        self._ff_mode = self.method.feedforward_mode()
        self._work[K.P_FF_MODE] = self._ff_mode if self._ff_on else K.FF_NONE
        self._rows[1] = gain.rows(stack.target_dim, stack.posture_dim)
        self._k_dt = gain.largest * self._dt
        bound = self.method.bound(stack.n_chain)
        # the check can only fire when k dt times a bound of lambda_max reaches 2
        self._gain_check = (self._check_stability and not self._warned
                            and gain.mode == K.GAIN_FIXED
                            and (bound is None or self._k_dt * bound >= 2.0))

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
        stack = self.stack
        if stack.single:
            task = stack.task
            target = task.target(target)
            velocity = None if target_velocity is None else task.velocity(target_velocity)
            stack.kinematics.update(q)
            J, e, ff = task.compute(stack.kinematics, target, velocity)
            targets = (target,)
        else:
            targets, velocities = stack.targets(target, target_velocity)
            J, e, ff = stack.evaluate(q, targets, velocities)
        return self._advance(q, J, e, ff, targets)

    def _advance(self, q, J, e, ff, targets) -> np.ndarray:
        work, step, info = self._work, self._step, self._info
        if ff is None:
            if self._ff_on:
                work[K.P_FF_MODE], self._ff_on = K.FF_NONE, False
            ff = self._no_ff
        elif not self._ff_on:
            work[K.P_FF_MODE], self._ff_on = self._ff_mode, True
        self._kernel(J, e, ff, self._rows, self._mask, work, step)
        if not math.isfinite(info[K.I_E_SQ] + info[K.I_FF_SQ]):
            self._raise_non_finite(q, targets)
        if self._gain_check:
            self._check_gain(J)
        escaped = False
        escape = self.escape
        if escape is not None and (escape.active or escape.observe(info[K.I_STALL],
                                                                   info[K.I_E_SQ])):
            escaped = self._escape(q, J, step, targets)
        dt = self._dt
        enforced = False
        for limit in self.limits:
            if limit.violated(q, step, dt):
                if not enforced:
                    enforced = True
                    for other in self.limits:
                        other.reset()
                step = limit.enforce(q, step, dt, self._remap(J, e, ff))
        q_next = pin.integrate(self._model, q, step)
        if enforced and self.position_limit is not None:
            self.position_limit.clip(q, q_next)
        self._J, self._dq_step = J, step
        self._e = e if self.stack.single else self.stack.error
        self._escaped, self._enforced = escaped, enforced
        self._stepped, self._last = True, None
        return q_next

    def _remap(self, J, e, ff):
        """The method's step with only ``free`` joints and their share of the task velocity."""

        def remap(free: np.ndarray, fixed_velocity: np.ndarray) -> np.ndarray:
            mask = self._mask * free
            extra = ff - J @ fixed_velocity
            work = self._work
            work[K.P_FF_MODE] = self._ff_mode
            out = np.empty_like(self._step)
            self._kernel(J, e, extra, self._rows, mask, work, out)
            work[K.P_FF_MODE] = self._ff_mode if self._ff_on else K.FF_NONE
            return out

        return remap

    def _escape(self, q, J, step, targets) -> bool:
        escape = self.escape
        if not escape.active and not escape.test(q, self._weighted_rows(targets)):
            return False
        velocity = escape.velocity(float(np.linalg.norm(step)) / self._dt, self._dt)
        if velocity is None:
            return False
        step += velocity * self._dt
        return True

    def _weighted_rows(self, targets):
        """``q -> (J_w, e_w)``: the weighted, masked task rows for ``targets``, evaluated on a
        stack of their own (the step's buffers stay as they are)."""
        probe = self._probe_stack()
        sw, mask = self._rows[0], self._mask
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
        return math.sqrt(self._info[K.I_E_SQ]) if self._stepped else math.nan

    @property
    def error(self) -> np.ndarray:
        """The last step's task error e (m,), as a view that the next step overwrites (copy it
        to keep it; :attr:`last` holds copies)."""
        return self._e

    @property
    def displacement(self) -> np.ndarray:
        """The last step's joint displacement ``q_dot dt`` (nv,), as a view that the next step
        overwrites."""
        return self._dq_step

    @property
    def last(self) -> StepInfo | None:
        """The :class:`StepInfo` of the last step (``None`` before the first)."""
        if self._last is None and self._stepped:
            info, stack = self._info, self.stack
            J = self._J
            gain = self._gain
            k = gain.value if gain.mode == K.GAIN_FIXED else float(info[K.I_GAIN])
            Jw = self._rows[0][:, None] * J * self._mask
            alpha = self.method.scaling_factors(Jw)
            clamped = (self.position_limit.clamped if self._enforced and self.position_limit
                       else np.zeros(0, dtype=np.int64))
            scale = (self.velocity_limit.scale if self._enforced and self.velocity_limit
                     else 1.0)
            self._last = StepInfo(
                error=np.array(self._e, dtype=float), error_norm=math.sqrt(info[K.I_E_SQ]),
                dq=self._dq_step / self._dt, gain=k, loop_bound=float(info[K.I_LOOP]),
                pose=stack.poses(), alpha=alpha, escaped=self._escaped,
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
        Jw = self._rows[0][:, None] * J * self._mask
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
        info = self._info
        if not math.isfinite(info[K.I_E_SQ]):
            for target in targets:
                if target is None:
                    continue
                values = target.np if isinstance(target, pin.SE3) else np.asarray(target)
                if not np.all(np.isfinite(values)):
                    raise ValueError("target contains NaN or inf")
            raise ValueError("target is too far for a finite task error (a translation above "
                             "about 1e150 m overflows): check its units")
        raise ValueError("target_velocity contains NaN or inf (the feed-forward is not finite)")

    # -- other entry points ----------------------------------------------------------------------
    def solve(self, target, q0, **options):
        """Solve to ``target`` from ``q0``: set-point IK along this solver's direction, with
        random restarts within the limits; see :func:`sjt_pin.solve.solve` for the options.
        Returns an :class:`~sjt_pin.solve.IKResult`."""
        from .solve import solve

        return solve(self, target, q0, **options)

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
