"""Errors and warnings that carry what the user needs to fix the call."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

#: :class:`FrameNotFound` lists every frame of a model with at most this many (TIAGo has 156),
#: the first tenth of them otherwise
FRAMES_SHOWN = 300


class SJTError(Exception):
    """Base class of the errors this package raises on its own."""


class FrameNotFound(SJTError, KeyError):
    """A frame name that the model does not have; the message lists the closest names (by
    spelling, and names containing it) and the model's frames (``Robot.frames()`` lists them
    with their types and joints)."""

    def __init__(self, name: str, available: Iterable[str], robot: str = "the model",
                 message: str | None = None):
        available = list(dict.fromkeys(available))
        lowered = name.lower()
        close = difflib.get_close_matches(name, available, n=5, cutoff=0.6)
        close += [a for a in available if lowered and lowered in a.lower() and a not in close]
        hint = f"close names: {close[:8]}; " if close else ""
        self.name = name
        #: every frame name of the model, in its order (the message lists them all up to
        #: :data:`~sjt_pin.exceptions.FRAMES_SHOWN`)
        self.available = available
        if len(available) <= FRAMES_SHOWN:
            listed = f"its {len(available)} frames: {available}"
        else:
            listed = (f"its {len(available)} frames, the first {FRAMES_SHOWN // 10}: "
                      f"{available[:FRAMES_SHOWN // 10]}, ... (this error's .available holds "
                      "them all)")
        super().__init__(message or (
            f"frame {name!r} not found in {robot}; {hint}{listed}; robot.frames() lists them, "
            "robot.frames('text') those whose name holds 'text', with type and parent joint"))

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
