"""The four CLIK methods of the paper: JP, DLS, JT and SJT, and ``make_solver``.

Each is a :class:`~sjt_pin.solvers.DifferentialIKSolver` with its own mapping M(J)
(:mod:`.mappings`): JP eq. (8), DLS (introduction), JT eq. (10), SJT eq. (21).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from . import mappings
from .kernels import sjt_step
from .robot import Robot
from .solvers import _LOCAL, DifferentialIKSolver
from .tasks import PoseTask
from .validation import positive


class JPSolver(DifferentialIKSolver):
    """Jacobian pseudoinverse CLIK, eq. (8)-(9): exact tracking, blows up near singularities.

    ``rcond``: singular values below ``rcond * sigma_max`` are treated as zero.
    """

    method = "jp"

    def __init__(self, robot: Robot, gain="auto", dt: float = 1e-3, task=None, *,
                 rcond: float = mappings.JP_RCOND, **options):
        self.rcond = positive(rcond, "rcond")
        super().__init__(robot, gain, dt, task, **options)

    def _apply(self, J, v):
        return mappings.jp_apply(J, v, self.rcond)

    def matrix(self, J):
        return mappings.jp_matrix(J, self.rcond)


class DLSSolver(DifferentialIKSolver):
    """Damped least-squares CLIK: ``M = J^T (J J^T + damping^2 I)^-1``.

    ``damping`` (lambda) is in task units (m for position rows, rad for orientation rows):
    larger is more robust near singularities and less accurate.
    """

    method = "dls"

    def __init__(self, robot: Robot, gain="auto", dt: float = 1e-3, task=None, *,
                 damping: float = 0.05, **options):
        self.damping = positive(damping, "damping", "task units (m, rad)")
        super().__init__(robot, gain, dt, task, **options)

    def _apply(self, J, v):
        return mappings.dls_apply(J, v, self.damping)

    def matrix(self, J):
        return mappings.dls_matrix(J, self.damping)


class _TransposeSolver(DifferentialIKSolver):
    """Shared by JT and SJT: gradient-type updates, which can stall at singular saddles.

    At an exactly singular configuration an error along the lost task direction gives
    ``J^T e = 0`` although ``e != 0``: a saddle of ``1/2 e^T K e`` that round-off alone takes
    thousands of steps to leave (UR5 at q = 0 asked to roll its tool about the lost axis never
    moves). Every ``saddle_check_every`` steps the step looks for it — the loop gain along the
    command below ``saddle_ratio`` (``v^T J M v < saddle_ratio v^T v``) while the error is above
    ``saddle_error`` — and escapes as perturbed gradient descent does: it tries joint moves of
    ``escape_step`` rad along +-the null direction of J and along ``escape_candidates`` random
    directions (seeded, so runs repeat), takes the one that leaves the smallest error, and then
    lets the regular update work for ``escape_cooldown`` steps before it may escape again.
    """

    escapes_saddles = True
    saddle_ratio = 1e-6
    saddle_error = 1e-6
    saddle_check_every = 10
    escape_step = 0.05  # rad
    escape_candidates = 8
    escape_cooldown = 20

    def __init__(self, *args, seed: int = 0, **kwargs):
        super().__init__(*args, **kwargs)
        self._rng = np.random.default_rng(seed)

    def _escape_saddle(self, q, oMd, J, e, v, step, gain) -> bool:
        """Called every ``saddle_check_every`` steps (``_countdown`` counts down in ``_finish``)."""
        self._countdown = self.saddle_check_every - 1
        if e @ e < self.saddle_error**2:
            return False
        v = gain * e if v is None else v
        vv = v @ v
        if vv == 0.0 or (v @ J) @ step >= self.saddle_ratio * vv * self.dt:
            return False
        chain = np.flatnonzero(self._chain)  # joints off every chain have no null direction
        _, s, Vt = np.linalg.svd(J[:, chain], full_matrices=False)
        null = np.zeros(J.shape[1])
        null[chain] = Vt[s.size - 1]
        random = self._rng.standard_normal((self.escape_candidates, J.shape[1])) * self._chain
        directions = np.vstack([null, -null, random])
        directions /= np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), 1e-12)
        norms = [self._error_norm_at(pin.integrate(self._model, q, self.escape_step * d), oMd)
                 for d in directions]
        self._countdown = self.escape_cooldown
        step += self.escape_step * directions[int(np.argmin(norms))]
        return True

    def _error_norm_at(self, q: np.ndarray, oMd) -> float:
        _, e, _, _, _ = self._kinematics(q, oMd, None)
        return float(np.sqrt(e @ e))


class JTSolver(_TransposeSolver):
    """Jacobian transpose CLIK, eq. (10)-(11): no singularities, gain limited by sigma_max(J)^2."""

    method = "jt"

    def _apply(self, J, v):
        return v @ J

    def matrix(self, J):
        return mappings.jt_matrix(J)

    def _loop_eigenvalue_bound(self, J):
        return float(np.einsum("ij,ij->", J, J))  # trace(J J^T) >= lambda_max


class SJTSolver(_TransposeSolver):
    """Scaled Jacobian transpose CLIK, eq. (21)-(22): ``M = D J^T``, ``D = diag(alpha_i)``.

    ``alpha_i = 1 / (J_i^T W J_i)`` from the tasks' own (weighted, stacked) rows, 0 for joints
    that do not move them: joints outside the frames' kinematic chains, and columns whose squared
    norm is below ``column_tol`` (see :func:`~sjt_pin.mappings.scaling_factors`). The loop matrix
    ``J D J^T`` has eigenvalues in ``[0, n]`` whatever the robot's size or length unit (eq. 25),
    so ``gain < 2 / (n dt)`` is stable at every configuration; ``gain="auto"`` uses half that.
    """

    method = "sjt"

    def __init__(self, robot: Robot, gain="auto", dt: float = 1e-3, task=None, *,
                 column_tol: float = mappings.COLUMN_TOL, **options):
        self.column_tol = positive(column_tol, "column_tol", "task units squared")
        super().__init__(robot, gain, dt, task, **options)
        self._not_chain = 1.0 - self._chain
        # one pose task: the error is log6 itself and the step one compiled loop (_step)
        self._fast = self._single and self.posture is None and isinstance(self.task, PoseTask)
        self._slowest2 = self.limits.slowest ** 2

    def _gain_changed(self) -> None:
        super()._gain_changed()
        # chain_i k dt: dividing it by |J_i|^2 gives k dt alpha_i in one operation (the base
        # constructor sets the chain before the gain, so it is known here)
        k = self._auto_gain(None) if self._auto else self._gain
        self._chain_kdt = self._chain * (k * self.dt) if np.ndim(k) == 0 else None
    def _apply(self, J, v):
        # alpha_i = 1 / |J_i|^2 on the chain, 0 elsewhere and below column_tol (eq. 18)
        out = np.empty(J.shape[1])
        sjt_step(J, v, self._chain, self._not_chain, out, self.column_tol)
        return out

    def _step(self, q, oMd, velocity):
        """The SJT step of eq. (21)-(22) for one pose task and a scalar gain: Pinocchio's calls,
        then :func:`~sjt_pin.kernels.sjt_step`; the general path otherwise."""
        if not self._fast or self._chain_kdt is None or velocity is not None:
            return super()._step(q, oMd, velocity)
        model, data, fid = self._model, self._data, self.frame_id
        pin.computeJointJacobians(model, data, q)
        oMf = pin.updateFramePlacement(model, data, fid)
        J = pin.getFrameJacobian(model, data, fid, _LOCAL)
        e = pin.log6(oMf.actInv(oMd)).vector
        gain = self._gain_max if not self._auto else self._auto_gain(None)
        sw, v, e_w = self.task.sqrt_weight, None, e
        if sw is not None:
            J = sw[:, None] * J
            e_w = sw * e
            v = gain * e_w
        step = np.empty(self.robot.nv)
        # k dt D J^T e, and |e|^2 (weighted when the task has weights)
        ee = sjt_step(J, e_w, self._chain_kdt, self._not_chain, step, self.column_tol)
        if not math.isfinite(ee):
            self._raise_non_finite(q)
        if sw is not None:
            ee = float(e @ e)
        # |q_dot_i| = k alpha_i |J_i^T e| <= k sqrt(alpha_i) |e| <= k |e| since alpha_i <= 1
        # (eq. 19): below the slowest joint's limit, the speed test can be skipped
        speed_safe = sw is None and gain * gain * ee <= self._slowest2
        return self._finish(q, oMd, J, e, ee, v, step, gain, oMf, speed_safe)

    def scaling_factors(self, J):
        return mappings.scaling_factors(J, self.column_tol) * self._chain

    def matrix(self, J):
        return self.scaling_factors(J)[:, None] * J.T

    def _loop_eigenvalue_bound(self, J):
        return float(self.n_chain)  # trace(J D J^T) = n_active <= n

    def _auto_gain(self, J):
        return 1.0 / (self.dt * max(self.n_chain, 1))


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
