"""Joint acceleration limits."""

from __future__ import annotations

from ..validation import positive_limits
from .base import Limit


class AccelerationLimit(Limit):
    """``|q_ddot_i| <= limits_i`` between consecutive steps: the velocity of this step stays
    within ``limits dt`` of the previous step's (rad/s^2 or m/s^2; ``inf`` for none). A
    smoothness limit: it yields to the position, speed and collision limits where both cannot
    hold (``StepInfo.limit_conflicts``). With it, each joint also brakes so that it can stop
    where the feedback sends it (and before its position limits), so that a target is reached
    without overshoot and at rest.

    Franka's Panda, for example, allows 15, 7.5, 10, 12.5, 15, 20, 20 rad/s^2 on its joints
    (its control interface's "necessary conditions").
    """

    name = "acceleration"

    def __init__(self, limits, nv: int):
        self.limits = positive_limits(limits, nv, "acceleration_limits", "rad/s^2 or m/s^2")

    def __repr__(self) -> str:
        return "AccelerationLimit()"
