"""A joint-space motion to a goal configuration, as the task frame's trajectory.

A local method (SJT, JT, JP, DLS, pink's QP) sent to a far pose can stop at a local minimum of
its error against the joint limits. :meth:`sjt_pin.Solver.move_to` reaches any pose
``solve()`` reaches: ``solve()`` finds a goal configuration from the current one, and
:class:`JointMove` is the motion there, the straight joint-space path ``q(s) = q_start (+)
s (q_goal (-) q_start)`` (Pinocchio's ``interpolate``: the manifold's geodesic) timed by the
minimum-jerk profile ``s = 10 tau^3 - 15 tau^4 + 6 tau^5``, ``tau = t / T``. Its peaks are
``1.875 d / T`` (speed), ``5.774 d / T^2`` (acceleration) and ``60 d / T^3`` (jerk) for a joint
moving ``d``, so the duration

    T = max_j max(1.875 d_j / (r V_j), sqrt(5.774 d_j / (r A_j)), cbrt(60 d_j / (r J_j)))

keeps every joint within the share ``r`` of its speed, acceleration and jerk limits. It is
sampled as the frame's pose ``fk(q(t))`` and velocity ``J(q(t)) q_dot(t)`` (world-aligned),
and :meth:`JointMove.step` follows it with a twin of the solver (its method, options and
limits) whose posture task, stacked with the pose task, is pulled along ``q(t)``: the joints
stay on the path (a posture in the pose task's null space alone let a UR5 change branch at a
singularity on the path and never arrive), and every limit the solver was given (collision
rows included) still holds on every step, whatever the path asks.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from .trajectories import Trajectory

#: min-jerk profile's peak |s'|, |s''| and |s'''| for T = 1 (at tau = 1/2, (3 -+ sqrt 3)/6, 0)
_PEAKS = (1.875, 10.0 / math.sqrt(3.0), 60.0)


class JointMove(Trajectory):
    """The task frame's pose along the minimum-jerk joint-space path from ``q_start`` to
    ``q_goal`` (nq,), timed so that no joint exceeds ``share`` of its limits (see the module);
    made by :meth:`sjt_pin.Solver.move_to`, stepped by :meth:`step`.

    Attributes:
        duration: the path's duration (s).
        q_goal: where it ends (nq,).
        time: the time of the next step (s).
        last: the last step's :class:`~sjt_pin.StepInfo` (``None`` before the first).
    """

    #: the posture task's weight during a move, in the pose task's level (its rows in rad against
    #: the pose's in m and rad)
    POSTURE_WEIGHT = 0.2

    def __init__(self, owner, twin, frame_id: int, q_start: np.ndarray, q_goal: np.ndarray,
                 velocity: np.ndarray | None, acceleration: np.ndarray | None = None,
                 jerk: np.ndarray | None = None, share: float = 0.5,
                 min_duration: float = 0.1):
        if not 0.0 < share <= 1.0:
            raise ValueError(f"share must be in (0, 1], got {share!r}")
        self._owner, self._twin = owner, twin
        self._reference = twin.stack.tasks[-1].q_ref  # the twin's posture task's q_ref
        self.robot, self.frame_id = owner.robot, frame_id
        self.q_start, self.q_goal = q_start.copy(), q_goal.copy()
        self._model, self._data = self.robot.model, self.robot.model.createData()
        self._delta = pin.difference(self._model, q_start, q_goal)
        distance = np.abs(self._delta)
        times = [min_duration]
        for limit, peak, power in zip((velocity, acceleration, jerk), _PEAKS, (1, 2, 3),
                                      strict=True):
            if limit is None:
                continue
            limit = np.asarray(limit, dtype=float)
            moving = (distance > 0.0) & np.isfinite(limit) & (limit > 0.0)
            if moving.any():
                need = peak * distance[moving] / (share * limit[moving])
                times.append(float(np.max(need)) ** (1.0 / power))
        self.duration = max(times)
        self.time = 0.0
        self.last = None

    def configuration(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The path's configuration (nq,) and joint velocity (nv,) at time ``t`` (s)."""
        tau = min(max(t / self.duration, 0.0), 1.0)
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        inside = 0.0 <= t < self.duration
        rate = 30.0 * tau**2 * (1.0 - tau) ** 2 / self.duration if inside else 0.0
        q = pin.integrate(self._model, self.q_start, s * self._delta)
        return q, rate * self._delta

    def sample(self, t):
        q, dq = self.configuration(t)
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(model, data, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
        twist = J.reshape(6, model.nv) @ dq  # ((6,) where nv = 1)
        return pin.SE3(data.oMf[self.frame_id]), pin.Motion(twist[:3], twist[3:])

    def step(self, q) -> np.ndarray:
        """One control period of the move from ``q`` (nq,): the next configuration. Past
        ``duration`` it holds the goal. The solver that made the move carries on from here."""
        pose, velocity = self.sample(self.time)
        self._reference[:] = self.configuration(self.time)[0]
        q_next = self._twin.step(q, pose, velocity)
        self._owner.continue_from(self._twin)
        self.last = self._twin.last
        self.time += self._twin.dt
        return q_next

    @property
    def done(self) -> bool:
        """Whether the path has ended and the arm is at its goal pose (task error below 1e-9,
        at rest to 1e-9 rad/s)."""
        return (self.time >= self.duration and self.last is not None
                and self.last.error_norm < 1e-9 and float(np.abs(self.last.dq).max()) < 1e-9)


def move_goal(solver, q, target, options: dict) -> tuple[np.ndarray, Any]:
    """``q`` checked, and the result of ``solver.solve()`` from it (with ``options``) for
    ``Solver.move_to``: ``ValueError`` when the solver's task is not one frame's, or when
    ``solve()`` finds no configuration within its tolerance."""
    stack = solver.stack
    if not stack.single or stack.task.frame_id < 0:
        raise ValueError("move_to needs a solver with one frame task (PoseTask, "
                         "PositionTask, OrientationTask)")
    q = solver.robot.check_q(q)
    result = solver.solve(target, q, **options)
    if not result.success:
        raise ValueError(f"move_to: solve() found no configuration that reaches the target "
                         f"(best error {result.error:.3g} after {result.restarts} restarts)")
    return q, result


def solver_move(solver, twin, q: np.ndarray, goal: np.ndarray, share: float) -> JointMove:
    """``Solver.move_to``'s motion of ``solver`` from ``q`` to ``goal``, stepped by its
    ``twin``, timed within ``share`` of the solver's speed, acceleration and jerk limits."""
    speed = None if solver.velocity_limit is None else solver.velocity_limit.limits
    return JointMove(solver, twin, solver.stack.task.frame_id, q, goal, speed,
                     None if solver.acceleration_limit is None
                     else solver.acceleration_limit.limits,
                     None if solver.jerk_limit is None else solver.jerk_limit.limits, share)
