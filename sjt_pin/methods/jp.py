"""The Jacobian pseudoinverse, eq. (8)-(9)."""

from __future__ import annotations

from .. import mappings
from ..validation import positive
from .least_squares import LeastSquaresMethod


class JP(LeastSquaresMethod):
    """``M = J^+`` (Moore-Penrose): exact tracking, blows up near singularities.

    ``rcond``: singular values below ``rcond sigma_max`` count as zero (the kernel works on
    ``J J^T``, whose eigenvalues are exact to about 1e3 eps, so the effective cutoff is at
    least ``sqrt(1e3 eps) ~ 5e-7``).
    """

    name = "jp"

    def __init__(self, rcond: float = mappings.JP_RCOND):
        self.rcond = positive(rcond, "rcond")

    def matrix(self, J):
        return mappings.jp_matrix(J, self.rcond)

    def __repr__(self):
        return f"JP(rcond={self.rcond:g})"
