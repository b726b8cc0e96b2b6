"""Joint speed limits."""

from __future__ import annotations

import numpy as np

from .base import Limit


class VelocityLimit(Limit):
    """No joint faster than its limit: ``|q_dot_i| <= limits_i`` (a hard limit of the compiled
    stage; with jerk limits, also no acceleration that could not ramp down before it).

    Args:
        limits: (nv,) speed limits in rad/s or m/s (``inf`` for none).
    """

    name = "velocity"

    def __init__(self, limits: np.ndarray):
        self.limits = np.asarray(limits, dtype=float)

    @property
    def active(self) -> bool:
        return bool(np.any(np.isfinite(self.limits)))

    def __repr__(self) -> str:
        return "VelocityLimit()"
