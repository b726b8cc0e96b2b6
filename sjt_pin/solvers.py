"""Closed-loop inverse kinematics (CLIK): the solver base class, one ``step()`` per period.

The four methods (:mod:`.methods`) differ only in their mapping M(J) (:mod:`.mappings`); every
solver implements the paper's CLIK law::

    q_dot = M(J(q)) (x_dot_d + K e),     e = task error at q        (eq. 5, 10, 21)
    q_next = integrate(q, q_dot dt)                                  (eq. 9, 11, 22)

``integrate`` is ``pinocchio.integrate``, so continuous joints and free flyers stay on their
manifold. ``K`` is ``gain``: a scalar, a diagonal (one entry per task row) or ``"auto"``.
Several frames can be driven at once (their task rows are stacked), an optional posture task
keeps redundant arms from drifting, and joint position and velocity limits are enforced.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
import pinocchio as pin

from . import mappings
from .exceptions import GainWarning
from .limits import JointLimits
from .robot import Robot
from .tasks import PoseTask, PostureTask, Task
from .validation import as_motion, positive

_LOCAL = pin.LOCAL


class StepInfo:
    """What one ``step()`` computed, at the configuration it was given.

    Attributes:
        error: task error vector e (stacked task rows; m and rad), before weights and gain.
        error_norm: Euclidean norm of ``error``.
        dq: joint velocity q_dot (nv,), in rad/s or m/s (after limits; before multiplying by dt).
        alpha: SJT scaling factors (nv,), zero for joints that do not move the tasks;
            ``None`` for the other methods (computed on first access).
        gain: the scalar or per-row gain K used in this step (1/s).
        pose: world pose of the task frame (``pin.SE3``); with several frames a dict
            ``{frame: pose}``.
        escaped: True when the step added a saddle escape (see ``_TransposeSolver``).
        clamped: tangent indices of the joints clamped out of the update at their limits.
        velocity_scale: factor (<= 1) applied to the joint velocity for the speed limits.
    """

    __slots__ = ("error", "error_norm", "dq", "_alpha", "gain", "pose", "escaped", "clamped",
                 "velocity_scale")

    def __init__(self, error, error_norm, dq, alpha, gain, pose, escaped=False,
                 clamped=(), velocity_scale=1.0):
        self.error = error
        self.error_norm = error_norm
        self.dq = dq
        self._alpha = alpha  # an array, None, or a function computing it
        self.gain = gain
        self.pose = pose
        self.escaped = escaped
        self.clamped = np.asarray(clamped, dtype=int)
        self.velocity_scale = velocity_scale

    @property
    def alpha(self) -> np.ndarray | None:
        if callable(self._alpha):
            self._alpha = self._alpha()
        return self._alpha

    def __repr__(self) -> str:
        return f"StepInfo(error_norm={self.error_norm:.3g}, |dq|={np.linalg.norm(self.dq):.3g})"


def _normalise_tasks(task) -> list[Task]:
    if task is None:
        return [PoseTask()]
    if isinstance(task, Task):
        return [task]
    if isinstance(task, Mapping):
        tasks = []
        for frame, t in task.items():
            if not isinstance(t, Task):
                raise TypeError(f"task[{frame!r}] must be a sjt_pin Task, got {type(t).__name__}")
            if t.frame not in (None, frame):
                raise ValueError(f"task[{frame!r}] is on frame {t.frame!r}")
            t.frame = frame
            tasks.append(t)
        return tasks
    if isinstance(task, Sequence) and task and all(isinstance(t, Task) for t in task):
        return list(task)
    raise TypeError("task must be a sjt_pin Task, a list of tasks or a {frame: task} mapping")


class DifferentialIKSolver:
    """Base class of the four CLIK solvers; subclasses supply the mapping M(J).

    Args:
        robot: the :class:`~sjt_pin.robot.Robot` to move.
        gain: K in 1/s. A float (K = k I), a sequence (diagonal of K, one per task row) or
            ``"auto"``: for SJT ``1 / (n dt)`` with n the joints that move the tasks, half the
            configuration-independent bound ``2 / (n dt)``; for the others
            ``1 / (dt lambda_max(J M))`` at the current q.
        dt: control period in s (the integration step).
        task: a :class:`~sjt_pin.tasks.Task` (default: :class:`~sjt_pin.tasks.PoseTask` on the
            end effector), a list of tasks on distinct frames, or a ``{frame: task}`` mapping.
            With several tasks, ``step`` takes ``{frame: target}`` mappings.
        posture: an optional :class:`~sjt_pin.tasks.PostureTask` stacked under the tasks; its
            rows take the scalar gain (the mean gain when the gain is given per row).
        position_limits: keep joints within their URDF position limits (default: when the URDF
            has them); see :mod:`.limits`.
        velocity_limits: ``True`` (URDF limits), ``False``, or an (nv,) array in rad/s or m/s;
            default: the URDF's when it has any.
        check_stability: warn (:class:`~sjt_pin.exceptions.GainWarning`, once per solver) when a
            fixed gain exceeds the linear stability bound ``2 / (dt lambda_max(J M))`` at the
            current configuration.

    ``step()`` never mutates its arguments. ``last`` is the :class:`StepInfo` of the last step.
    """

    method: ClassVar[str] = ""
    #: Jacobian-transpose-type updates stall at saddles of exactly singular configurations.
    escapes_saddles: ClassVar[bool] = False

    def __init__(
        self,
        robot: Robot,
        gain: float | str | Sequence[float] = "auto",
        dt: float = 1e-3,
        task: Task | Sequence[Task] | Mapping[str, Task] | None = None,
        *,
        posture: PostureTask | None = None,
        position_limits: bool | None = None,
        velocity_limits=None,
        check_stability: bool = True,
    ):
        if not isinstance(robot, Robot):
            raise TypeError(f"robot must be a sjt_pin.Robot, got {type(robot).__name__}")
        self.robot = robot
        self._model = robot.model
        self._data = robot.model.createData()  # the solver's own scratch space
        self.dt = positive(dt, "dt", "s")
        self.tasks = _normalise_tasks(task)
        self.frame_ids = [robot.ee_frame_id if t.frame is None else robot.frame_id(t.frame)
                          for t in self.tasks]
        self.frames = [robot.model.frames[f].name for f in self.frame_ids]
        if len(set(self.frames)) != len(self.frames):
            raise ValueError(f"each frame takes one task, got frames {self.frames}")
        self.task, self.frame_id = self.tasks[0], self.frame_ids[0]
        self._single = len(self.tasks) == 1
        self.task_dim = sum(t.dim for t in self.tasks)
        if posture is not None and not isinstance(posture, PostureTask):
            raise TypeError(f"posture must be a PostureTask, got {type(posture).__name__}")
        self.posture = posture
        if posture is not None:
            q_ref = robot.q0 if posture.q_ref is None else robot.check_q(posture.q_ref, "q_ref")
            self._q_ref = q_ref.copy()
            self._posture_rows = np.sqrt(np.broadcast_to(posture.weight, (robot.nv,)))
        # joints that can move at least one task frame (the others never enter the update)
        chain = np.zeros(robot.nv)
        for fid in self.frame_ids:
            for j in robot.model.supports[robot.model.frames[fid].parentJoint][1:]:
                joint = robot.model.joints[j]
                chain[joint.idx_v:joint.idx_v + joint.nv] = 1.0
        self._chain = chain if posture is None else np.ones(robot.nv)
        self.n_chain = int(self._chain.sum())
        self.limits = JointLimits(robot, position_limits, velocity_limits)
        self.limits.only_moving(self._chain)
        self._gain_warned = False
        self._check_stability = bool(check_stability)
        self.gain = gain
        self._countdown = 0
        self._last: StepInfo | None = None
        self._state: tuple | None = None
        self._q_shape = (robot.nq,)

    # -- gain ---------------------------------------------------------------------------------
    @property
    def gain(self) -> float | np.ndarray | str:
        """K (1/s): a float, the diagonal of K (one per task row), or ``"auto"``."""
        return "auto" if self._auto else self._gain

    @gain.setter
    def gain(self, gain) -> None:
        if isinstance(gain, str):
            if gain != "auto":
                raise ValueError(f"gain must be a number, a sequence or 'auto', got {gain!r}")
            self._auto, self._gain, self._gain_max = True, None, None
        elif np.ndim(gain) == 0:
            value = float(gain)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"gain must be a finite number >= 0 (1/s), got {gain!r}")
            self._auto, self._gain, self._gain_max = False, value, value
        else:
            arr = np.asarray(gain, dtype=float)
            if arr.shape != (self.task_dim,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(
                    f"gain as a sequence must have shape ({self.task_dim},) (one per task row) "
                    f"with finite entries >= 0, got {gain!r}"
                )
            self._auto, self._gain, self._gain_max = False, arr.copy(), float(arr.max())
        self._gain_changed()

    @property
    def check_stability(self) -> bool:
        """Warn once when a fixed gain exceeds the stability bound (see the class docstring)."""
        return self._check_stability

    @check_stability.setter
    def check_stability(self, value: bool) -> None:
        self._check_stability = bool(value)
        self._gain_changed()

    def _gain_changed(self) -> None:
        """Recompute what depends on the gain; subclasses extend it."""
        self._gain_check = self._check_stability and not self._auto and not self._gain_warned

    # -- the mapping (subclasses) --------------------------------------------------------------
    def _apply(self, J: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``M(J) v``."""
        raise NotImplementedError

    def matrix(self, J: np.ndarray) -> np.ndarray:
        """The mapping M(J) as an (n, m) matrix (for analysis, not used by ``step``)."""
        raise NotImplementedError

    def scaling_factors(self, J: np.ndarray) -> np.ndarray | None:
        """SJT's alpha_i for the (weighted, stacked) rows ``J``; ``None`` for other methods."""
        return None

    def _loop_eigenvalue_bound(self, J: np.ndarray) -> float:
        """A cheap upper bound of lambda_max(J M(J)); exact where that is cheap."""
        return 1.0  # J J^+ is a projector, J J^T (J J^T + l^2 I)^-1 has eigenvalues below 1

    def _auto_gain(self, J: np.ndarray) -> float:
        return 1.0 / (self.dt * max(mappings.max_loop_eigenvalue(J, self.matrix(J)), 1e-12))

    # -- one control period ----------------------------------------------------------------------
    def step(self, q, target, target_velocity=None) -> np.ndarray:
        """One CLIK step: the configuration after ``dt`` (a new array; ``q`` is not modified).

        Args:
            q: current configuration (nq,).
            target: desired pose x_d(t): ``pin.SE3`` or 4x4 matrix (position tasks also take a
                3-vector in m); with several tasks a ``{frame: target}`` mapping.
            target_velocity: desired velocity x_dot_d(t) as ``pin.Motion`` or 6-vector
                [linear (m/s), angular (rad/s)], world axes at the desired origin (``None``: 0);
                with several tasks a ``{frame: velocity}`` mapping (missing frames: 0).
        """
        if not (isinstance(q, np.ndarray) and q.shape == self._q_shape and q.dtype == float):
            q = self.robot.check_q(q)
        if self._single:
            oMd = self.task.target_pose(target)
            velocity = None if target_velocity is None else as_motion(target_velocity)
        else:
            oMd, velocity = self._targets(target, target_velocity)
        return self._step(q, oMd, velocity)

    def _targets(self, target, target_velocity) -> tuple[list, list | None]:
        if not isinstance(target, Mapping):
            raise ValueError(f"target must be a {{frame: target}} mapping for frames {self.frames}")
        unknown = set(target) - set(self.frames)
        missing = set(self.frames) - set(target)
        if unknown or missing:
            raise ValueError(f"target must have exactly the frames {self.frames}; "
                             f"missing {sorted(missing)}, unknown {sorted(unknown)}")
        poses = [t.target_pose(target[f]) for t, f in zip(self.tasks, self.frames, strict=True)]
        if target_velocity is None:
            return poses, None
        if not isinstance(target_velocity, Mapping) or set(target_velocity) - set(self.frames):
            raise ValueError(f"target_velocity must be a {{frame: velocity}} mapping over "
                             f"{self.frames}")
        velocities = [None if f not in target_velocity else
                      as_motion(target_velocity[f], f"target_velocity[{f!r}]") for f in self.frames]
        return poses, velocities

    def _kinematics(self, q, oMd, velocity):
        """Stacked task rows J (weighted), error e (unweighted), weighted e, feed-forward, poses."""
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, q)
        if self._single:
            task, fid = self.task, self.frame_id
            oMf = pin.updateFramePlacement(model, data, fid)
            J = task.jacobian(oMf, pin.getFrameJacobian(model, data, fid, _LOCAL))
            e = task.error(oMf, oMd)
            ff = None if velocity is None else task.feedforward(oMf, oMd, velocity)
            sw = task.sqrt_weight
            if sw is not None:
                J, e_w = sw[:, None] * J, sw * e
                ff = None if ff is None else sw * ff
            else:
                e_w = e
            pose = oMf
        else:
            blocks, errors, weighted, ffs, pose = [], [], [], [], {}
            for k, (task, fid) in enumerate(zip(self.tasks, self.frame_ids, strict=True)):
                oMf = pin.updateFramePlacement(model, data, fid)
                rows = task.jacobian(oMf, pin.getFrameJacobian(model, data, fid, _LOCAL))
                err = task.error(oMf, oMd[k])
                vel = None if velocity is None else velocity[k]
                f = np.zeros(task.dim) if vel is None else task.feedforward(oMf, oMd[k], vel)
                sw = 1.0 if task.sqrt_weight is None else task.sqrt_weight
                blocks.append(rows * (sw if np.ndim(sw) == 0 else sw[:, None]))
                errors.append(err)
                weighted.append(sw * err)
                ffs.append(sw * f)
                pose[self.frames[k]] = oMf
            J, e, e_w = np.vstack(blocks), np.concatenate(errors), np.concatenate(weighted)
            ff = None if velocity is None else np.concatenate(ffs)
        return J, e, e_w, ff, pose

    def _step(self, q: np.ndarray, oMd, velocity) -> np.ndarray:
        """One step on validated arguments (``track`` and ``step`` call this)."""
        J, e, e_w, ff, pose = self._kinematics(q, oMd, velocity)
        ee = e.dot(e)
        if not math.isfinite(ee):
            self._raise_non_finite(q)
        gain = self._auto_gain(J) if self._auto else self._gain
        v = gain * e_w
        if ff is not None:
            v += ff
        if self.posture is not None:
            k_p = gain if np.ndim(gain) == 0 else float(np.mean(gain))
            J = np.vstack([J, np.diag(self._posture_rows)])
            v = np.concatenate([v, k_p * self._posture_rows
                                * pin.difference(self._model, q, self._q_ref)])
        return self._finish(q, oMd, J, e, ee, v, self._apply(J, v) * self.dt, gain, pose)

    def _finish(self, q, oMd, J, e, ee, v, step, gain, pose, speed_safe=False) -> np.ndarray:
        """Stability check, saddle escape, limits, integration and the record of the step.

        ``step`` is q_dot dt (the vector integrated); ``v`` the task velocity it maps, or
        ``None`` for ``gain * e`` (computed only if a safeguard needs it); ``speed_safe`` says
        the caller has proved every joint below its speed limit.
        """
        if self._gain_check:
            self._check_gain(J)
        escaped = False
        if self.escapes_saddles:
            if self._countdown > 0:
                self._countdown -= 1
            else:
                escaped = self._escape_saddle(q, oMd, J, e, v, step, gain)
                speed_safe = speed_safe and not escaped
        limits, clamped, scale, dt = self.limits, (), 1.0, self.dt
        q_next = pin.integrate(self._model, q, step)
        if limits.active and limits.violated(q_next, step, dt, not speed_safe):
            if limits.position and limits.outside(q_next):
                v = gain * e if v is None else v
                dq, clamped = limits.clamp(q, step / dt, dt, J, v, self._apply)
                step = dq * dt
            if limits.velocity:
                scale = limits.scale_step(step, dt)
            q_next = pin.integrate(self._model, q, step)
            if limits.position:
                limits.clip(q_next)
        self._state = (J, e, ee, step, gain, pose, escaped, clamped, scale)
        self._last = None
        return q_next

    def solve(self, target, q0, tol: float = 1e-6, max_iters: int = 500, restarts: int = 0,
              rng: np.random.Generator | None = None, inner: int | None = None,
              timeout: float | None = None):
        """Solve to ``target`` from ``q0`` with an adaptive step along this solver's direction.

        Returns an :class:`~sjt_pin.solve.IKResult` (q, success, iterations, error); see
        :func:`sjt_pin.solve.solve`. Solutions respect the position limits the solver enforces.
        """
        from .solve import solve

        return solve(self, target, q0, tol=tol, max_iters=max_iters, restarts=restarts, rng=rng,
                     inner=inner, timeout=timeout)

    @property
    def last(self) -> StepInfo | None:
        """The :class:`StepInfo` of the last step (``None`` before the first)."""
        if self._last is None and self._state is not None:
            J, e, ee, step, gain, pose, escaped, clamped, scale = self._state
            alpha = functools.partial(self.scaling_factors, J)  # tracking logs never read it
            self._last = StepInfo(e, math.sqrt(ee), step / self.dt, alpha, gain,
                                  pose, escaped, clamped, scale)
        return self._last

    def _raise_non_finite(self, q: np.ndarray) -> None:
        self.robot.check_q(q)  # names q if q holds NaN or inf
        raise ValueError("target contains NaN or inf (the task error is not finite)")

    # -- safeguards ------------------------------------------------------------------------------
    def _check_gain(self, J: np.ndarray) -> None:
        """Warn once if ``k_max dt lambda_max(J M) >= 2`` at this configuration."""
        k_dt = self._gain_max * self.dt
        if k_dt * self._loop_eigenvalue_bound(J) < 2.0:
            return
        bound = mappings.stable_gain_bound(J, self.matrix(J), self.dt)
        if self._gain_max >= bound:
            self._gain_warned, self._gain_check = True, False
            warnings.warn(
                f"{self.method.upper()} gain {self._gain_max:g} 1/s exceeds the stability bound "
                f"2 / (dt lambda_max(J M)) = {bound:.4g} 1/s at the current configuration "
                f"(dt = {self.dt:g} s); the closed loop will oscillate or diverge",
                GainWarning,
                stacklevel=4,
            )

    def _escape_saddle(self, q, oMd, J, e, v, step, gain) -> bool:
        return False

    def __repr__(self) -> str:
        tasks = self.task if self._single else self.tasks
        return (f"{type(self).__name__}({self.robot.name!r}, gain={self.gain!r}, dt={self.dt:g}, "
                f"task={tasks!r})")
