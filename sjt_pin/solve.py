"""The former name of :mod:`sjt_pin.ik` (set-point IK), kept so that ``from sjt_pin.solve
import ...`` works as before."""

from .ik import (  # noqa: F401 (re-exported under the old path)
    BUDGET,
    MAX_ITERS,
    MAX_STEP,
    MU,
    NU_START,
    TIMEOUT,
    TOL,
    IKResult,
    Search,
    solve,
)

__all__ = ["BUDGET", "MAX_ITERS", "MAX_STEP", "MU", "NU_START", "TIMEOUT", "TOL", "IKResult",
           "Search", "solve"]
