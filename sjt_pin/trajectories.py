"""Desired end-effector trajectories with analytic velocities.

``sample(t)`` returns ``(pose, velocity)``: the desired world pose ``oMd`` (``pin.SE3``) and a
``pin.Motion`` with ``linear = p_dot_d`` (m/s) and ``angular = omega_d`` (rad/s), both in world
axes at the desired origin. ``samples(times)`` returns the same for many times at once, as
arrays. Before 0 and after ``duration`` a trajectory holds its end pose with zero velocity, so
``track`` can keep commanding the final target. Times must be finite (``ValueError``
otherwise: a NaN time would give a NaN pose).

A ``Line`` or ``Circle`` made without ``rotation=`` is *position-only* (``position_only`` is
True): it prescribes no orientation. ``track`` then holds the task frame's orientation at the
start configuration (so a pose task keeps the tool as it was, and a position task is
unaffected); ``sample`` and ``samples`` return the identity rotation, meaningful only with a
position task, so give ``rotation=`` (or call :meth:`Trajectory.holding`) to step a pose task
with it yourself.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod

import numpy as np
import pinocchio as pin

from .validation import as_pose, as_vector, positive

TIMINGS = ("linear", "min_jerk")


def _timing(name: str) -> str:
    if name not in TIMINGS:
        raise ValueError(f"timing must be one of {TIMINGS}, got {name!r}")
    return name


def _finite_times(t) -> None:
    """``ValueError`` unless every time in ``t`` is a finite number."""
    if not np.all(np.isfinite(t)):
        raise ValueError(f"t must be finite times in s, got {t!r}")


def _rotation(rotation) -> np.ndarray | None:
    """``rotation`` (3x3) as a rotation matrix (projected if within the tolerance), or None."""
    if rotation is None:
        return None
    return as_pose(pin.SE3(np.asarray(rotation, dtype=float), np.zeros(3)),
                   "rotation").rotation


def min_jerk(tau):
    """The minimum-jerk progress ``s = 10 tau^3 - 15 tau^4 + 6 tau^5`` (rest to rest) of
    ``tau``, clipped to [0, 1] (0 before, 1 after); a number or an array."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


def _progress(t, duration: float, timing: str):
    """Path parameter s(t) in [0, 1] and its rate ds/dt (1/s); ``t`` a number or an array."""
    _finite_times(t)
    tau = np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0)
    inside = (np.asarray(t) >= 0.0) & (np.asarray(t) < duration)  # right-continuous rate
    if timing == "linear":
        s, rate = tau, np.where(inside, 1.0 / duration, 0.0)
    else:  # minimum jerk: s = 10 tau^3 - 15 tau^4 + 6 tau^5
        s = min_jerk(tau)
        rate = np.where(inside, 30.0 * tau**2 * (1.0 - tau) ** 2 / duration, 0.0)
    if np.ndim(t) == 0:
        return float(s), float(rate)
    return s, rate


class Trajectory(ABC):
    """A desired pose x_d(t) for t in [0, duration] (s), with its velocity x_dot_d(t)."""

    duration: float
    #: True when the trajectory prescribes a position only (no ``rotation=``): see the module
    position_only: bool = False
    #: the orientation held (3x3), for trajectories that hold one; None when position-only
    rotation: np.ndarray | None = None

    def holding(self, rotation) -> Trajectory:
        """A copy that holds the orientation ``rotation`` (3x3) throughout (no longer
        position-only); ``self`` if it prescribes an orientation of its own."""
        if not self.position_only:
            return self
        held = copy.copy(self)
        held.rotation = _rotation(rotation)
        held.position_only = False
        return held

    @abstractmethod
    def sample(self, t: float) -> tuple[pin.SE3, pin.Motion]:
        """Desired pose and velocity at time ``t`` (s)."""

    def samples(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Desired positions (N, 3) in m, rotations (N, 3, 3) and velocities (N, 6)
        [p_dot_d (m/s), omega_d (rad/s)] at ``times`` (N,) in s, as :meth:`sample` gives them."""
        times = np.asarray(times, dtype=float)
        _finite_times(times)
        positions, rotations = np.empty((times.size, 3)), np.empty((times.size, 3, 3))
        velocities = np.empty((times.size, 6))
        for k, t in enumerate(times):
            pose, velocity = self.sample(float(t))
            positions[k], rotations[k], velocities[k] = (pose.translation, pose.rotation,
                                                         velocity.vector)
        return positions, rotations, velocities

    def times(self, dt: float, duration: float | None = None) -> np.ndarray:
        """Sample times 0, dt, 2 dt, ... up to ``duration`` (default: the trajectory's) included."""
        dt = positive(dt, "dt", "s")
        end = self.duration if duration is None else positive(duration, "duration", "s")
        return np.arange(int(np.floor(end / dt + 1e-9)) + 1) * dt

    def positions(self, dt: float) -> np.ndarray:
        """Desired positions (N, 3) at ``times(dt)``, in m (for drawing the path)."""
        return np.array([self.sample(t)[0].translation for t in self.times(dt)])


_IDENTITY = np.eye(3)
_IDENTITY.flags.writeable = False


def _held(rotation: np.ndarray | None) -> np.ndarray:
    """The rotation a trajectory samples: its own, or the identity when position-only."""
    return _IDENTITY if rotation is None else rotation


class Line(Trajectory):
    """Straight line from ``start`` to ``end`` (3-vectors, m) in ``duration`` s.

    It starts at ``start``, not where the robot is: give the frame's own position
    (``robot.fk(q0).translation``) to start without a jump; :func:`~sjt_pin.track` warns when
    the first target is away from the frame. The orientation is held at ``rotation`` (3x3);
    without it the line is position-only (see the module: ``track`` holds the start
    orientation). ``timing`` is ``"linear"`` (constant speed, as in the paper's tasks) or
    ``"min_jerk"`` (rest to rest).
    """

    def __init__(self, start, end, duration: float, rotation=None, timing: str = "linear"):
        self.start = as_vector(start, "start", 3)
        self.end = as_vector(end, "end", 3)
        self.duration = positive(duration, "duration", "s")
        self.rotation = _rotation(rotation)
        self.position_only = rotation is None
        self.timing = _timing(timing)

    def sample(self, t):
        s, ds = _progress(t, self.duration, self.timing)
        delta = self.end - self.start
        return (pin.SE3(_held(self.rotation), self.start + s * delta),
                pin.Motion(ds * delta, np.zeros(3)))

    def samples(self, times):
        s, ds = _progress(np.asarray(times, dtype=float), self.duration, self.timing)
        delta = self.end - self.start
        velocities = np.zeros((s.size, 6))
        velocities[:, :3] = ds[:, None] * delta
        return (self.start + s[:, None] * delta,
                np.broadcast_to(_held(self.rotation), (s.size, 3, 3)), velocities)


class Circle(Trajectory):
    """Circle of ``radius`` (m) about ``center`` in the plane normal to ``normal``.

    Starts at angle ``start_angle`` (rad, measured from the plane's first axis: world x for the
    default normal +z), that is at ``center + radius * x`` by default, and runs ``turns`` times
    counter-clockwise about ``normal`` at constant speed over ``duration`` s, with the
    orientation held at ``rotation`` (3x3; without it the circle is position-only, see the
    module). To start where the frame is, centre the circle ``radius`` before it along that
    axis (``Circle(p - [r, 0, 0], r, ...)`` for the default normal) or choose ``start_angle``;
    :func:`~sjt_pin.track` warns when the first target is away from the frame (a circle
    centred on the other side of it jumps the target by its diameter at t = 0). ``start``
    (m) is where it starts.
    """

    def __init__(self, center, radius: float, duration: float, normal=(0.0, 0.0, 1.0),
                 start_angle: float = 0.0, turns: float = 1.0, rotation=None):
        self.center = as_vector(center, "center", 3)
        self.radius = positive(radius, "radius", "m")
        self.duration = positive(duration, "duration", "s")
        n = as_vector(normal, "normal", 3)
        if np.linalg.norm(n) < 1e-12:
            raise ValueError("normal must be a non-zero 3-vector")
        n = n / np.linalg.norm(n)
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        self._u = helper - (helper @ n) * n
        self._u /= np.linalg.norm(self._u)
        self._w = np.cross(n, self._u)
        self.normal = n
        self.start_angle = float(as_vector([start_angle], "start_angle", 1)[0])
        self.turns = float(as_vector([turns], "turns", 1)[0])
        self.rotation = _rotation(rotation)
        self.position_only = rotation is None

    @property
    def start(self) -> np.ndarray:
        """Where the circle starts (3, m, world)."""
        return self.center + self.radius * (np.cos(self.start_angle) * self._u
                                            + np.sin(self.start_angle) * self._w)

    def sample(self, t):
        positions, _, velocities = self.samples(np.array([t], dtype=float))
        return pin.SE3(_held(self.rotation), positions[0]), pin.Motion(velocities[0])

    def samples(self, times):
        s, ds = _progress(np.asarray(times, dtype=float), self.duration, "linear")
        sweep = 2.0 * np.pi * self.turns
        angle = (self.start_angle + sweep * s)[:, None]
        cos, sin = np.cos(angle), np.sin(angle)
        radial = cos * self._u + sin * self._w
        tangent = -sin * self._u + cos * self._w
        velocities = np.zeros((s.size, 6))
        velocities[:, :3] = (self.radius * sweep * ds)[:, None] * tangent
        return (self.center + self.radius * radial,
                np.broadcast_to(_held(self.rotation), (s.size, 3, 3)), velocities)


class PoseInterpolation(Trajectory):
    """SE(3) geodesic from ``start`` to ``end`` (``pin.SE3`` or 4x4): ``start exp6(s xi)``.

    ``xi = log6(start^-1 end)`` is a constant body twist, so the path is a screw motion; ``s(t)``
    follows ``timing`` (``"min_jerk"`` by default, or ``"linear"``).
    """

    def __init__(self, start, end, duration: float, timing: str = "min_jerk"):
        self.start = as_pose(start, "start")
        self.end = as_pose(end, "end")
        self.duration = positive(duration, "duration", "s")
        self.timing = _timing(timing)
        self._twist = pin.log6(self.start.actInv(self.end)).vector  # [v; w], body axes

    def sample(self, t):
        s, ds = _progress(t, self.duration, self.timing)
        pose = self.start * pin.exp6(s * self._twist)
        R = pose.rotation  # the body twist ds * xi, rotated to world axes
        return pose, pin.Motion(ds * (R @ self._twist[:3]), ds * (R @ self._twist[3:]))
