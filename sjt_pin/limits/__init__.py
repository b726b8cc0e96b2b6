"""Limits applied inside a step, one class per file (see :mod:`.base`)."""

from .base import Limit
from .position import PositionLimit
from .velocity import VelocityLimit

__all__ = ["Limit", "PositionLimit", "VelocityLimit"]
