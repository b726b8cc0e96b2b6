"""Joint speed limits: scale the whole step down, keeping its direction."""

from __future__ import annotations

import numpy as np

from .base import Limit


class VelocityLimit(Limit):
    """No joint faster than its limit: the joint velocity is scaled down uniformly, so the
    direction of the update (and of the task motion) is kept. A solver runs it inside its step
    kernel, where a joint held by the position limit (moving onto its limit, or back into its
    range) is capped on its own and the others scaled; these methods are the reference.

    Args:
        limits: (nv,) speed limits in rad/s or m/s (``inf`` for none).
    """

    def __init__(self, limits: np.ndarray):
        self.limits = np.asarray(limits, dtype=float)
        self._inv = 1.0 / self.limits

    @property
    def active(self) -> bool:
        return bool(np.any(np.isfinite(self.limits)))

    def violated(self, q, step, dt):
        return bool(np.max(np.abs(step) * self._inv) > dt)

    def enforce(self, q, step, dt, remap):
        worst = float(np.max(np.abs(step) * self._inv)) / dt
        if worst > 1.0:
            step /= worst
        return step
