"""Joint jerk limits."""

from __future__ import annotations

from ..validation import positive_limits
from .base import Limit


class JerkLimit(Limit):
    """``|q_dddot_i| <= limits_i``: this step's acceleration stays within ``limits dt`` of the
    previous step's (rad/s^3 or m/s^3; ``inf`` for none). A smoothness limit, like
    :class:`~sjt_pin.limits.AccelerationLimit` (to which it yields where the two contradict each
    other). With it, each joint's acceleration ramps: toward a wanted velocity it ramps down in
    time not to pass it, toward a speed limit not to exceed it, and every braking plan (to a
    target, to a position limit) counts the ramps: a jerk-limited stream reaches a held target
    and rests, for any ratio of jerk to acceleration.

    Franka's Panda allows 7,500, 3,750, 5,000, 6,250, 7,500, 10,000, 10,000 rad/s^3.
    """

    name = "jerk"

    def __init__(self, limits, nv: int):
        self.limits = positive_limits(limits, nv, "jerk_limits", "rad/s^3 or m/s^3")

    def __repr__(self) -> str:
        return "JerkLimit()"
