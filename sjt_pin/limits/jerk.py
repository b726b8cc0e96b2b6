"""Joint jerk limits."""

from __future__ import annotations

import numpy as np

from ..validation import positive_limits
from .base import Limit, Motion


class JerkLimit(Limit):
    """``|q_dddot_i| <= limits_i``: this step's acceleration stays within ``limits dt`` of the
    previous step's, so its velocity within ``dt (q_ddot_prev +- limits dt)`` of the previous
    velocity (rad/s^3 or m/s^3; ``inf`` for none). A smoothness limit, like
    :class:`~sjt_pin.limits.AccelerationLimit`.

    Franka's Panda allows 7,500, 3,750, 5,000, 6,250, 7,500, 10,000, 10,000 rad/s^3.
    """

    name = "jerk"
    hard = False
    yields_first = True  # to the acceleration limit, where the two contradict each other

    def __init__(self, limits, nv: int, speeds: np.ndarray | None = None):
        self.limits = positive_limits(limits, nv, "jerk_limits", "rad/s^3 or m/s^3")
        self.speeds = np.full(nv, np.inf) if speeds is None else np.asarray(speeds, dtype=float)

    def bounds(self, kinematics, motion: Motion):
        dt, J = motion.dt, self.limits
        change = J * dt
        lower = motion.dq + dt * (motion.ddq - change)
        upper = motion.dq + dt * (motion.ddq + change)
        # approach a speed limit with an acceleration that can ramp down to 0 before it:
        # a + a^2 / (2 J) per unit of the velocity left, v_next + a_next^2 / (2 J) <= v_max
        with np.errstate(invalid="ignore"):
            for sign in (1.0, -1.0):
                left = np.maximum(self.speeds - sign * motion.dq, 0.0)
                a_max = J * (-dt + np.sqrt(dt * dt + 2.0 * left / J))
                bound = motion.dq + sign * dt * a_max
                if sign > 0:
                    upper = np.where(np.isfinite(bound), np.minimum(upper, bound), upper)
                else:
                    lower = np.where(np.isfinite(bound), np.maximum(lower, bound), lower)
        return lower, upper

    def approach(self, desired: np.ndarray, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """Bounds that let each joint's velocity reach ``desired`` (rad/s) without
        overshooting it: the acceleration toward it must be able to ramp down to 0 at the jerk
        limit before it is reached, ``a^2 / (2 J) + a dt <= |desired - dq|``."""
        dt, J = motion.dt, self.limits
        gap = desired - motion.dq
        with np.errstate(invalid="ignore"):  # inf * 0 where a joint has no jerk limit
            a_max = J * (-dt + np.sqrt(dt * dt + 2.0 * np.abs(gap) / J))
        step = np.where(np.isfinite(a_max), dt * a_max, np.inf)
        return (np.where(gap < 0, motion.dq - step, -np.inf),
                np.where(gap > 0, motion.dq + step, np.inf))
