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

    def __init__(self, limits, nv: int):
        self.limits = positive_limits(limits, nv, "jerk_limits", "rad/s^3 or m/s^3")

    def bounds(self, kinematics, motion: Motion):
        dt = motion.dt
        change = self.limits * dt
        return (motion.dq + dt * (motion.ddq - change), motion.dq + dt * (motion.ddq + change))
