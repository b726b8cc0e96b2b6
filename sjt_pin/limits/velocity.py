"""Joint speed limits: scale the whole step down, keeping its direction."""

from __future__ import annotations

import numpy as np

from ..kernels import limits_violated
from .base import Limit


class VelocityLimit(Limit):
    """No joint faster than its limit: the whole joint velocity is scaled down uniformly, so
    the direction of the update (and of the task motion) is kept.

    Args:
        limits: (nv,) speed limits in rad/s or m/s (``inf`` for none).
    """

    def __init__(self, limits: np.ndarray):
        self.limits = np.asarray(limits, dtype=float)
        self._inv = 1.0 / self.limits
        self._empty = np.zeros(0, dtype=np.int64)
        self._none = np.zeros(0)
        self._dt = None
        #: the factor (<= 1) the last step was scaled by
        self.scale = 1.0

    @property
    def active(self) -> bool:
        return bool(np.any(np.isfinite(self.limits)))

    def violated(self, q, step, dt):
        if dt != self._dt:
            self._dt, self._inv_dt = dt, self._inv / dt
        return limits_violated(q, step, self._empty, self._empty, self._none, self._none,
                               self._inv_dt) != 0

    def reset(self):
        self.scale = 1.0

    def enforce(self, q, step, dt, remap):
        worst = float(np.max(np.abs(step) * self._inv)) / dt
        if worst > 1.0:
            step /= worst
            self.scale = 1.0 / worst
        return step
