"""Damped least squares (the paper's introduction, [4, 11, 12]), damped by the error too."""

from __future__ import annotations

from ..validation import positive
from .least_squares import LeastSquaresMethod

#: lambda of DLS, in task units (m for position rows, rad for orientation rows).
DLS_DAMPING = 0.05


class DLS(LeastSquaresMethod):
    """``M = J^T (J J^T + (lambda^2 + w |e_w| L) I)^-1``.

    ``damping`` (lambda) in task units (m, rad): larger is more robust near singularities and
    less accurate (not unit-free). ``error_damping`` (w): a Levenberg-Marquardt term that grows
    with the weighted error |e_w| (m) times the tasks' characteristic length L (m), Sugihara's
    error-dependent damping (IEEE T-RO 2011), so that the arm comes to rest at a target it
    cannot reach instead of oscillating (see :mod:`.least_squares`; default ``None``: 0.5 with
    pose and orientation rows only, 1 otherwise); 0 is the textbook
    ``J^T (J J^T + lambda^2 I)^-1``, which the paper's baselines use.
    """

    name = "dls"

    def __init__(self, damping: float = DLS_DAMPING, error_damping: float | None = None):
        super().__init__(error_damping)
        self.damping = positive(damping, "damping", "task units (m, rad)")

    def __repr__(self):
        return f"DLS(damping={self.damping:g}, error_damping={self.error_damping!r})"
