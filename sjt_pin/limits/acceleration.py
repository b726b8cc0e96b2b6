"""Joint acceleration limits."""

from __future__ import annotations

from ..validation import positive_limits
from .base import Limit, Motion


class AccelerationLimit(Limit):
    """``|q_ddot_i| <= limits_i`` between consecutive steps: the velocity of this step stays
    within ``limits dt`` of the previous step's (rad/s^2 or m/s^2; ``inf`` for none). A
    smoothness limit: it yields to the position and speed limits where both cannot hold.

    Franka's Panda, for example, allows 15, 7.5, 10, 12.5, 15, 20, 20 rad/s^2 on its joints
    (its control interface's "necessary conditions").
    """

    name = "acceleration"
    hard = False

    def __init__(self, limits, nv: int):
        self.limits = positive_limits(limits, nv, "acceleration_limits", "rad/s^2 or m/s^2")

    def bounds(self, kinematics, motion: Motion):
        step = self.limits * motion.dt
        return motion.dq - step, motion.dq + step
