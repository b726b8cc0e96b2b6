"""Closed-loop inverse kinematics (CLIK) solvers: one ``step()`` per control period.

Every solver implements the paper's CLIK law with its own mapping M(J) (see :mod:`.mappings`)::

    q_dot = M(J(q)) (x_dot_d + K e),     e = task error at q        (eq. 5, 10, 21)
    q_next = integrate(q, q_dot dt)                                  (eq. 9, 11, 22)

``integrate`` is ``pinocchio.integrate``, so continuous joints and free flyers stay on their
manifold. ``K`` is ``gain``: a scalar, a diagonal (one entry per task row) or ``"auto"``.
"""

from __future__ import annotations

import warnings
from typing import ClassVar

import numpy as np
import pinocchio as pin

from . import mappings
from .exceptions import GainWarning
from .robot import Robot
from .tasks import PoseTask, Task
from .validation import as_motion, positive


class StepInfo:
    """What one ``step()`` computed, at the configuration it was given.

    Attributes:
        error: task error vector e (task rows; m and rad), before weights and gain.
        error_norm: Euclidean norm of ``error``.
        dq: joint velocity q_dot (nv,), in rad/s or m/s (before multiplying by dt).
        alpha: SJT scaling factors (nv,), zero for joints that do not move the task;
            ``None`` for the other methods.
        gain: the scalar or per-row gain K used in this step (1/s).
        pose: world pose of the task frame at the given configuration (``pin.SE3``).
        escaped: True when the step added a saddle escape (see ``DifferentialIKSolver``).
    """

    __slots__ = ("error", "error_norm", "dq", "alpha", "gain", "pose", "escaped")

    def __init__(self, error, error_norm, dq, alpha, gain, pose, escaped=False):
        self.error = error
        self.error_norm = error_norm
        self.dq = dq
        self.alpha = alpha
        self.gain = gain
        self.pose = pose
        self.escaped = escaped

    def __repr__(self) -> str:
        return f"StepInfo(error_norm={self.error_norm:.3g}, |dq|={np.linalg.norm(self.dq):.3g})"


class DifferentialIKSolver:
    """Base class of the four CLIK solvers; subclasses supply the mapping M(J).

    Args:
        robot: the :class:`~sjt_pin.robot.Robot` to move.
        gain: K in 1/s. A float (K = k I), a sequence (diagonal of K, one per task row) or
            ``"auto"``: for SJT ``1 / (n_active dt)``, half the configuration-independent bound
            ``2 / (n_active dt)``; for the others ``1 / (dt lambda_max(J M))`` at the current q.
        dt: control period in s (the integration step).
        task: the task (default :class:`~sjt_pin.tasks.PoseTask` on the end effector).
        check_stability: warn (:class:`~sjt_pin.exceptions.GainWarning`, once per solver) when a
            fixed gain exceeds the linear stability bound ``2 / (dt lambda_max(J M))`` at the
            current configuration.

    ``step()`` never mutates its arguments. ``last`` holds the :class:`StepInfo` of the last step.
    """

    method: ClassVar[str] = ""
    #: Jacobian-transpose-type updates stall at saddles of exactly singular configurations.
    escapes_saddles: ClassVar[bool] = False

    def __init__(
        self,
        robot: Robot,
        gain: float | str | np.ndarray = "auto",
        dt: float = 1e-3,
        task: Task | None = None,
        *,
        check_stability: bool = True,
    ):
        if not isinstance(robot, Robot):
            raise TypeError(f"robot must be a sjt_pin.Robot, got {type(robot).__name__}")
        self.robot = robot
        self.dt = positive(dt, "dt", "s")
        self.task = PoseTask() if task is None else task
        if not isinstance(self.task, Task):
            raise TypeError(f"task must be a sjt_pin Task, got {type(self.task).__name__}")
        self.frame_id = robot.ee_frame_id if self.task.frame is None else robot.frame_id(
            self.task.frame)
        self.gain = gain
        self.check_stability = check_stability
        self.last: StepInfo | None = None
        self._model = robot.model
        self._data = robot.model.createData()  # the solver's own scratch space
        self._gain_warned = False

    # -- gain ---------------------------------------------------------------------------------
    @property
    def gain(self) -> float | np.ndarray | str:
        """K (1/s): a float, the diagonal of K, or ``"auto"``."""
        return "auto" if self._auto else self._gain

    @gain.setter
    def gain(self, gain) -> None:
        self._auto = isinstance(gain, str)
        if self._auto:
            if gain != "auto":
                raise ValueError(f"gain must be a number, a sequence or 'auto', got {gain!r}")
            self._gain = None
            return
        arr = np.asarray(gain, dtype=float) if not isinstance(gain, (int, float)) else None
        if arr is None or arr.ndim == 0:
            value = float(gain)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"gain must be a finite number >= 0 (1/s), got {gain!r}")
            self._gain, self._gain_max = value, value
            return
        if arr.shape != (self.task.dim,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(
                f"gain as a sequence must have shape ({self.task.dim},) (one per task row) with "
                f"finite entries >= 0, got {gain!r}"
            )
        self._gain, self._gain_max = arr.copy(), float(arr.max())

    # -- the mapping (subclasses) --------------------------------------------------------------
    def _scaling(self, J: np.ndarray) -> np.ndarray | None:
        """SJT's scaling factors alpha (nv,); ``None`` for the other methods."""
        return None

    def _apply(self, J: np.ndarray, v: np.ndarray, alpha) -> np.ndarray:
        """``M(J) v``."""
        raise NotImplementedError

    def matrix(self, J: np.ndarray) -> np.ndarray:
        """The mapping M(J) as an (n, m) matrix (for analysis, not used by ``step``)."""
        raise NotImplementedError

    def _loop_eigenvalue_bound(self, J: np.ndarray, alpha) -> float:
        """A cheap upper bound of lambda_max(J M(J)); exact where that is cheap."""
        return 1.0  # J J^+ is a projector, J J^T (J J^T + l^2 I)^-1 has eigenvalues below 1

    def _auto_gain(self, J: np.ndarray, alpha) -> float:
        return 1.0 / (self.dt * max(mappings.max_loop_eigenvalue(J, self.matrix(J)), 1e-12))

    # -- one control period ----------------------------------------------------------------------
    def step(self, q, target, target_velocity=None) -> np.ndarray:
        """One CLIK step: the configuration after ``dt`` (a new array; ``q`` is not modified).

        Args:
            q: current configuration (nq,).
            target: desired pose x_d(t): ``pin.SE3`` or 4x4 matrix (position tasks also take a
                3-vector in m).
            target_velocity: desired velocity x_dot_d(t) as ``pin.Motion`` or 6-vector
                [linear (m/s), angular (rad/s)], world axes at the desired origin; ``None`` = 0.
        """
        q = self.robot.check_q(q)
        oMd = self.task.target_pose(target)
        velocity = None if target_velocity is None else as_motion(target_velocity)
        return self._step(q, oMd, velocity)

    def _step(self, q: np.ndarray, oMd: pin.SE3, velocity: pin.Motion | None) -> np.ndarray:
        model, data, task, fid = self._model, self._data, self.task, self.frame_id
        pin.computeJointJacobians(model, data, q)
        oMf = pin.updateFramePlacement(model, data, fid)
        J = task.jacobian(oMf, pin.getFrameJacobian(model, data, fid, pin.LOCAL))
        e = task.error(oMf, oMd)
        if task.sqrt_weight is not None:
            J = task.sqrt_weight[:, None] * J
            e_w = task.sqrt_weight * e
        else:
            e_w = e
        alpha = self._scaling(J)
        gain = self._auto_gain(J, alpha) if self._auto else self._gain
        v = gain * e_w
        if velocity is not None:
            ff = task.feedforward(oMf, oMd, velocity)
            v += ff if task.sqrt_weight is None else task.sqrt_weight * ff
        dq = self._apply(J, v, alpha)
        if self.check_stability and not self._auto and not self._gain_warned:
            self._check_gain(J, alpha)
        escaped = False
        if self.escapes_saddles:
            escaped = self._escape_saddle(q, oMd, J, e, v, dq)
        self.last = StepInfo(e, float(np.sqrt(e @ e)), dq, alpha, gain, oMf, escaped)
        return pin.integrate(model, q, dq * self.dt)

    # -- safeguards ------------------------------------------------------------------------------
    def _check_gain(self, J: np.ndarray, alpha) -> None:
        """Warn once if ``k_max dt lambda_max(J M) >= 2`` at this configuration."""
        k_dt = self._gain_max * self.dt
        if k_dt * self._loop_eigenvalue_bound(J, alpha) < 2.0:
            return
        bound = mappings.stable_gain_bound(J, self.matrix(J), self.dt)
        if self._gain_max >= bound:
            self._gain_warned = True
            warnings.warn(
                f"{self.method.upper()} gain {self._gain_max:g} 1/s exceeds the stability bound "
                f"2 / (dt lambda_max(J M)) = {bound:.4g} 1/s at the current configuration "
                f"(dt = {self.dt:g} s); the closed loop will oscillate or diverge",
                GainWarning,
                stacklevel=3,
            )

    def _escape_saddle(self, q, oMd, J, e, v, dq) -> bool:
        return False

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.robot.name!r}, gain={self.gain!r}, dt={self.dt:g}, "
                f"task={self.task!r})")


class JPSolver(DifferentialIKSolver):
    """Jacobian pseudoinverse CLIK, eq. (8)-(9): exact tracking, blows up near singularities.

    ``rcond``: singular values below ``rcond * sigma_max`` are treated as zero.
    """

    method = "jp"

    def __init__(self, robot: Robot, gain="auto", dt: float = 1e-3, task: Task | None = None, *,
                 rcond: float = mappings.JP_RCOND, check_stability: bool = True):
        self.rcond = positive(rcond, "rcond")
        super().__init__(robot, gain, dt, task, check_stability=check_stability)

    def _apply(self, J, v, alpha):
        return mappings.jp_apply(J, v, self.rcond)

    def matrix(self, J):
        return mappings.jp_matrix(J, self.rcond)


class DLSSolver(DifferentialIKSolver):
    """Damped least-squares CLIK: ``M = J^T (J J^T + damping^2 I)^-1``.

    ``damping`` (lambda) is in task units (m for position rows, rad for orientation rows):
    larger is more robust near singularities and less accurate.
    """

    method = "dls"

    def __init__(self, robot: Robot, gain="auto", dt: float = 1e-3, task: Task | None = None, *,
                 damping: float = 0.05, check_stability: bool = True):
        self.damping = positive(damping, "damping", "task units (m, rad)")
        super().__init__(robot, gain, dt, task, check_stability=check_stability)

    def _apply(self, J, v, alpha):
        return mappings.dls_apply(J, v, self.damping)

    def matrix(self, J):
        return mappings.dls_matrix(J, self.damping)


class _TransposeSolver(DifferentialIKSolver):
    """Shared by JT and SJT: gradient-type updates, which can stall at singular saddles.

    At an exactly singular configuration an error along the lost task direction gives
    ``J^T e = 0`` although ``e != 0``: a saddle of ``1/2 e^T K e`` that round-off alone takes
    thousands of steps to leave (UR5 at q = 0 asked to roll its tool about the lost axis never
    moves). The step detects it, when the loop gain along the command falls below
    ``saddle_ratio`` (``v^T J M v < saddle_ratio v^T v``) while the error is above
    ``saddle_error``, and escapes as perturbed gradient descent does: it tries joint moves of
    ``escape_step`` rad along +-the null direction of J and along ``escape_candidates`` random
    directions (seeded, so runs repeat), takes the one that leaves the smallest error, and then
    lets the regular update work for ``escape_cooldown`` steps before it may escape again.
    """

    escapes_saddles = True
    saddle_ratio = 1e-6
    saddle_error = 1e-6
    escape_step = 0.05  # rad
    escape_candidates = 8
    escape_cooldown = 20

    def __init__(self, *args, seed: int = 0, **kwargs):
        super().__init__(*args, **kwargs)
        self._rng = np.random.default_rng(seed)
        self._cooldown = 0

    def _escape_saddle(self, q, oMd, J, e, v, dq) -> bool:
        if self._cooldown > 0:
            self._cooldown -= 1
            return False
        vv = v @ v
        if vv == 0.0 or e @ e < self.saddle_error**2 or (v @ J) @ dq >= self.saddle_ratio * vv:
            return False
        _, s, Vt = np.linalg.svd(J, full_matrices=False)
        random = self._rng.standard_normal((self.escape_candidates, J.shape[1]))
        directions = np.vstack([Vt[s.size - 1], -Vt[s.size - 1], random])
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        norms = [self._error_norm_at(pin.integrate(self._model, q, self.escape_step * d), oMd)
                 for d in directions]
        self._cooldown = self.escape_cooldown
        dq += (self.escape_step / self.dt) * directions[int(np.argmin(norms))]
        return True

    def _error_norm_at(self, q: np.ndarray, oMd: pin.SE3) -> float:
        pin.forwardKinematics(self._model, self._data, q)
        oMf = pin.updateFramePlacement(self._model, self._data, self.frame_id)
        return float(np.linalg.norm(self.task.error(oMf, oMd)))


class JTSolver(_TransposeSolver):
    """Jacobian transpose CLIK, eq. (10)-(11): no singularities, gain limited by sigma_max(J)^2."""

    method = "jt"

    def _apply(self, J, v, alpha):
        return mappings.jt_apply(J, v)

    def matrix(self, J):
        return mappings.jt_matrix(J)

    def _loop_eigenvalue_bound(self, J, alpha):
        return float(np.einsum("ij,ij->", J, J))  # trace(J J^T) >= lambda_max


class SJTSolver(_TransposeSolver):
    """Scaled Jacobian transpose CLIK, eq. (21)-(22): ``M = D J^T``, ``D = diag(alpha_i)``.

    ``alpha_i = 1 / (J_i^T W J_i)`` from the task's own (weighted) rows, 0 for joints that do not
    move the task (squared column norm below ``column_tol``). The loop matrix ``J D J^T`` has
    eigenvalues in ``[0, n_active]`` whatever the robot's size or length unit (eq. 25), so
    ``gain < 2 / (n_active dt)`` is stable at every configuration; ``gain="auto"`` uses half that.
    """

    method = "sjt"

    def __init__(self, robot: Robot, gain="auto", dt: float = 1e-3, task: Task | None = None, *,
                 column_tol: float = mappings.COLUMN_TOL, check_stability: bool = True):
        self.column_tol = positive(column_tol, "column_tol", "task units squared")
        super().__init__(robot, gain, dt, task, check_stability=check_stability)

    def _scaling(self, J):
        return mappings.scaling_factors(J, self.column_tol)

    def _apply(self, J, v, alpha):
        return mappings.sjt_apply(J, v, alpha)

    def matrix(self, J):
        return mappings.sjt_matrix(J, self.column_tol)

    def _loop_eigenvalue_bound(self, J, alpha):
        return float(np.count_nonzero(alpha))  # trace(J D J^T) = n_active

    def _auto_gain(self, J, alpha):
        return 1.0 / (self.dt * max(np.count_nonzero(alpha), 1))


SOLVERS: dict[str, type[DifferentialIKSolver]] = {
    cls.method: cls for cls in (SJTSolver, JTSolver, JPSolver, DLSSolver)
}


def make_solver(name: str, robot: Robot, **kwargs) -> DifferentialIKSolver:
    """The solver called ``name`` (``"sjt"``, ``"jt"``, ``"jp"`` or ``"dls"``, any case).

    ``kwargs`` go to its constructor (``gain``, ``dt``, ``task``, ``damping`` for DLS, ...).
    """
    key = str(name).lower()
    if key not in SOLVERS:
        raise ValueError(f"name must be one of {sorted(SOLVERS)}, got {name!r}")
    return SOLVERS[key](robot, **kwargs)
