"""The Jacobian pseudoinverse, eq. (8)-(9), damped by the error away from the target."""

from __future__ import annotations

from ..validation import positive
from .least_squares import LeastSquaresMethod

#: Singular values below ``JP_RCOND * sigma_max`` are treated as zero by the pseudoinverse.
JP_RCOND = 1e-12


class JP(LeastSquaresMethod):
    """``M = J^+`` (Moore-Penrose) at the target: exact tracking, blows up near singularities.

    ``rcond``: singular values below ``rcond sigma_max`` count as zero (the kernel works on
    ``J J^T``, whose eigenvalues are exact to about 1e3 eps, so the effective cutoff is at
    least ``sqrt(1e3 eps) ~ 5e-7``). ``error_damping`` (w): away from the target the
    pseudoinverse is damped by ``w |e_w| L`` only, ``J^T (J J^T + w |e_w| L I)^-1`` on the
    singular values above the cutoff: the Levenberg-Marquardt step (Sugihara, IEEE T-RO 2011),
    so that the arm comes to rest at a target it cannot reach (see :mod:`.least_squares`;
    default ``None``: 0.5 with pose and orientation rows only, 1 otherwise); 0 is the textbook
    ``J^+``, which the paper's baselines use.
    """

    name = "jp"

    def __init__(self, rcond: float = JP_RCOND, error_damping: float | None = None):
        super().__init__(error_damping)
        self.rcond = positive(rcond, "rcond")

    def __repr__(self):
        return f"JP(rcond={self.rcond:g}, error_damping={self.error_damping!r})"
