"""Joint position and velocity limits applied inside a CLIK step.

Position limits (1-DoF revolute and prismatic joints with URDF limits) are never crossed: a joint
whose update would leave its range is clamped out of the update — it moves exactly to its limit
(or stays there) and its column is removed from the mapping, which is recomputed for the task
velocity that joint no longer provides, so the other joints take over. Velocity limits scale the
whole joint velocity down uniformly, keeping its direction.
"""

from __future__ import annotations

import numpy as np

from .kernels import clamp_pass, outside_box
from .robot import Robot


class JointLimits:
    """The limits one solver enforces, in configuration (q) and tangent (v) indices.

    Args:
        robot: where the URDF limits come from.
        position: enforce position limits (``None``: when the URDF has any).
        velocity: ``True``/``None`` for the URDF's speed limits (if any), ``False`` for none, or
            an (nv,) array of limits in rad/s or m/s (``inf`` for none).
    """

    def __init__(self, robot: Robot, position: bool | None = None, velocity=None):
        model = robot.model
        lower, upper = robot.lower_limits, robot.upper_limits
        qi, vi = [], []
        for j in range(1, model.njoints):
            joint = model.joints[j]
            if joint.nq == 1 and joint.nv == 1 and np.isfinite(lower[joint.idx_q]) \
                    and np.isfinite(upper[joint.idx_q]):
                qi.append(joint.idx_q)
                vi.append(joint.idx_v)
        self.q_index = np.array(qi, dtype=int)
        self.v_index = np.array(vi, dtype=int)
        self.lower = lower[self.q_index]
        self.upper = upper[self.q_index]
        self.position = bool(qi) if position is None else bool(position) and bool(qi)
        if velocity is None or velocity is True:
            vmax = robot.velocity_limits
        elif velocity is False:
            vmax = np.full(model.nv, np.inf)
        else:
            vmax = np.asarray(velocity, dtype=float)
            if vmax.shape != (model.nv,) or np.any(np.isnan(vmax)) or np.any(vmax <= 0):
                raise ValueError(f"velocity_limits must have shape ({model.nv},) with entries "
                                 f"> 0 (rad/s or m/s; inf for none), got {velocity!r}")
        self.velocity_limits = vmax
        self._inv_vmax = 1.0 / vmax
        self.velocity = bool(np.any(np.isfinite(vmax))) and velocity is not False
        self.active = self.position or self.velocity
        # every joint 1-DoF, limited and in order: one fused test of both limits per step
        self._dense = (len(qi) == model.nq == model.nv
                       and np.array_equal(self.q_index, np.arange(model.nq)))
        if self._dense:
            self._mid = 0.5 * (self.upper + self.lower)
            half = 0.5 * (self.upper - self.lower)
            self._inv_half = np.where(half > 0, 1.0 / np.maximum(half, 1e-300), np.inf)
            if not self.position:
                self._inv_half = np.zeros(model.nq)
            self._no_speed = np.zeros(model.nv)
        self._inv_vmax_dt = None
        self._moving = np.ones(model.nv)

    def only_moving(self, moving: np.ndarray) -> None:
        """Skip joints that never move (``moving[i] == 0``, e.g. off every task's chain) in the
        per-step test, so a finger resting on its limit costs nothing."""
        self._moving = np.asarray(moving, dtype=float)
        if self._dense:
            self._inv_half = self._inv_half * self._moving
        self._inv_vmax_dt = None

    @property
    def slowest(self) -> float:
        """The lowest speed limit of the joints that move (rad/s or m/s; inf for none)."""
        moving = self.velocity_limits[self._moving > 0]
        return float(moving.min()) if self.velocity and moving.size else np.inf

    def violated(self, q_next: np.ndarray, step: np.ndarray, dt: float,
                 speed: bool = True) -> bool:
        """Whether ``q_next`` leaves a position limit or ``step / dt`` exceeds a speed limit.

        The per-step test of the common case: one compiled loop, no allocation.
        ``speed=False`` skips the speed part (the caller has bounded every joint's speed).
        """
        if not self._dense:
            return (self.position and self.outside(q_next)) or (
                speed and self.velocity and bool((np.abs(step) * self._inv_vmax).max() > dt))
        if self._inv_vmax_dt is None or self._dt != dt:
            self._dt, self._inv_vmax_dt = dt, self._inv_vmax * self._moving / dt
            if not self.velocity:
                self._inv_vmax_dt = np.zeros_like(self._inv_vmax)
        return outside_box(q_next, step, self._mid, self._inv_half,
                           self._inv_vmax_dt if speed else self._no_speed)

    def outside(self, q_next: np.ndarray) -> bool:
        """Whether ``q_next`` leaves the position limits (cheap check for the common case)."""
        q = q_next if self._dense else q_next[self.q_index]
        return bool((q > self.upper).any() or (q < self.lower).any())

    def clip(self, q_next: np.ndarray) -> None:
        """Clip ``q_next`` into the limits in place (round-off of a step that lands on one)."""
        if self._dense:
            np.minimum(np.maximum(q_next, self.lower, out=q_next), self.upper, out=q_next)
        else:
            q_next[self.q_index] = np.minimum(np.maximum(q_next[self.q_index], self.lower),
                                              self.upper)

    def scale_step(self, step: np.ndarray, dt: float) -> float:
        """Scale ``step`` (= q_dot dt) in place so no joint exceeds its speed limit.

        Returns the factor applied (1 when no joint is too fast).
        """
        worst = float(np.max(np.abs(step) * self._inv_vmax)) / dt if step.size else 0.0
        if worst <= 1.0:
            return 1.0
        step /= worst
        return 1.0 / worst

    def clamp(self, q: np.ndarray, dq: np.ndarray, dt: float, J: np.ndarray, v: np.ndarray,
              remap) -> tuple[np.ndarray, np.ndarray]:
        """``dq`` with the joints that would leave their limits clamped out of the update.

        ``remap(J, v)`` recomputes the joint velocity of the mapping for Jacobian ``J`` and task
        velocity ``v``. Returns the new ``dq`` and the tangent indices of the clamped joints.
        """
        fixed = np.zeros(J.shape[1], dtype=bool)
        fixed_dq = np.zeros(J.shape[1])
        for _ in range(self.q_index.size):
            if not clamp_pass(q, dq, self.q_index, self.v_index, self.lower, self.upper, dt,
                              fixed, fixed_dq):
                break
            # the others take over the task velocity the fixed joints no longer provide
            dq = remap(J * ~fixed, v - J @ fixed_dq)
            dq[fixed] = fixed_dq[fixed]
        return dq, np.flatnonzero(fixed)
