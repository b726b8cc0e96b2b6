"""Tasks: what the end effector must do, as an error e, Jacobian rows J and a feed-forward.

A task turns the current frame pose ``oMf`` (world pose of the frame), its LOCAL Jacobian and a
desired pose ``oMd`` into the three pieces of the CLIK law ``q_dot = M(J) (x_dot_d + K e)``
(paper eq. 5/10/21). Conventions (DESIGN.md section 4):

- :class:`PoseTask`: ``e = log6(oMf^-1 oMd)`` in the frame's LOCAL axes, with the LOCAL Jacobian.
- :class:`PositionTask`: ``e = p_d - p`` in world axes, LOCAL_WORLD_ALIGNED linear rows.
- :class:`OrientationTask`: ``e = log3(R^T R_d)`` in LOCAL axes, with the LOCAL angular rows.

Desired velocities are ``pin.Motion`` objects with ``linear = p_dot_d`` and ``angular = omega_d``,
both in world axes at the desired frame's origin; each task expresses them in its own rows.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
import pinocchio as pin

from .validation import as_pose, as_vector

_AXES = {"x": 0, "y": 1, "z": 2}


class Task(ABC):
    """Base class: a block of ``dim`` rows on one frame (default: the robot's end effector).

    ``weight`` (optional, one positive number per row, or a scalar) scales rows in the
    least-squares sense: the mappings see ``sqrt(W) J`` and ``sqrt(W) e``, so SJT's scaling
    factors become ``alpha_i = 1 / (J_i^T W J_i)`` (paper eq. 18 with a weighted norm).
    """

    dim: int

    def __init__(self, frame: str | None = None, weight=None):
        self.frame = frame
        if weight is None:
            self.sqrt_weight = None
        else:
            w = np.full(self.dim, float(weight)) if np.ndim(weight) == 0 else weight
            w = as_vector(w, "weight", self.dim)
            if np.any(w <= 0):
                raise ValueError(f"weight must be positive, got {w}")
            self.sqrt_weight = np.sqrt(w)

    def target_pose(self, target) -> pin.SE3:
        """``target`` (``pin.SE3`` or 4x4 matrix) validated as a ``pin.SE3``."""
        return as_pose(target, "target")

    @abstractmethod
    def error(self, oMf: pin.SE3, oMd: pin.SE3) -> np.ndarray:
        """Task error e (dim,) of the frame at ``oMf`` with respect to the desired pose ``oMd``."""

    @abstractmethod
    def jacobian(self, oMf: pin.SE3, J_local: np.ndarray) -> np.ndarray:
        """Task Jacobian rows (dim, nv) from the frame's LOCAL Jacobian ``J_local``."""

    @abstractmethod
    def feedforward(self, oMf: pin.SE3, oMd: pin.SE3, velocity: pin.Motion) -> np.ndarray:
        """Desired task velocity (dim,) from ``velocity`` (world axes, desired origin)."""

    def __repr__(self) -> str:
        frame = f"frame={self.frame!r}" if self.frame else "end effector"
        return f"{type(self).__name__}({frame})"


class PoseTask(Task):
    """Full SE(3) pose: 6 rows [linear; angular] in the frame's LOCAL axes (m, rad)."""

    dim = 6

    def error(self, oMf, oMd):
        return pin.log6(oMf.actInv(oMd)).vector

    def jacobian(self, oMf, J_local):
        return J_local

    def feedforward(self, oMf, oMd, velocity):
        # body velocity of the desired frame, moved to the current frame's origin and axes
        R_d = oMd.rotation
        body = pin.Motion(R_d.T @ velocity.linear, R_d.T @ velocity.angular)
        return oMf.actInv(oMd).act(body).vector


class PositionTask(Task):
    """Position of the frame origin along a subset of the world axes (m).

    ``axes`` is any non-empty subset of ``"xyz"`` in any order, e.g. ``"xy"`` for a planar arm.
    Targets may be ``pin.SE3`` (only the translation is used) or a 3-vector in metres.
    """

    def __init__(self, axes: str = "xyz", frame: str | None = None, weight=None):
        if (not isinstance(axes, str) or not axes or set(axes) - set(_AXES)
                or len(set(axes)) != len(axes)):
            raise ValueError(f"axes must be a non-empty subset of 'xyz', got {axes!r}")
        self.axes = axes
        self.dim = len(axes)
        self._rows = slice(None) if axes == "xyz" else [_AXES[a] for a in axes]
        super().__init__(frame, weight)

    def target_pose(self, target) -> pin.SE3:
        if isinstance(target, pin.SE3) or np.shape(target) == (4, 4):
            return as_pose(target, "target")
        return pin.SE3(np.eye(3), as_vector(target, "target", 3))

    def error(self, oMf, oMd):
        return (oMd.translation - oMf.translation)[self._rows]

    def jacobian(self, oMf, J_local):
        return (oMf.rotation @ J_local[:3])[self._rows]

    def feedforward(self, oMf, oMd, velocity):
        return velocity.linear[self._rows]

    def __repr__(self) -> str:
        frame = f", frame={self.frame!r}" if self.frame else ""
        return f"PositionTask(axes={self.axes!r}{frame})"


class OrientationTask(Task):
    """Orientation of the frame: 3 rows (rad) in the frame's LOCAL axes."""

    dim = 3

    def error(self, oMf, oMd):
        return pin.log3(oMf.rotation.T @ oMd.rotation)

    def jacobian(self, oMf, J_local):
        return J_local[3:]

    def feedforward(self, oMf, oMd, velocity):
        return oMf.rotation.T @ velocity.angular


class PostureTask:
    """A joint-space pull toward a reference configuration, for redundant robots.

    Stacked under the other tasks with a low ``weight`` (dimensionless per joint), it keeps the
    self-motion of a 7-DoF arm from drifting over long runs at the price of a small bias of the
    main task of order ``weight``. Its error is ``difference(q, q_ref)`` (rad or m per joint)
    and its rows are ``sqrt(weight) I``; SJT's scaling factors then become
    ``alpha_i = 1 / (J_i^T W J_i + weight_i)``, and the loop's eigenvalues stay in [0, n].
    ``q_ref`` defaults to the robot's ``q0``.
    """

    def __init__(self, q_ref=None, weight=1e-2):
        self.q_ref = None if q_ref is None else np.asarray(q_ref, dtype=float)
        w = np.asarray(weight, dtype=float)
        if w.ndim > 1 or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ValueError(f"weight must be positive (a number or one per joint), "
                             f"got {weight!r}")
        self.weight = w

    def __repr__(self) -> str:
        return f"PostureTask(weight={self.weight})"
