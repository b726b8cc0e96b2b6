"""Errors and warnings that carry what the user needs to fix the call."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class SJTError(Exception):
    """Base class of the errors this package raises on its own."""


class FrameNotFound(SJTError, KeyError):
    """A frame name that the model does not have; the message lists the closest names."""

    def __init__(self, name: str, available: Iterable[str], robot: str = "the model"):
        available = list(available)
        close = difflib.get_close_matches(name, available, n=5, cutoff=0.4)
        hint = f"close names: {close}" if close else f"frames: {available[:20]}"
        self.name = name
        self.available = available
        super().__init__(f"frame {name!r} not found in {robot}; {hint}")

    def __str__(self) -> str:  # KeyError would quote the message
        return self.args[0]


class URDFError(SJTError, ValueError):
    """A URDF that is missing, empty, not XML or not a valid robot tree; the message names the
    file (or ``<URDF string>``) and the joint or link at fault."""


class ConcurrentStepError(SJTError, RuntimeError):
    """A solver stepped by a second thread while a step of it is running: its buffers and its
    ``pin.Data`` are one thread's. Give each thread its own solver (or a copy)."""


class GainWarning(UserWarning):
    """A fixed gain above the discrete-time stability bound at the current configuration."""
