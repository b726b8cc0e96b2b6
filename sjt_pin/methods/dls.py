"""Damped least squares (the paper's introduction, [4, 11, 12])."""

from __future__ import annotations

from .. import mappings
from ..validation import positive
from .least_squares import LeastSquaresMethod

#: lambda of DLS, in task units (m for position rows, rad for orientation rows).
DLS_DAMPING = 0.05


class DLS(LeastSquaresMethod):
    """``M = J^T (J J^T + damping^2 I)^-1``; ``damping`` (lambda) in task units (m, rad): larger
    is more robust near singularities and less accurate (not unit-free)."""

    name = "dls"

    def __init__(self, damping: float = DLS_DAMPING):
        self.damping = positive(damping, "damping", "task units (m, rad)")

    def matrix(self, J):
        return mappings.dls_matrix(J, self.damping)

    def __repr__(self):
        return f"DLS(damping={self.damping:g})"
