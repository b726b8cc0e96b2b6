"""Limits of the constraint stage, one class per file (see :mod:`.base`)."""

from .acceleration import AccelerationLimit
from .base import Limit, Motion
from .collision import CollisionLimit
from .convex_parts import convex_parts
from .jerk import JerkLimit
from .position import PositionLimit
from .support import SupportLimit
from .velocity import VelocityLimit

__all__ = ["AccelerationLimit", "CollisionLimit", "JerkLimit", "Limit", "Motion", "PositionLimit",
           "SupportLimit", "VelocityLimit", "convex_parts"]
